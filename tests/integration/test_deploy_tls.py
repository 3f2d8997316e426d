"""The shipped TLS + access-control deployment, end to end (deploy/README.md, "TLS and access
control").

A CA and certificates are made with the ``openssl`` CLI the way the README does it; the router,
the robot and the operator run as separate OS processes on configurations derived from the real
``deploy/router-tls-acl.json5``, ``deploy/robot-tls.json5`` and ``deploy/operator-tls.json5`` by
substituting only certificate paths, the port and the host name, so the ACL rules and the TLS
settings under test are the shipped ones. There is no ``zenohd`` here: the router is a Python
process holding a Zenoh session in router mode.

- An operator process drives a robot process through the router, with ``require_clock_sync``
  as the README recommends for such networks, so the operator's clock queries must pass the ACL
  too; its liveliness token does (the robot sees it come and go).
- A certificate signed by the project CA but with a common name outside the ACL connects, yet
  sees no telemetry, gets no clock, and its commands never reach the robot; the very same
  commands from an allowed certificate drive it (the positive control).
- Each role sends only its own messages: commands published with a robot certificate do not
  reach the robot, telemetry and state forged with an operator certificate reach no one; the
  map query of the world-frame view passes; the operator's via points (goal) pass.
- A robot certificate is tied to its robot id: robot-1's base commands reach robot-1's base
  bridge, not another robot's; an operator certificate reaches no base.
- Without a client certificate, with one from another CA, or over plain TCP, no session opens.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import msgpack
import pytest
import zenoh
from egc_common import keys
from egc_common.messages import (
    Rejection,
    StateMessage,
    Telemetry,
    decode_clock_reply,
    decode_state,
    decode_telemetry,
)

from tests.integration.harness import MS, ROOT, joystick_file

pytestmark = [pytest.mark.integration, pytest.mark.timeout(60)]

DEPLOY = ROOT / "deploy"
OPENSSL = shutil.which("openssl") or "/usr/bin/openssl"
ALLOWED = ("router", "operator-1", "robot-1")  # common names the shipped ACL knows (or needs)
INTRUDER = "intruder"  # signed by the project CA, but not in the ACL
ROBOT = "robot-1"  # the robot id the shipped ACL ties the robot-1 certificate to

ROUTER_SCRIPT = """\
import sys, time, zenoh
zenoh.init_log_from_env_or("warn")
session = zenoh.open(zenoh.Config.from_file(sys.argv[1]))
print("router ready", flush=True)
while True:
    time.sleep(3600)
"""


# -- certificates and configurations ------------------------------------------------------------


def openssl(cwd: Path, *args: str) -> None:
    subprocess.run([OPENSSL, *args], cwd=cwd, check=True, capture_output=True, timeout=30)


def make_pki(cwd: Path, ca_cn: str, cns: tuple[str, ...]) -> Path:
    """deploy/README.md's commands (rsa:2048 for speed): ``ca.pem`` signs ``<cn>.pem``; the
    router's certificate names the host the clients dial (``localhost`` here) as its
    subjectAltName, the clients' say they are clients (an X.509 v3 extension: without one
    ``openssl x509 -req`` makes a version 1 certificate, which rustls refuses)."""
    cwd.mkdir(parents=True, exist_ok=True)
    openssl(
        cwd,
        *("req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "3650"),
        *("-subj", f"/CN={ca_cn}", "-keyout", "ca-key.pem", "-out", "ca.pem"),
    )
    for cn in cns:
        ext = "subjectAltName=DNS:localhost" if cn == "router" else "extendedKeyUsage=clientAuth"
        openssl(
            cwd,
            *("req", "-newkey", "rsa:2048", "-nodes", "-subj", f"/CN={cn}"),
            *("-keyout", f"{cn}-key.pem", "-out", f"{cn}.csr", "-addext", ext),
        )
        openssl(
            cwd,
            *("x509", "-req", "-in", f"{cn}.csr", "-CA", "ca.pem", "-CAkey", "ca-key.pem"),
            *("-CAcreateserial", "-days", "825", "-copy_extensions", "copy"),
            *("-out", f"{cn}.pem"),
        )
    return cwd


@pytest.fixture(scope="module")
def pki(tmp_path_factory) -> Path:
    """The project CA with every certificate; ``rogue/`` is another CA's ``operator-1``."""
    root = tmp_path_factory.mktemp("pki")
    make_pki(root, "egc-ca", (*ALLOWED, INTRUDER))
    make_pki(root / "rogue", "rogue-ca", ("operator-1",))
    return root


