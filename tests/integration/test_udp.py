"""Robot and operator over ``udp/`` endpoints (DESIGN 9 "Transport", issue 12 item 6).

``egc_common.transport`` turns a plain ``udp/HOST:PORT`` into two links of one Zenoh transport:
``tcp/HOST:PORT`` for the reliable control traffic (declarations, liveliness, queries) and
``udp/HOST:PORT?rel=0`` for the best-effort data (commands, telemetry). The robot
(``--driver zenoh``: the test is its sensor and watches its base commands over its own
``tcp/`` port) also listens on such a ``udp/`` endpoint; the operator process reaches it only
through that one, directly or through ``egc-teleop link`` with ``udp/`` endpoints (which relays
the TCP half on the same port numbers, without loss).

- Direct: the operator drives; its liveliness token, its clock queries (robot-clock stamps,
  small command ages), the robot's state and telemetry all cross the UDP link.
- Through a UDP relay with 5 % loss each way and 20 ms delay: the session opens and stays up,
  the operator drives, the relay counts the datagrams it forwarded and dropped, and the robot
  never HOLDs for more than a few cycles at a time.
- A 1 s outage of the UDP relay: HOLD, then driving again without re-centring (short-gap
  resume, DESIGN 8), as over TCP (test_link_outage).
- Session start through 20 % loss on the UDP datagrams, ten sessions in a row: every one carries
  the declarations (the other side's liveliness token is seen, best-effort data flows), because
  a connecting process opens the TCP half first (``egc_common.transport._tcp_first``).
"""

from __future__ import annotations

import json
import threading
import time
from pathlib import Path

import pytest
import zenoh
from egc_common.transport import ZenohOptions, free_port, open_session

from tests.integration.harness import (
    MS,
    first_motion_after,
    first_state_after,
    forward_file,
    operator_args,
    start_link,
)
from tests.integration.test_link import finish, start_robot, wait_full_speed

pytestmark = [pytest.mark.integration, pytest.mark.timeout(120)]


start_relay = start_link


def robot_on_tcp_and_udp(procs, observer, port: int) -> str:
    """The robot listening on tcp/:port (the observer) and on a UDP port; returns the latter."""
    udp = f"udp/127.0.0.1:{free_port('udp')}"
    start_robot(procs, observer, port, "--listen", udp)
    return udp


def udp_operator(port: int, endpoint: str, op_id: str, js: Path, *extra: str) -> list[str]:
    args = operator_args(port, op_id, js, *extra)
    args[args.index("--zenoh-connect") + 1] = endpoint
    return args


