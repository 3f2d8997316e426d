"""deploy/README.md as a reader follows it: its certificate recipe, its command lines and the
service units it installs (outside check: a team following it got an opaque "Unable to connect"
after putting the router's address into the TLS endpoints, an operator that showed only "robot:
no telemetry" for lack of ``--robot robot-1``, an ``install`` into a missing /etc/egc, a router
unit reading a file no step installed, two different install paths, and a robot unit whose
``--driver zenoh`` had no bridge unit, so the robot stayed in HOLD, "sensor stale").

- The recipe, run with ``openssl`` as written (only the router's SAN line swapped), gives the
  router the SAN the README says, and the IP alternative it shows; the client certificates are
  X.509 v3 and signed by the CA.
- A client reaches the router at its address only when the router's certificate has that IP
  as a SAN (real ``egc-teleop router`` processes on the shipped ACL file).
- Every ``egc-teleop`` command line of the TLS section and of the units parses with the real
  command-line parser; robot, bridge and operator all name the robot id the ACL knows.
- The units use one install path, every /etc/egc file they read is installed by a step of
  "As services", those steps create /etc/egc, the black box has a state directory, and the
  robot's ``--driver zenoh`` has its bridge unit for the same robot id.
"""

from __future__ import annotations

import argparse
import re
import shlex
import subprocess
import time
from pathlib import Path

import pytest
import zenoh
from egc_common.transport import free_tcp_port

from tests import cli_process
from tests.integration.harness import ROOT
from tests.integration.test_deploy_acl import ACL
from tests.integration.test_deploy_tls import OPENSSL, client_config, router_config

DEPLOY = ROOT / "deploy"
README = (DEPLOY / "README.md").read_text()
UNITS = sorted((DEPLOY / "systemd").glob("*.service"))
BIN = "/opt/egc-teleop/bin/egc-teleop"
ROUTER_SAN = 'ROUTER_SAN="subjectAltName=DNS:router.local"'


def sh_blocks() -> list[str]:
    return re.findall(r"```sh\n(.*?)```", README, flags=re.S)


def block_with(marker: str) -> str:
    found = [b for b in sh_blocks() if marker in b]
    assert len(found) == 1, f"{len(found)} sh blocks of deploy/README.md contain {marker!r}"
    return found[0]


def section(title: str) -> str:
    start = README.index(f"## {title}\n")
    end = README.find("\n## ", start + 1)
    return README[start : end if end >= 0 else None]


def commands(text: str) -> list[list[str]]:
    """The shell command lines of ``text``, continuation lines joined, comments dropped."""
    joined = re.sub(r"\\\n\s*", " ", text)
    return [shlex.split(line, comments=True) for line in joined.splitlines() if line.strip()]


def parse_all(*argvs: list[str]) -> list[tuple[str, argparse.Namespace]]:
    """``egc-teleop SUBCOMMAND ...`` lines through their subcommands' real parsers (in one
    process: nothing imports egc_app, DESIGN 2)."""
    for argv in argvs:
        assert argv[0].endswith("egc-teleop"), argv
    parsed = []
    for argv, result in zip(argvs, cli_process.parse(*(a[1:] for a in argvs)), strict=True):
        if isinstance(result, str):
            pytest.fail(f"does not parse: {shlex.join(argv)}: {result}")
        parsed.append((argv[1], argparse.Namespace(**result)))
    return parsed


def parse(argv: list[str]) -> tuple[str, argparse.Namespace]:
    (parsed,) = parse_all(argv)
    return parsed


# -- the certificate recipe ---------------------------------------------------------------------


def run_recipe(cwd: Path, san: str | None = None) -> Path:
    """The README's recipe, verbatim but for the router's SAN line."""
    script = block_with("openssl req -x509")
    assert ROUTER_SAN in script
    if san is not None:
        script = script.replace(ROUTER_SAN, f'ROUTER_SAN="subjectAltName={san}"')
    cwd.mkdir(parents=True, exist_ok=True)
    subprocess.run(["bash", "-euc", script], cwd=cwd, check=True, capture_output=True, timeout=120)
    return cwd