def derive(deploy_file: str, dest: Path, subs: dict[str, str]) -> Path:
    """A copy of a shipped deploy file with only ``subs`` (paths, port, host) replaced; every
    one of them must occur, so a changed deploy file fails here instead of going untested."""
    text = (DEPLOY / deploy_file).read_text()
    for old, new in subs.items():
        assert old in text, f"{deploy_file} no longer contains {old!r}"
        text = text.replace(old, new)
    dest.write_text(text)
    return dest


def router_config(pki: Path, port: int, dest: Path) -> Path:
    return derive(
        "router-tls-acl.json5",
        dest,
        {"/etc/egc/tls/": f"{pki}/", "tls/0.0.0.0:7447": f"tls/127.0.0.1:{port}"},
    )


def client_config(
    deploy_file: str, pki: Path, port: int, dest: Path, extra: dict[str, str] | None = None
) -> Path:
    subs = dict(extra or {})
    subs |= {"/etc/egc/tls/": f"{pki}/", "tls/router.local:7447": f"tls/localhost:{port}"}
    return derive(deploy_file, dest, subs)


def operator_config(pki: Path, port: int, dest: Path, cn: str = "operator-1") -> Path:
    """deploy/operator-tls.json5 with the certificate of ``cn``."""
    extra = {} if cn == "operator-1" else {"/etc/egc/tls/operator-1": f"{pki}/{cn}"}
    return client_config("operator-tls.json5", pki, port, dest, extra)


# -- the router process -------------------------------------------------------------------------


@pytest.fixture
def router(pki, port, tmp_path):
    """The shipped router configuration in its own OS process, until the test ends."""
    config = router_config(pki, port, tmp_path / "router.json5")
    script = tmp_path / "router.py"
    script.write_text(ROUTER_SCRIPT)
    log = tmp_path / "router.log"
    with log.open("wb") as out:
        proc = subprocess.Popen(
            [sys.executable, str(script), str(config)],
            stdout=out,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            cwd=tmp_path,
        )
    try:
        wait_until(
            "the router",
            lambda: "router ready" in log.read_text(errors="replace") or proc.poll() is not None,
            20,
        )
        assert proc.poll() is None, f"the router exited:\n{log.read_text(errors='replace')}"
        yield proc
    finally:
        proc.kill()
        proc.wait(5)


# -- sessions in the test process ---------------------------------------------------------------


def wait_until(what: str, predicate: Callable[[], Any], timeout_s: float) -> Any:
    deadline = time.monotonic() + timeout_s
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")
        time.sleep(0.01)


def open_client(config_path: Path) -> zenoh.Session:
    return zenoh.open(zenoh.Config.from_file(str(config_path)))


class Watcher:
    """A TLS client of the router recording one robot's telemetry and state."""

    def __init__(self, session: zenoh.Session, robot: str) -> None:
        self.session = session
        self.robot = robot
        self._lock = threading.Lock()
        self._telemetry: list[tuple[int, Telemetry]] = []
        self._state: list[tuple[int, StateMessage]] = []
        self._subs = [
            session.declare_subscriber(keys.telemetry(robot), self._on_telemetry),
            session.declare_subscriber(keys.state(robot), self._on_state),
        ]

    def _on_telemetry(self, sample: zenoh.Sample) -> None:
        t = decode_telemetry(sample.payload.to_bytes())
        assert not isinstance(t, Rejection), t
        with self._lock:
            self._telemetry.append((time.monotonic_ns(), t))

    def _on_state(self, sample: zenoh.Sample) -> None:
        s = decode_state(sample.payload.to_bytes())
        assert not isinstance(s, Rejection), s
        with self._lock:
            self._state.append((time.monotonic_ns(), s))

    def telemetry(self, since_ns: int = 0) -> list[Telemetry]:
        with self._lock:
            return [t for rx, t in self._telemetry if rx >= since_ns]

    def states(self, since_ns: int = 0) -> list[StateMessage]:
        with self._lock:
            return [s for rx, s in self._state if rx >= since_ns]

    def moving(self, since_ns: int = 0) -> Telemetry | None:
        return next(
            (t for t in self.telemetry(since_ns) if t.state == "DRIVING" and t.v_cmd > 0), None
        )

    def close(self) -> None:
        for sub in self._subs:
            sub.undeclare()