def test_an_operator_drives_the_robot_over_udp(port, procs, observer, tmp_path):
    udp = robot_on_tcp_and_udp(procs, observer, port)
    procs.start("op", *udp_operator(port, udp, "alice", forward_file(tmp_path)))
    wait_full_speed(observer)
    since = time.monotonic_ns()
    observer.wait_for("a second of telemetry", lambda: observer.telemetry(since + 10**9), 10)
    driving = [t for t in observer.telemetry(since) if t.state == "DRIVING"]
    assert len(driving) >= 15 and all(t.operator == "alice" for t in driving), driving[-1:]
    ages = sorted(t.cmd_age_ms for t in driving if t.cmd_age_ms is not None)
    assert ages and ages[len(ages) // 2] < 30, ages  # clock queries answered over UDP
    assert "operator alice alive" in procs.log("robot")  # liveliness over UDP
    observer.wait_for("the operator sees the robot", lambda: "robot present" in procs.log("op"))
    observer.wait_for("the operator's state view", lambda: "robot DRIVING" in procs.log("op"))
    assert driving[-1].rejected == 0
    assert procs.stop("op") == 0, procs.log("op")
    observer.wait_for("operator gone", lambda: "operator alice lost" in procs.log("robot"), 5)
    finish(procs, observer)


def test_udp_through_a_lossy_relay(port, procs, observer, tmp_path):
    udp = robot_on_tcp_and_udp(procs, observer, port)
    relay = f"udp/127.0.0.1:{free_port('udp')}"
    spec = "delay=20,loss=5"
    stats = tmp_path / "link.json"
    start_relay(procs, relay, udp, "--up", spec, "--down", spec, "--stats", str(stats))
    procs.start("op", *udp_operator(port, relay, "alice", forward_file(tmp_path)))
    wait_full_speed(observer, timeout_s=20)
    since = time.monotonic_ns()
    time.sleep(4.0)
    window = observer.telemetry(since)
    driving = [t for t in window if t.state == "DRIVING"]
    # 50 Hz commands with 5 % loss: gaps of 250 ms (12 lost in a row) are all but impossible
    assert len(driving) >= 0.9 * len(window), [t.reason for t in window if t.state != "DRIVING"]
    ages = sorted(t.cmd_age_ms for t in driving if t.cmd_age_ms is not None)
    assert ages and 15 <= ages[len(ages) // 2] < 60, ages  # 20 ms delay, synchronised clocks
    loss = [t.link_loss for t in driving if t.link_loss is not None]
    assert loss and 0.0 < max(loss) < 0.25, loss  # the robot sees the loss in the seq gaps
    assert procs.stop("op") == 0, procs.log("op")
    assert procs.stop("link") == 0, procs.log("link")
    report = json.loads(stats.read_text())
    for direction in ("up", "down"):
        d = report[direction]
        assert d["forwarded"] > 200 and d["dropped"] > 0, report
        assert 2.0 < d["loss_pct"] < 10.0, report
    finish(procs, observer)


def test_one_second_udp_outage_resumes_without_centring(port, procs, observer, tmp_path):
    udp = robot_on_tcp_and_udp(procs, observer, port)
    relay = f"udp/127.0.0.1:{free_port('udp')}"
    # after the relay's start: time to reach full speed first (see test_link_outage)
    outage_start_s = 15.0
    t0 = start_relay(procs, relay, udp, "--up", f"outage={outage_start_s:g}+1", "--down",
                     f"outage={outage_start_s:g}+1")  # fmt: skip
    procs.start("op", *udp_operator(port, relay, "alice", forward_file(tmp_path, 90)))
    wait_full_speed(observer)
    begin = t0 + int(outage_start_s * 1e9)
    end = begin + 1_000_000_000
    assert time.monotonic_ns() < begin - 500 * MS, "the operator took too long to drive"
    hold = observer.wait_for(
        "HOLD", lambda: first_state_after(observer, "HOLD", begin), outage_start_s + 5
    )
    assert (hold - begin) / MS <= 250 + 100
    moving = observer.wait_for("moving again", lambda: first_motion_after(observer, end), 5)
    assert (moving - end) / MS <= 300
    t = observer.wait_state("DRIVING", since_ns=end)
    assert t.reason == "resumed after a link gap", t
    assert not any("lost" in s.reason for _, s in observer.rec.state)
    finish(procs, observer)


def test_sessions_through_heavy_udp_loss_always_carry_their_declarations(procs):
    listen = f"udp/127.0.0.1:{free_port('udp')}"
    relay = f"udp/127.0.0.1:{free_port('udp')}"
    robot = open_session(ZenohOptions(listen=(listen,)))
    try:
        start_relay(procs, relay, listen, "--up", "loss=20", "--down", "loss=20")
        got: list[int] = []
        sub = robot.declare_subscriber("itest/udp/data", lambda s: got.append(1))
        token = robot.liveliness().declare_token("itest/udp/alive/robot")
        broken = []
        closing: list[threading.Thread] = []
        for trial in range(10):
            seen: list[str] = []
            operator = open_session(ZenohOptions(connect=(relay,)))
            watch = operator.liveliness().declare_subscriber(
                "itest/udp/alive/**",
                lambda s, seen=seen: seen.append(str(s.key_expr)),
                history=True,
            )
            pub = operator.declare_publisher(
                "itest/udp/data", reliability=zenoh.Reliability.BEST_EFFORT
            )
            before = len(got)
            deadline = time.monotonic() + 3.0
            while time.monotonic() < deadline and not (seen and len(got) > before + 5):
                pub.put(b"x" * 100)
                time.sleep(0.02)
            if not seen or len(got) <= before + 5:
                broken.append((trial, len(seen), len(got) - before))
            watch.undeclare()
            pub.undeclare()
            # closing over a lossy UDP link can take Zenoh ~10 s: do not wait for each one
            closing.append(threading.Thread(target=operator.close, daemon=True))
            closing[-1].start()
        for thread in closing:
            thread.join(15)
        assert not broken, f"sessions without declarations (trial, tokens, data): {broken}"
        token.undeclare()
        sub.undeclare()
    finally:
        robot.close()
