"""``egc-teleop router`` (DESIGN 10): a Zenoh router in our own process, for sites without zenohd.

- A robot (``--driver zenoh``: the test is its sensor and watches its base commands) and an
  operator process, both clients of an ``egc-teleop router`` process, exchange commands and
  telemetry through it; the router logs the clients that join; SIGTERM stops it with code 0.
- The same over ``udp/`` (the robot and the operator reach the router over UDP, the test's own
  client over TCP): the router adds the same UDP link settings as every process.
- A port in use and a bad configuration file are one error line and exit code 2.
"""

from __future__ import annotations

import subprocess
import sys
import time

import pytest
from egc_common.transport import free_port

from tests.integration.harness import ROBOT, Observer, forward_file, operator_args
from tests.integration.test_link import wait_full_speed

pytestmark = [pytest.mark.integration, pytest.mark.timeout(90)]


def start_router(procs, *listen: str) -> None:
    args = ["router"]
    for endpoint in listen:
        args += ["--listen", endpoint]
    proc = procs.start("router", *args)
    deadline = time.monotonic() + 20
    while "listening on" not in procs.log("router"):
        assert proc.poll() is None, procs.log("router")
        assert time.monotonic() < deadline, "the router did not say it listens"
        time.sleep(0.02)


@pytest.mark.parametrize("proto", ["tcp", "udp"])
def test_robot_and_operator_drive_through_egc_teleop_router(proto, port, procs, tmp_path):
    clients = f"{proto}/127.0.0.1:{free_port(proto) if proto == 'udp' else port}"
    listen = [f"tcp/127.0.0.1:{port}"] + ([clients] if proto == "udp" else [])
    start_router(procs, *listen)
    observer = Observer(port, mode="client")
    try:
        client = ["--zenoh-mode", "client", "--connect", clients]
        procs.start("robot", "robot", "--robot", ROBOT, "--driver", "zenoh", *client)
        observer.wait_for("robot telemetry through the router", observer.last_telemetry, 15)
        observer.start_scans()
        js = forward_file(tmp_path)
        op = operator_args(port, "alice", js, "--zenoh-mode", "client")
        op[op.index("--zenoh-connect") + 1] = clients  # over UDP in the udp case
        procs.start("op", *op)
        wait_full_speed(observer)
        last = observer.last_telemetry()
        assert last is not None and last.operator == "alice", last
        # the operator's clock queries crossed the router: its commands carry robot-clock
        # stamps (the median: one cycle's age is one scheduling hiccup away from 100 ms)
        ages = sorted(t.cmd_age_ms for t in observer.telemetry() if t.cmd_age_ms is not None)
        assert ages and 0 <= ages[len(ages) // 2] < 100, ages
        observer.wait_for(
            "the operator's liveliness token at the robot",
            lambda: "operator alice alive" in procs.log("robot"),
            5,
        )
        # the operator sees the robot's telemetry and state through the router
        observer.wait_for("the operator sees the robot", lambda: "robot DRIVING" in procs.log("op"))
        assert procs.stop("op") == 0, procs.log("op")
        assert procs.alive("robot"), procs.log("robot")
        assert procs.stop("robot") == 0, procs.log("robot")
    finally:
        observer.close()
    log = procs.log("router")
    assert log.count("client") >= 3 and "joined" in log and "left" in log, log
    assert procs.stop("router") == 0, log
    assert "router: stopped" in procs.log("router")


def test_port_in_use_and_bad_config_are_one_line_and_exit_2(port, procs, tmp_path):
    start_router(procs, f"tcp/127.0.0.1:{port}")
    cmd = [sys.executable, "-m", "egc_app.cli", "router"]
    taken = subprocess.run(
        [*cmd, "--listen", f"tcp/127.0.0.1:{port}"],
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert taken.returncode == 2
    assert taken.stderr.count("\n") == 1 and "Address already in use" in taken.stderr
    bad = tmp_path / "bad.json5"
    bad.write_text("{ mode: 'router', listen: { endpoints: 5 } }")
    free = f"tcp/127.0.0.1:{free_port()}"
    wrong = subprocess.run(
        [*cmd, "--listen", free, "--zenoh-config", str(bad)],
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert wrong.returncode == 2
    assert wrong.stderr.count("\n") == 1 and "invalid zenoh config" in wrong.stderr
    assert procs.stop("router") == 0


def test_the_robot_log_says_when_its_router_goes_and_comes_back(port, procs):
    """Outside check: a router that went down showed in the robot's log only as "operator ...
    lost", then HOLD and IDLE, with no word of the cause; nor did its return."""
    start_router(procs, f"tcp/127.0.0.1:{port}")
    client = ["--zenoh-mode", "client", "--connect", f"tcp/127.0.0.1:{port}"]
    procs.start("robot", "robot", "--robot", ROBOT, "--driver", "zenoh", *client)
    deadline = time.monotonic() + 20
    while "Zenoh connection to router" not in procs.log("robot"):
        assert time.monotonic() < deadline, procs.log("robot")
        time.sleep(0.05)
    assert "open" in procs.log("robot")
    assert procs.stop("router") == 0
    deadline = time.monotonic() + 15
    while "no Zenoh connection left" not in procs.log("robot"):
        assert time.monotonic() < deadline, procs.log("robot")
        time.sleep(0.05)
    start_router(procs, f"tcp/127.0.0.1:{port}")
    deadline = time.monotonic() + 30  # the client retries with a growing period
    while procs.log("robot").count("Zenoh connection to router") < 3:
        assert time.monotonic() < deadline, procs.log("robot")
        time.sleep(0.05)
    assert procs.alive("robot") and procs.stop("robot") == 0, procs.log("robot")