def clock_replies(session: zenoh.Session, robot: str) -> list[int]:
    stamps = []
    for reply in session.get(keys.clock(robot), timeout=1.0):
        if reply.ok is not None:
            stamp = decode_clock_reply(reply.ok.payload.to_bytes())
            assert isinstance(stamp, int), stamp
            stamps.append(stamp)
    return stamps


def command(seq: int, x: float) -> bytes:
    """A pinned OperatorCommand map (DESIGN 7), unsynchronised (stamp 0)."""
    msg = {"v": 1, "seq": seq, "stamp_ns": 0, "x": x, "y": 0.0, "mode": "shared"}
    msg |= {"deadman": True, "estop": False, "reset": False, "op": "outside"}
    data: bytes = msgpack.packb(msg)
    return data


def drive(session: zenoh.Session, robot: str, count: int, until: Callable[[], Any]) -> int:
    """``count`` commands at 50 Hz: centred with the deadman held for the first 25 (0.5 s), then
    half forward; fewer if ``until()``. Returns how many were published. (A count, not a
    duration: a busy machine's 20 ms sleeps take longer, and 2 s sent fewer than 75.)"""
    seq = 0
    while seq < count and not until():
        seq += 1
        session.put(
            keys.cmd(robot),
            command(seq, 0.0 if seq <= 25 else 0.5),
            priority=zenoh.Priority.INTERACTIVE_HIGH,
            express=True,
            congestion_control=zenoh.CongestionControl.BLOCK,
        )
        time.sleep(0.02)
    return seq


def start_robot(procs, robot: str, config: Path, *extra: str) -> None:
    procs.start("robot", "robot", "--robot", robot, "--zenoh-config", str(config), *extra)


def stop_robot(procs) -> None:
    assert procs.alive("robot"), procs.log("robot")
    assert procs.stop("robot") == 0, procs.log("robot")


# -- the tests ------------------------------------------------------------------------------------


def test_an_operator_drives_a_robot_through_the_tls_router(procs, pki, port, router, tmp_path):
    robot = ROBOT
    robot_cfg = client_config("robot-tls.json5", pki, port, tmp_path / "robot-tls.json5")
    op_cfg = operator_config(pki, port, tmp_path / "operator-tls.json5")
    # README: on a network you do not control, commands must carry a robot-clock stamp.
    start_robot(procs, robot, robot_cfg, "--set", "safety.require_clock_sync=true")
    # The test watches with the operator's certificate, which the ACL lets see telemetry.
    watcher = Watcher(open_client(op_cfg), robot)
    try:
        wait_until("robot telemetry through the router", watcher.telemetry, 20)
        assert clock_replies(watcher.session, robot), "the robot's clock did not answer"
        js = joystick_file(tmp_path / "fwd.csv", [(0, 0, 0, 1), (1.5, 0.5, 0, 1), (60, 0.5, 0, 1)])
        op_args = ["--robot", robot, "--operator-id", "op-tls", "--joystick-file", str(js)]
        op_args += ["--no-view", "--no-status", "--zenoh-config", str(op_cfg), "--goal", "5,1.2"]
        procs.start("op", "operator", *op_args)
        driving = wait_until("DRIVING with v_cmd > 0", watcher.moving, 20)
        assert driving.operator == "op-tls", driving
        assert driving.v_cmd > 0.0 and driving.v_ref > 0.0, driving
        assert "operator op-tls alive" in procs.log("robot")  # its liveliness token got through
        # Its via points too (egc/<robot>/goal; the first ACL had no rule for them).
        wait_until("the via point", lambda: "via points from op-tls" in procs.log("robot"), 5)
        wait_until("the active via point echoed", lambda: watcher.telemetry()[-1].goal, 5)
        # Killed, the operator's link closes: the router withdraws its token from the robot.
        killed = time.monotonic_ns()
        procs.children["op"].kill()
        wait_until(
            "operator lost",
            lambda: any(s.reason == "operator op-tls lost" for s in watcher.states(killed)),
            5,
        )
        wait_until(
            "the robot stopped",
            lambda: any(t.v_cmd == 0.0 for t in watcher.telemetry(killed + 300 * MS)),
            5,
        )
        stop_robot(procs)
    finally:
        watcher.close()
        watcher.session.close()


