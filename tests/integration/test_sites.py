"""Two sites joined router to router (deploy/README.md, "Two sites"; DESIGN 15), across network
namespaces (``egc_experiments.netns``: three namespaces, no IP forwarding in the middle one)::

    site B (namespace "op")          middle ("mid")                site A (namespace "rb")
    router B  tls/0.0.0.0:7447       egc-teleop link               router A  tls/0.0.0.0:7447
      operator-1, operator-2,        10.201.1.1:7447 -> 10.201.2.2:7447   robot-1 (--driver sim)
      the watcher, `robots`          delay=100 each way

Router B connects to router A through the relay (the network between the sites, 100 ms each
way); robot-1 is a client of router A, the operators are clients of router B. Every file is the
shipped one with only certificate paths and host names replaced (``test_deploy_tls.derive``):
``site-robots-router.json5``, ``site-operators-router.json5``, and, unchanged as the README
says, ``robot-tls.json5`` and ``operator-tls.json5``. Certificates are made with ``openssl``
at test time; router A's names the relay's address as the host router B dials.

What it shows (the issue's "Sites" must-show):
- operator-1 (whose certificate the ACL lets drive robot-1) drives robot-1 from site B: the
  robot's telemetry says DRIVING with op-1 and v_cmd > 0, its summary a distance, and the
  relay's counts that the commands crossed it at 100 ms;
- operator-2 (a fleet operator allowed robot-2 only) runs the very same script against robot-1
  before and while operator-1 drives: the robot never sees it (no token, no command: IDLE and
  nothing rejected while it tries alone, never a telemetry or log line naming it);
- both list robot-1 with ``egc-teleop robots`` at site B (with its info: the ACL lets every
  fleet operator list and watch every robot), and operator-2's certificate receives robot-1's
  telemetry (the watcher);
- an operator certificate that dials site A's router directly (past site B's per-operator
  rules) lists nothing there.

Skipped, with the reason, when not root or when ``ip netns`` does not work (CI runs as root).
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
from egc_experiments import netns

from tests.integration.test_deploy_tls import (
    client_config,
    derive,
    openssl,
    operator_config,
    wait_until,
)
from tests.integration.test_netns import Spawner

pytestmark = [pytest.mark.integration, pytest.mark.timeout(150)]

_REASON = netns.unavailable_reason()
needs_netns = pytest.mark.skipif(_REASON is not None, reason=str(_REASON))

PORT = 7447
ROBOT = "robot-1"
DELAY_MS = 100
RELAY = f"{netns.MIDDLE_OP_ADDR}:{PORT}"  # where router B dials router A: the relay
# Router A's certificate names the hosts its clients dial: localhost for the robot beside it,
# the relay's address for router B (in the field: site A's public name, site-a.example.net).
CERTS = {
    "robots-router": [f"subjectAltName=DNS:localhost,IP:{netns.MIDDLE_OP_ADDR}"],
    "operators-router": [
        "subjectAltName=DNS:localhost",
        "extendedKeyUsage=serverAuth,clientAuth",
    ],
    "robot-1": ["extendedKeyUsage=clientAuth"],
    "operator-1": ["extendedKeyUsage=clientAuth"],
    "operator-2": ["extendedKeyUsage=clientAuth"],
}

WATCHER = """\
import json, sys, threading, time
import zenoh
from egc_common import keys
from egc_common.messages import Rejection, decode_telemetry
zenoh.init_log_from_env_or("error")
session = zenoh.open(zenoh.Config.from_file(sys.argv[1]))
out = open(sys.argv[3], "a", buffering=1)
lock = threading.Lock()
def on_telemetry(sample):
    t = decode_telemetry(sample.payload.to_bytes())
    if isinstance(t, Rejection):
        return
    line = {"rx_ns": time.monotonic_ns(), "state": t.state, "operator": t.operator,
            "rejected": t.rejected, "v_cmd": t.v_cmd}
    with lock:
        out.write(json.dumps(line) + "\\n")
sub = session.declare_subscriber(keys.telemetry(sys.argv[2]), on_telemetry)
print("watching", flush=True)
while True:
    time.sleep(3600)