def x509(cwd: Path, name: str, *what: str) -> str:
    out = subprocess.run(
        [OPENSSL, "x509", "-in", name, "-noout", *what],
        cwd=cwd,
        check=True,
        capture_output=True,
        text=True,
        timeout=30,
    )
    return out.stdout


def sans(cwd: Path) -> str:
    text = x509(cwd, "router.pem", "-ext", "subjectAltName")
    return " ".join(text.splitlines()[1:]).strip()


@pytest.fixture(scope="module")
def recipe(tmp_path_factory) -> Path:
    return run_recipe(tmp_path_factory.mktemp("recipe"))


def test_the_recipe_names_router_local_and_signs_v3_client_certificates(recipe):
    assert sans(recipe) == "DNS:router.local"
    for cn in ("operator-1", "robot-1"):
        assert f"CN={cn}" in x509(recipe, f"{cn}.pem", "-subject").replace(" ", "")
        assert "Version: 3" in x509(recipe, f"{cn}.pem", "-text")
    verify = subprocess.run(
        [OPENSSL, "verify", "-CAfile", "ca.pem", "router.pem", "operator-1.pem", "robot-1.pem"],
        cwd=recipe,
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert verify.returncode == 0, verify.stdout + verify.stderr


def test_the_ip_alternative_the_readme_shows(tmp_path):
    shown = re.search(r"DNS:router\.local,IP:[0-9.]+", block_with("openssl req -x509"))
    assert shown, "the recipe no longer shows the IP alternative"
    alt = run_recipe(tmp_path, shown.group(0))
    ip = shown.group(0).split("IP:")[1]
    assert sans(alt) == f"DNS:router.local, IP Address:{ip}"
    assert f"subjectAltName=DNS:router.local,IP:{ip}" in section("TLS and access control")


def start_router(procs, name: str, config: Path, port: int) -> None:
    proc = procs.start(
        name, "router", "--zenoh-config", str(config), "--listen", f"tls/127.0.0.1:{port}"
    )
    deadline = time.monotonic() + 20
    while "listening on" not in procs.log(name):
        assert proc.poll() is None, procs.log(name)
        assert time.monotonic() < deadline, procs.log(name)
        time.sleep(0.02)


@pytest.mark.integration
@pytest.mark.timeout(120)
def test_a_client_reaches_the_router_by_address_only_with_an_ip_san(procs, tmp_path, recipe):
    with_ip = run_recipe(tmp_path / "ip", "DNS:router.local,IP:127.0.0.1")
    ports = {}
    for name, pki in (("dns-only", recipe), ("with-ip", with_ip)):
        ports[name] = port = free_tcp_port()
        start_router(procs, name, router_config(pki, port, tmp_path / f"{name}.json5"), port)
    for name, pki in (("dns-only", recipe), ("with-ip", with_ip)):
        op = client_config("operator-tls.json5", pki, ports[name], tmp_path / f"op-{name}.json5")
        text = op.read_text().replace(
            f"tls/localhost:{ports[name]}", f"tls/127.0.0.1:{ports[name]}"
        )
        op.write_text(text)
        if name == "dns-only":
            with pytest.raises(zenoh.ZError, match="Unable to connect"):
                zenoh.open(zenoh.Config.from_file(str(op))).close()
        else:
            zenoh.open(zenoh.Config.from_file(str(op))).close()
    for name in ports:
        assert procs.stop(name) == 0, procs.log(name)


# -- the command lines --------------------------------------------------------------------------


def acl_robot_ids() -> set[str]:
    ids = set()
    for rule in ACL["rules"]:
        for key in rule["key_exprs"]:
            robot = key.split("/")[1]
            if robot != "*":
                ids.add(robot)
    return ids


def test_the_tls_command_lines_name_the_robot_the_acl_knows():
    lines = [c for c in commands(block_with("--zenoh-config /etc/egc/operator-tls.json5")) if c]
    parsed = parse_all(*lines)
    names = [name for name, _ in parsed]
    assert names == ["router", "robot", "sim", "operator"], names
    assert acl_robot_ids() == {"robot-1"}
    for name, args in parsed:
        config = Path(args.zenoh_config)
        assert config.parent == Path("/etc/egc") and (DEPLOY / config.name).is_file(), config
        if name == "router":
            assert config.name == "router-tls-acl.json5" and args.listen[0].startswith("tls/")
        else:
            assert args.robot == "robot-1", (name, args.robot)
            assert config.name == (
                "operator-tls.json5" if name == "operator" else "robot-tls.json5"
            )
    robot = dict(parsed)["robot"]
    assert robot.driver == "zenoh" and robot.config == "/etc/egc/robot.toml"


def test_every_egc_teleop_path_is_the_one_install_path():
    text = README + "".join(u.read_text() for u in UNITS)
    paths = set(re.findall(r"/opt/[\w./-]*egc-teleop\b", text))
    assert paths == {BIN, "/opt/egc-teleop"}, paths


# -- the service units --------------------------------------------------------------------------


def unit(path: Path) -> dict[str, list[str]]:
    """Key -> values of a unit file, continuation lines joined, comments dropped."""
    out: dict[str, list[str]] = {}
    text = re.sub(r"\\\n\s*", " ", path.read_text())
    for line in text.splitlines():
        if line.startswith(("#", ";", "[")) or "=" not in line:
            continue
        key, value = line.split("=", 1)
        out.setdefault(key.strip(), []).append(value.strip())
    return out


def exec_start(path: Path) -> list[str]:
    (line,) = unit(path)["ExecStart"]
    return shlex.split(line)


def installed_by_readme() -> set[str]:
    """The files the "As services" steps install, by their path on the target."""
    done: set[str] = set()
    made: set[str] = set()
    for argv in commands("\n".join(re.findall(r"```sh\n(.*?)```", section("As services"), re.S))):
        if argv[:2] != ["sudo", "install"]:
            continue
        opts = [a for a in argv[2:] if a.startswith("-")]
        files = [a for a in argv[2:] if not a.startswith("-") and a not in ("644", "755")]
        *sources, dest = files
        if dest.startswith("/etc/egc"):
            # install into /etc/egc, which does not exist yet: -D (or install -d first)
            assert "-D" in opts or str(Path(dest).parent) in made, shlex.join(argv)
        if "-d" in opts:
            made.update(files)
        elif len(sources) == 1 and not dest.endswith("/"):
            done.add(dest)
        else:
            done.update(f"{dest.rstrip('/')}/{Path(s).name}" for s in sources)
    return done


@pytest.mark.parametrize("path", UNITS, ids=[u.name for u in UNITS])
def test_each_unit_runs_a_command_that_parses_from_installed_files(path):
    values = unit(path)
    argv = exec_start(path)
    assert argv[0] == BIN, argv
    _, args = parse(argv)
    installed = installed_by_readme()
    assert f"/etc/systemd/system/{path.name}" in installed, path.name
    for arg in argv:
        if arg.startswith("/etc/egc/"):
            assert arg in installed, f"{path.name} reads {arg}, which no step installs"
    if getattr(args, "record", None):
        assert args.record.startswith("/var/lib/egc/") and values.get("StateDirectory") == ["egc"]
    assert values.get("StartLimitIntervalSec") == ["0"], "systemd would give up restarting"
    assert values.get("User") == ["egc"] and "useradd --system" in README


def test_the_robot_unit_has_its_bridge_unit():
    bridge_units = [exec_start(u) for u in UNITS if exec_start(u)[1] == "sim"]
    (_, robot), *bridges = parse_all(
        exec_start(DEPLOY / "systemd" / "egc-robot.service"), *bridge_units
    )
    assert robot.driver == "zenoh"
    assert len(bridges) == 1, bridges
    _, sim = bridges[0]
    assert (sim.robot, sim.zenoh_config) == (robot.robot, robot.zenoh_config)
    services = section("As services")
    assert "egc-sim.service" in services and "egc/robot-1/scan" in services
    assert "egc/robot-1/base/odom" in services and "sensor stale" in services