def test_a_certificate_outside_the_acl_cannot_drive(procs, pki, port, router, tmp_path):
    robot = ROBOT
    robot_cfg = client_config("robot-tls.json5", pki, port, tmp_path / "robot-tls.json5")
    start_robot(procs, robot, robot_cfg)
    sessions: list[zenoh.Session] = []
    watchers: list[Watcher] = []
    try:
        watcher = Watcher(open_client(operator_config(pki, port, tmp_path / "op.json5")), robot)
        sessions.append(watcher.session)
        watchers.append(watcher)
        wait_until("robot telemetry through the router", watcher.telemetry, 20)
        # The intruder's certificate is signed by the project CA: TLS lets it in ...
        intruder = open_client(operator_config(pki, port, tmp_path / "intruder.json5", INTRUDER))
        sessions.append(intruder)
        spy = Watcher(intruder, robot)
        watchers.append(spy)
        start = time.monotonic_ns()
        sent = drive(intruder, robot, 100, lambda: False)
        end = time.monotonic_ns()
        # ... but the ACL does not: no clock,
        assert not clock_replies(intruder, robot), "the intruder got the robot's clock"
        # (the robot keeps publishing: anything of the intruder's in flight has arrived by then)
        wait_until(
            "telemetry well after the last command", lambda: watcher.telemetry(end + 300 * MS), 5
        )
        # The robot published all along (20 Hz, fewer when the machine is busy: 28 in 2.3 s
        # once), so "IDLE throughout" below is about the whole attempt.
        during = watcher.telemetry(start)
        assert sent == 100 and len(during) >= 10, (sent, len(during))
        assert not spy.telemetry(), "the intruder sees telemetry"  # no telemetry,
        assert not spy.states(), "the intruder sees the robot's state"
        # ... and its commands never reach the robot: not applied, not even counted.
        assert all(t.state == "IDLE" and t.v_cmd == 0.0 for t in during), during[-1]
        assert all(t.rejected == 0 and t.operator is None for t in during), during[-1]
        assert "rejected command" not in procs.log("robot")
        # Positive control: the very same commands from an allowed certificate drive.
        allowed = open_client(operator_config(pki, port, tmp_path / "allowed.json5"))
        sessions.append(allowed)
        control = time.monotonic_ns()
        drive(allowed, robot, 500, lambda: watcher.moving(control))
        driving = wait_until("DRIVING with v_cmd > 0", lambda: watcher.moving(control), 1)
        assert driving.operator == "outside" and driving.rejected == 0, driving
        stop_robot(procs)
    finally:
        for w in watchers:
            w.close()
        for s in sessions:
            s.close()