"""


@pytest.fixture(scope="module")
def pki(tmp_path_factory) -> Path:
    """deploy/README.md's recipe ("TLS and access control", "Two sites"), rsa:2048 for speed."""
    root = tmp_path_factory.mktemp("sites-pki")
    openssl(
        root,
        *("req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "3650"),
        *("-subj", "/CN=egc-ca", "-keyout", "ca-key.pem", "-out", "ca.pem"),
    )
    for cn, exts in CERTS.items():
        addext = [a for ext in exts for a in ("-addext", ext)]
        openssl(
            root,
            *("req", "-newkey", "rsa:2048", "-nodes", "-subj", f"/CN={cn}"),
            *("-keyout", f"{cn}-key.pem", "-out", f"{cn}.csr", *addext),
        )
        openssl(
            root,
            *("x509", "-req", "-in", f"{cn}.csr", "-CA", "ca.pem", "-CAkey", "ca-key.pem"),
            *("-CAcreateserial", "-days", "825", "-copy_extensions", "copy"),
            *("-out", f"{cn}.pem"),
        )
    return root


def telemetry_lines(path: Path) -> list[dict[str, Any]]:
    """The watcher's telemetry lines so far (a line still being written is left out)."""
    if not path.exists():
        return []
    return [json.loads(line) for line in path.read_text().split("\n")[:-1]]


def listed(run: Spawner, net: netns.TwoHosts, config: Path) -> dict[str, dict[str, Any]]:
    """``egc-teleop robots --json`` at site B with ``config``'s certificate: robot -> its line."""
    out = net.run(
        "op",
        [sys.executable, "-m", "egc_app.cli", "robots", "--zenoh-config", str(config)]
        + ["--json", "--wait", "3"],
        timeout_s=60,
    )
    return {row["robot"]: row for row in map(json.loads, out.splitlines())}


@needs_netns
def test_an_operator_at_one_site_drives_only_the_robots_its_certificate_allows(pki, tmp_path):
    tls = {"/etc/egc/tls/": f"{pki}/"}
    router_a = derive("site-robots-router.json5", tmp_path / "router-a.json5", tls)
    router_b = derive(
        "site-operators-router.json5",
        tmp_path / "router-b.json5",
        tls | {"tls/site-a.example.net:7447": f"tls/{RELAY}"},
    )
    robot_cfg = client_config("robot-tls.json5", pki, PORT, tmp_path / "robot.json5")
    op1_cfg = operator_config(pki, PORT, tmp_path / "op1.json5", "operator-1")
    op2_cfg = operator_config(pki, PORT, tmp_path / "op2.json5", "operator-2")
    direct_cfg = tmp_path / "op2-direct.json5"
    direct_cfg.write_text(op2_cfg.read_text().replace(f"tls/localhost:{PORT}", f"tls/{RELAY}"))
    summary, stats = tmp_path / "robot.json", tmp_path / "link.json"
    watched = tmp_path / "telemetry.jsonl"
    (tmp_path / "watcher.py").write_text(WATCHER)
    with netns.TwoHosts() as net:
        run = Spawner(net, tmp_path)
        try:
            run.start("link", "mid", "link", "--listen", f"tcp/{RELAY}",
                      "--connect", f"tcp/{netns.ROBOT_ADDR}:{PORT}", "--up", f"delay={DELAY_MS}",
                      "--down", f"delay={DELAY_MS}", "--stats", str(stats))  # fmt: skip
            for name, side, config in (("router-a", "rb", router_a), ("router-b", "op", router_b)):
                run.start(name, side, "router", "--zenoh-config", str(config),
                          "--listen", f"tls/0.0.0.0:{PORT}")  # fmt: skip
            for name in ("link", "router-a", "router-b"):
                run.wait_log(name, "listening on")
            run.start("robot", "rb", "robot", "--robot", ROBOT, "--driver", "sim",
                      "--map", "hallway", "--zenoh-config", str(robot_cfg),
                      "--summary", str(summary))  # fmt: skip
            run.wait_log("robot", "ready", 30)
            # operator-2's certificate watches robot-1 across the sites ...
            with (tmp_path / "watcher.log").open("wb") as out:
                watcher = net.popen(
                    "op",
                    [sys.executable, str(tmp_path / "watcher.py"), str(op2_cfg), ROBOT,
                     str(watched)],
                    stdout=out, stderr=subprocess.STDOUT, cwd=tmp_path,
                )  # fmt: skip
            run.children["watcher"] = watcher
            wait_until("robot-1's telemetry at site B", lambda: telemetry_lines(watched), 30)
            # ... and lists it, with its info.
            listing_2 = listed(run, net, op2_cfg)
            # An operator certificate dialling site A's router itself, past its own site's
            # rules, gets nothing there: not even the robot's token.
            assert listed(run, net, direct_cfg) == {}
            # operator-2 drives robot-1 with the script that makes operator-1 drive below.
            script = ["--robot", ROBOT, "--script", "demo", "--no-view", "--no-status"]
            alone_from = time.monotonic_ns()
            run.start("op2", "op", "operator", *script, "--operator-id", "op-2",
                      "--zenoh-config", str(op2_cfg), "--duration", "120")  # fmt: skip
            run.wait_log("op2", "robot present", 30)  # it sees the robot: it may watch
            time.sleep(5.0)  # the script's stick is forward after 1 s
            # Alone, operator-2 never reached the robot: IDLE, nothing rejected, nothing
            # applied (an allowed operator took control within about 2 s, see below).
            alone = [t for t in telemetry_lines(watched) if t["rx_ns"] >= alone_from]
            assert len(alone) >= 40, len(alone)  # 5 s of 20 Hz telemetry
            assert all(t["state"] == "IDLE" and t["operator"] is None for t in alone), alone[-1]
            assert all(t["rejected"] == 0 and t["v_cmd"] == 0.0 for t in alone), alone[-1]
            # The positive control: operator-1, its certificate allowed robot-1.
            op1_start = time.monotonic_ns()
            run.start("op1", "op", "operator", *script, "--operator-id", "op-1",
                      "--zenoh-config", str(op1_cfg), "--duration", "10")  # fmt: skip

            def driving() -> dict[str, Any] | None:
                return next(
                    (
                        t
                        for t in telemetry_lines(watched)
                        if t["operator"] == "op-1" and t["state"] == "DRIVING" and t["v_cmd"] > 0
                    ),
                    None,
                )

            wait_until("robot-1 DRIVING for op-1", driving, 40)
            in_control = next(t for t in telemetry_lines(watched) if t["operator"] == "op-1")
            listing_1 = listed(run, net, op1_cfg)
            run.children["op1"].wait(60)
            assert run.children["op1"].returncode == 0, run.log("op1")
            assert run.stop("op2", timeout_s=10) == 0, run.log("op2")
            assert run.stop("robot", timeout_s=15) == 0, run.log("robot")
            assert run.stop("link", timeout_s=10) == 0, run.log("link")
        finally:
            run.cleanup()
    robot_log = run.log("robot")
    # Nor later: with operator-1 in control its commands would have been rejected (not in
    # control) and logged by operator id, its token logged as "operator op-2 alive".
    assert all(t["operator"] in (None, "op-1") for t in telemetry_lines(watched))
    assert "op-2" not in robot_log, robot_log
    # operator-1 drove it, across the link.
    assert "operator op-1 took control" in robot_log
    robot = json.loads(summary.read_text())
    assert robot["distance_m"] > 0.3 and robot["collisions"] == 0, robot
    link = json.loads(stats.read_text())
    assert link["up"]["forwarded"] > 100 and link["down"]["forwarded"] > 100, link
    assert link["up"]["p50_ms"] == pytest.approx(DELAY_MS, abs=10), link
    assert robot["command_latency"]["p50_ms"] >= DELAY_MS * 0.6, robot  # synchronised, crossed
    # Both list robot-1 at site B, with its info (the ACL lets every fleet operator list).
    assert listing_2[ROBOT]["driver"] == "sim" and listing_2[ROBOT]["state"] == "IDLE", listing_2
    assert listing_1[ROBOT]["operator"] == "op-1", listing_1
    print(
        f"sites: op-1 start -> first telemetry naming it at site B "
        f"{(in_control['rx_ns'] - op1_start) / 1e6:.0f} ms; command latency "
        f"{robot['command_latency']}; link {link['up']}"
    )