def test_each_role_sends_only_its_own_messages(procs, pki, port, router, tmp_path):
    """Robot certificates cannot command, operator certificates cannot forge telemetry."""
    robot = ROBOT
    robot_cfg = client_config("robot-tls.json5", pki, port, tmp_path / "robot-tls.json5")
    start_robot(procs, robot, robot_cfg)
    sessions: list[zenoh.Session] = []
    watcher: Watcher | None = None
    try:
        watcher = Watcher(open_client(operator_config(pki, port, tmp_path / "op.json5")), robot)
        sessions.append(watcher.session)
        wait_until("robot telemetry through the router", watcher.telemetry, 20)
        # The map queryable answers operators through the router (the world-frame view).
        maps = [r for r in watcher.session.get(keys.world_map(robot), timeout=2.0) if r.ok]
        assert maps, "the robot's map did not come through the router"
        # A second client holding a robot certificate publishes valid commands ...
        fake_robot = open_client(
            client_config("robot-tls.json5", pki, port, tmp_path / "robot2.json5")
        )
        sessions.append(fake_robot)
        start = time.monotonic_ns()
        sent = drive(fake_robot, robot, 100, lambda: False)
        end = time.monotonic_ns()
        # ... and another operator certificate's session forges telemetry and state (from its
        # own session: Zenoh would deliver a session's puts to its own subscribers directly).
        forger = open_client(operator_config(pki, port, tmp_path / "forger.json5"))
        sessions.append(forger)
        forged = Telemetry(1, 1, "ESTOP", "shared", 0.0, 0.0, 0.0, 0.0, 0.0, operator="forger")
        forged_state = StateMessage(1, "ESTOP", "forged", "forger")
        for _ in range(20):
            forger.put(keys.telemetry(robot), forged.encode())
            forger.put(keys.state(robot), forged_state.encode())
            time.sleep(0.02)
        settled = time.monotonic_ns()
        wait_until("telemetry after the forgeries", lambda: watcher.telemetry(settled), 5)
        # The robot published all along (20 Hz, fewer when the machine is busy: 28 in 2.3 s
        # once), so "IDLE throughout" below is about the whole attempt.
        during = watcher.telemetry(start)
        assert sent == 100 and len(during) >= 10, (sent, len(during))
        assert all(t.state == "IDLE" and t.v_cmd == 0.0 for t in during), during[-1]
        assert all(t.rejected == 0 and t.operator is None for t in during), during[-1]
        assert all(t.operator != "forger" for t in watcher.telemetry()), "forged telemetry"
        assert all(s.operator != "forger" for s in watcher.states()), "forged state"
        assert watcher.telemetry(end), "the robot went silent"
        stop_robot(procs)
    finally:
        if watcher is not None:
            watcher.close()
        for session in sessions:
            session.close()


def test_a_robot_certificate_reaches_only_its_own_robot_id(pki, port, router, tmp_path):
    """The robot-1 certificate carries base commands and scans between the robot process and
    its base bridge, for egc/robot-1 only: put to another robot's base it reaches no one (an
    outside check drove robot 'sim''s base with it, past the filter, when rules said egc/*)."""
    cfg = client_config("robot-tls.json5", pki, port, tmp_path / "robot-tls.json5")
    bridge, other = open_client(cfg), open_client(cfg)
    got: dict[str, list[bytes]] = {"robot-1": [], "sim": []}
    subs = [
        bridge.declare_subscriber(
            keys.base_cmd(rid), lambda s, rid=rid: got[rid].append(s.payload.to_bytes())
        )
        for rid in got
    ]
    operator = open_client(operator_config(pki, port, tmp_path / "op.json5"))
    try:
        time.sleep(0.5)  # declarations through the router
        for _ in range(20):
            other.put(keys.base_cmd("sim"), b"drive")  # another robot's base
            operator.put(keys.base_cmd("robot-1"), b"drive")  # an operator at a base
            other.put(keys.base_cmd("robot-1"), b"own")  # positive control
            time.sleep(0.02)
        wait_until("the robot's own base commands", lambda: len(got["robot-1"]) >= 20, 5)
        time.sleep(0.3)
        assert got["sim"] == [], "a robot-1 certificate reached another robot's base"
        assert set(got["robot-1"]) == {b"own"}, "an operator certificate reached a base"
    finally:
        for sub in subs:
            sub.undeclare()
        for session in (bridge, other, operator):
            session.close()


def test_no_session_without_a_certificate_of_the_project_ca(pki, port, router, tmp_path):
    ok = operator_config(pki, port, tmp_path / "ok.json5")
    plain_tcp = derive(
        "operator-tls.json5",
        tmp_path / "tcp.json5",
        {"/etc/egc/tls/": f"{pki}/", "tls/router.local:7447": f"tcp/127.0.0.1:{port}"},
    )
    rogue = client_config(
        "operator-tls.json5",
        pki,
        port,
        tmp_path / "rogue.json5",
        {"/etc/egc/tls/operator-1": f"{pki}/rogue/operator-1"},  # same CN, another CA
    )
    # The shipped operator file with its "tls" section cut down to trusting the project CA.
    no_cert = zenoh.Config.from_file(str(ok))
    no_cert.insert_json5(
        "transport/link/tls",
        json.dumps({"root_ca_certificate": f"{pki}/ca.pem", "enable_mtls": False}),
    )
    assert json.loads(no_cert.get_json("transport/link/tls/connect_certificate")) is None
    refused: dict[str, zenoh.Config] = {
        "plain TCP": zenoh.Config.from_file(str(plain_tcp)),
        "TLS without a client certificate": no_cert,
        "operator-1 signed by another CA": zenoh.Config.from_file(str(rogue)),
    }
    for what, config in refused.items():
        try:
            session = zenoh.open(config)
        except zenoh.ZError as exc:
            assert "Unable to connect" in str(exc), (what, exc)
        else:
            session.close()
            pytest.fail(f"{what}: a session opened")
    # Positive control: the same file with the project's certificate connects.
    zenoh.open(zenoh.Config.from_file(str(ok))).close()


class Tokens:
    """One session's liveliness subscriber on ``key`` (with history): the token keys it holds
    as alive now, and every key it ever saw declared."""

    def __init__(self, session: zenoh.Session, key: str) -> None:
        self._lock = threading.Lock()
        self.alive: set[str] = set()
        self.seen: set[str] = set()
        self._sub = session.liveliness().declare_subscriber(key, self._on, history=True)

    def _on(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        with self._lock:
            if sample.kind == zenoh.SampleKind.PUT:
                self.alive.add(key)
                self.seen.add(key)
            else:
                self.alive.discard(key)

    def close(self) -> None:
        self._sub.undeclare()


def test_each_role_declares_only_its_own_liveliness_tokens(pki, port, router, tmp_path):
    """Outside check: a robot certificate declared egc/robot-1/alive/operator/op-robot-1 and
    the router passed it on (robot-watch-operators allowed liveliness_token ingress on every
    operator key); by the same rule an operator certificate could declare a robot's token.
    Forged tokens declared before the watchers subscribe (their history) and after (live)
    reach no one; the real ones (the positive control) do."""
    robot_cfg = client_config("robot-tls.json5", pki, port, tmp_path / "robot-tls.json5")
    op_cfg = operator_config(pki, port, tmp_path / "operator-tls.json5")
    robot_forger, op_forger = open_client(robot_cfg), open_client(op_cfg)
    robot_side, op_side = open_client(robot_cfg), open_client(op_cfg)
    sessions = [robot_forger, op_forger, robot_side, op_side]
    watchers: list[Tokens] = []
    tokens: list[Any] = []
    early_op, late_op = (
        keys.alive_operator(ROBOT, "op-early"),
        keys.alive_operator(ROBOT, "op-late"),
    )
    robot_token = keys.alive_robot(ROBOT)
    try:
        # Forged before anyone watches: a robot certificate's operator token, an operator
        # certificate's robot token.
        tokens.append(robot_forger.liveliness().declare_token(early_op))
        tokens.append(op_forger.liveliness().declare_token(robot_token))
        time.sleep(0.5)
        # What the robot process and the operator process watch (egc_robot.zenoh_node,
        # egc_operator.operator_node).
        on_robot = Tokens(robot_side, keys.alive_operators(ROBOT))
        on_operator = Tokens(op_side, robot_token)
        watchers += [on_robot, on_operator]
        time.sleep(0.5)
        tokens.append(robot_forger.liveliness().declare_token(late_op))  # forged, live
        # Positive control: each role's own tokens, through the same router.
        real_op = keys.alive_operator(ROBOT, "op-real")
        tokens.append(op_forger.liveliness().declare_token(real_op))
        wait_until("the operator's token at the robot", lambda: real_op in on_robot.alive, 5)
        assert not on_operator.seen, "an operator certificate declared the robot's token"
        tokens.append(robot_forger.liveliness().declare_token(robot_token))
        wait_until("the robot's token at the operator", lambda: robot_token in on_operator.alive, 5)
        time.sleep(0.3)
        assert on_robot.seen == {real_op}, "a robot certificate declared an operator's token"
    finally:
        for token in tokens:
            token.undeclare()
        for watcher in watchers:
            watcher.close()
        for session in sessions:
            session.close()
