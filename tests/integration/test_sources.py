"""Command sources and locks end to end (DESIGN 14, issue 29): the robot process on
``--driver zenoh`` (or ``sim``), a navigation source and locks published over Zenoh by the test,
the test's Observer as scans, base recorder and an outside operator.

Times are measured on the robot's own stamps: every cycle's base command carries the cycle's
time and number (``egc/<robot>/base/cmd``), the state message of the cycle that changed the
source or lock carries the same time, and the telemetry's ``source_age_ms`` says when the
command of the source that drives arrived. So "the first cycle after the timeout" is checked as
"no cycle ran between the timeout and the switch", whatever the machine's load; only the lock's
150 ms includes the lock message's way to the robot (the test's clock is CLOCK_MONOTONIC, the
robot's too)."""

from __future__ import annotations

import json
import threading
import time
from pathlib import Path

import pytest
import zenoh
from egc_common import keys
from egc_common.messages import BaseCommand
from egc_common.source_msg import SourceCommand, encode_lock
from egc_common.transport import command_publisher, free_tcp_port, loopback_endpoint

from tests.integration.harness import (
    MS,
    ROBOT,
    Observer,
    Processes,
    joystick_file,
    operator_args,
    robot_args,
)

pytestmark = [pytest.mark.integration, pytest.mark.timeout(180)]

NAV = """
[[source]]
name = "nav"
kind = "zenoh"
priority = 10
timeout_s = 0.5

[[source]]
name = "teleop"
kind = "operator"
priority = 100
timeout_s = 0.5
"""
PAUSE = """
[[lock]]
name = "pause"
priority = 200
timeout_s = 1.0
"""
HEARTBEAT = """
[[lock]]
name = "hb"
priority = 50
timeout_s = 0.3
"""
TIMEOUT_NS = 500 * MS
V_NAV = 0.1  # m/s; the Pioneer 3-DX's v_max is 0.14


class Feed:
    """A navigation source or a lock's heartbeat, published by the test at a fixed rate until
    paused (``value`` changes take effect at once: one message goes out on the change)."""

    def __init__(self, session: zenoh.Session, key: str, encode, value, period_s: float) -> None:
        self._publisher = command_publisher(session, key)
        self._encode = encode
        self._lock = threading.Lock()
        self.value = value
        self.paused = False
        self.last_put_ns = 0
        self._stop = threading.Event()
        self._period_s = period_s
        self._thread = threading.Thread(target=self._loop, daemon=True)
        self._thread.start()

    def _put(self) -> None:
        with self._lock:
            self._publisher.put(self._encode(self.value))
            self.last_put_ns = time.monotonic_ns()

    def set(self, value) -> int:
        """Change the value and send it now; returns when it was sent."""
        with self._lock:
            self.value = value
            self.paused = False
            before = time.monotonic_ns()
            self._publisher.put(self._encode(value))
            self.last_put_ns = time.monotonic_ns()
        return before

    def pause(self) -> int:
        """Stop sending; returns when the last message went out."""
        with self._lock:
            self.paused = True
            return self.last_put_ns

    def _loop(self) -> None:
        while not self._stop.wait(self._period_s):
            if not self.paused:
                self._put()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2)
        self._publisher.undeclare()


def nav_feed(session: zenoh.Session, v_mps: float = V_NAV) -> Feed:
    seq = iter(range(1, 10**9))

    def encode(v: float) -> bytes:
        return SourceCommand(next(seq), 0, v, 0.0).encode()

    return Feed(session, keys.source(ROBOT, "nav"), encode, v_mps, 0.05)


def lock_feed(session: zenoh.Session, name: str, value: bool, period_s: float = 0.1) -> Feed:
    return Feed(session, keys.lock(ROBOT, name), encode_lock, value, period_s)


@pytest.fixture
def feeds():
    opened: list[Feed] = []
    yield opened
    for feed in opened:
        feed.close()


def start_robot(procs: Processes, port: int, tmp_path: Path, toml: str, *extra: str) -> None:
    config = tmp_path / "robot.toml"
    config.write_text(toml)
    procs.start("robot", *robot_args(port, "--config", str(config), *extra))


def wait_state(observer: Observer, what: str, predicate, timeout_s: float = 30.0):
    """The first state message (arrival order) matching ``predicate``."""

    def found():
        with observer._lock:
            return next((s for _, s in observer.rec.state if predicate(s)), None)

    return observer.wait_for(what, found, timeout_s)


def bases(observer: Observer) -> list[BaseCommand]:
    return [b for _, b in observer.base()]


def source_arrival_ns(observer: Observer, source: str, seq: int | None = None) -> int:
    """When (robot clock) the newest command of ``source`` arrived, from the last telemetry
    that says ``source`` drives (optionally: while its command had ``seq``)."""
    ts = [t for t in observer.telemetry() if t.source == source and (seq is None or t.seq == seq)]
    assert ts, f"no telemetry with source {source}"
    t = ts[-1]
    assert t.source_age_ms is not None
    return t.stamp_ns - round(t.source_age_ms * MS)


def nav_driving(observer: Observer, since_ns: int = 0):
    return observer.wait_for(
        "navigation driving",
        lambda: next(
            (
                t
                for t in observer.telemetry(since_ns)
                if t.source == "nav" and t.state == "DRIVING" and t.v_cmd > 0.9 * V_NAV
            ),
            None,
        ),
        30.0,
    )


def test_navigation_drives_an_operator_takes_over_at_once_and_hands_back_after_its_timeout(
    procs, port, observer, feeds, tmp_path
):
    start_robot(procs, port, tmp_path, NAV)
    observer.start_scans()
    feeds.append(nav_feed(observer.session))
    t = nav_driving(observer)
    assert (t.reason, t.mode, t.operator) == ("source nav", "shared", None)
    assert t.v_ref == pytest.approx(V_NAV)  # the velocity as the source gave it (no eq. 4)

    # One command from an operator (priority 100), then it falls silent.
    observer.put_cmd(observer.command(1, 0, op="sup"))
    took = wait_state(observer, "the operator's source", lambda s: s.source == "teleop")
    back = wait_state(
        observer,
        "navigation again",
        lambda s: s.source == "nav" and s.stamp_ns > took.stamp_ns,
    )
    arrived_ns = source_arrival_ns(observer, "teleop", seq=1)
    cycles = bases(observer)
    # Within one control cycle of its first command: at most one cycle ran between its arrival
    # and the cycle that gave it the base (in fact none: the command runs a cycle itself).
    between = [b.seq for b in cycles if arrived_ns <= b.stamp_ns < took.stamp_ns]
    assert len(between) <= 1, (between, (took.stamp_ns - arrived_ns) / MS)
    assert took.stamp_ns >= arrived_ns
    assert took.operator == "sup"
    # Navigation drives again after the operator's timeout, at the first cycle after it.
    assert back.stamp_ns > arrived_ns + TIMEOUT_NS
    late = [b.seq for b in cycles if arrived_ns + TIMEOUT_NS < b.stamp_ns < back.stamp_ns]
    assert late == [], late
    teleop = [b for b in cycles if took.stamp_ns <= b.stamp_ns < back.stamp_ns]
    assert len(teleop) >= 5
    # The operator's centred stick: the base ramped down from navigation's speed, no jump.
    assert teleop[0].linear_mps > 0.0 and teleop[-1].linear_mps < teleop[0].linear_mps
    nav_driving(observer, since_ns=back.stamp_ns)


def test_a_lock_stops_everything_within_150_ms_and_releasing_it_lets_navigation_drive(
    procs, port, observer, feeds, tmp_path
):
    start_robot(procs, port, tmp_path, NAV + PAUSE)
    observer.start_scans()
    pause = lock_feed(observer.session, "pause", False)
    feeds += [nav_feed(observer.session), pause]
    nav_driving(observer)
    sent_ns = pause.set(True)
    locked = wait_state(observer, "the lock", lambda s: s.lock == "pause" and s.stamp_ns > sent_ns)
    assert locked.stamp_ns - sent_ns < 150 * MS, (locked.stamp_ns - sent_ns) / MS
    assert (locked.state, locked.source, locked.reason) == ("HOLD", None, "lock pause: true")
    # An operator of lower priority than the lock cannot drive either.
    observer.start_operator(x=1.0)
    time.sleep(1.5)
    observer.stick["paused"] = True
    time.sleep(0.7)  # its claim on the base ends (timeout_s 0.5)
    cycles = bases(observer)
    zeros = [b for b in cycles if b.stamp_ns >= sent_ns and b.linear_mps == 0.0]
    assert zeros and zeros[0].stamp_ns - sent_ns < 150 * MS
    after = [b for b in cycles if b.stamp_ns >= locked.stamp_ns]
    assert len(after) >= 20
    assert all((b.linear_mps, b.angular_radps) == (0.0, 0.0) for b in after), after[:3]
    assert all(t.lock == "pause" for t in observer.telemetry() if t.stamp_ns >= locked.stamp_ns)

    released_ns = pause.set(False)
    free = wait_state(
        observer, "the lock released", lambda s: s.lock is None and s.stamp_ns > released_ns
    )
    assert free.source == "nav"
    nav_driving(observer, since_ns=free.stamp_ns)


def test_a_lock_whose_feed_falls_silent_stays_locked(procs, port, observer, feeds, tmp_path):
    start_robot(procs, port, tmp_path, NAV + HEARTBEAT)
    observer.start_scans()
    hb = lock_feed(observer.session, "hb", False)
    feeds += [nav_feed(observer.session), hb]
    nav_driving(observer)
    last_beat_ns = hb.pause()
    locked = wait_state(
        observer,
        "the silent heartbeat's lock",
        lambda s: s.lock == "hb" and s.stamp_ns > last_beat_ns,
    )
    assert locked.stamp_ns > last_beat_ns + 300 * MS  # not before its timeout
    assert locked.reason.startswith("lock hb: silent for")
    time.sleep(2.0)  # navigation keeps sending all along
    after = [b for b in bases(observer) if b.stamp_ns >= locked.stamp_ns]
    assert len(after) >= 30
    assert all(b.linear_mps == 0.0 for b in after)
    held = [t for t in observer.telemetry() if t.stamp_ns >= locked.stamp_ns]
    assert len(held) >= 10 and all(t.lock == "hb" and t.state == "HOLD" for t in held)
    beat_ns = hb.set(False)
    wait_state(observer, "the heartbeat back", lambda s: s.lock is None and s.stamp_ns > beat_ns)
    nav_driving(observer, since_ns=beat_ns)


def test_when_no_source_may_drive_the_base_gets_zero_at_the_first_cycle_after_the_timeout(
    procs, port, observer, feeds, tmp_path
):
    start_robot(procs, port, tmp_path, NAV)
    observer.start_scans()
    nav = nav_feed(observer.session)
    feeds.append(nav)
    nav_driving(observer)
    last_put_ns = nav.pause()
    stopped = wait_state(
        observer, "no source", lambda s: s.source is None and s.stamp_ns > last_put_ns
    )
    last_ns = source_arrival_ns(observer, "nav")
    assert stopped.stamp_ns > last_ns + TIMEOUT_NS
    # The state message and the base command of a cycle are separate samples: on a busy machine
    # the state came first and no base command after the timeout had arrived yet (CI run 139).
    observer.wait_for(
        "the base command of the cycle that stopped",
        lambda: any(b.stamp_ns >= stopped.stamp_ns for b in bases(observer)),
    )
    cycles = bases(observer)
    moving = [b for b in cycles if last_ns <= b.stamp_ns <= last_ns + TIMEOUT_NS]
    assert moving and all(b.linear_mps > 0.0 for b in moving)  # it drove until the timeout
    # Zero at once (no deceleration ramp) from the first cycle after the timeout on.
    expired = [b for b in cycles if b.stamp_ns > last_ns + TIMEOUT_NS]
    assert expired and expired[0].stamp_ns == stopped.stamp_ns
    assert all((b.linear_mps, b.angular_radps) == (0.0, 0.0) for b in expired)
    idle = observer.wait_state("IDLE", 5.0, since_ns=stopped.stamp_ns)
    assert idle.reason == "no source fresh"


BOX = """
name = "box"
resolution_m = 0.05
bounds_m = [-0.3, -0.3, 8.3, 4.3]
[[segments]]
from_m = [-0.1, -0.1]
to_m = [8.1, -0.1]
thickness_m = 0.2
[[segments]]
from_m = [-0.1, 4.1]
to_m = [8.1, 4.1]
thickness_m = 0.2
[[segments]]
from_m = [-0.1, -0.1]
to_m = [-0.1, 4.1]
thickness_m = 0.2
[[segments]]
from_m = [8.1, -0.1]
to_m = [8.1, 4.1]
thickness_m = 0.2
"""
WALL_X_M = 8.0


def _drive_into_the_wall(
    procs: Processes, port: int, tmp_path: Path, who: str
) -> tuple[dict, float]:
    """A Jackal at (1, 2) facing the wall at x = 8, driven straight at it at full speed for
    6 s by navigation or by an operator; its summary and the largest x it reached."""
    world = tmp_path / "box.toml"
    world.write_text(BOX)
    summary = tmp_path / f"{who}.json"
    name = f"robot-{who}"
    config = tmp_path / "robot.toml"
    config.write_text(NAV)
    procs.start(
        name,
        "robot",
        "--robot",
        ROBOT,
        "--driver",
        "sim",
        "--map",
        str(world),
        "--start",
        "1,2,0",
        "--profile",
        "jackal",
        "--camera",
        "none",
        "--config",
        str(config),
        "--summary",
        str(summary),
        "--listen",
        loopback_endpoint(port),
    )
    observer = Observer(port)
    feed = None
    try:
        observer.wait_for(
            "telemetry", lambda: observer.last_telemetry() is not None and observer.telemetry(), 30
        )
        if who == "nav":
            feed = nav_feed(observer.session, v_mps=2.0)  # the Jackal's v_max
        else:
            observer.start_operator(x=0.0)
            observer.wait_state("DRIVING", 10.0)
            observer.stick["x"] = 1.0
        time.sleep(6.0)
        xs = [t.pose[0] for t in observer.telemetry() if t.pose is not None]
        last = observer.telemetry()[-1]
        assert last.state == "DRIVING" and abs(last.v_cmd) < 0.05, last  # asked on, held still
    finally:
        if feed is not None:
            feed.close()
        observer.close()
    assert procs.stop(name) == 0
    return json.loads(summary.read_text()), max(xs)


def test_a_navigation_command_into_a_wall_is_stopped_by_the_filter_like_an_operators(
    procs, tmp_path
):
    nav_summary, nav_x = _drive_into_the_wall(procs, free_tcp_port(), tmp_path, "nav")
    op_summary, op_x = _drive_into_the_wall(procs, free_tcp_port(), tmp_path, "op")
    half_length = 0.254  # the Jackal's
    for summary, x in ((nav_summary, nav_x), (op_summary, op_x)):
        assert summary["collisions"] == 0
        assert summary["interventions"] > 0  # the filter acted on the command
        assert 3.0 < x < WALL_X_M - half_length, x  # it drove, and stopped short of the wall
    assert abs(nav_x - op_x) < 0.2, (nav_x, op_x)


def test_a_supervisor_takes_control_at_once_and_the_other_operator_is_told_who(
    procs, port, observer, tmp_path
):
    """[[operator]] priorities (DESIGN 14), two real operator processes: ``op`` drives, the
    supervisor ``sup`` (priority 100) takes control with its first command, and ``op``'s status
    line (plain lines in its log) says who took control."""
    start_robot(procs, port, tmp_path, '[[operator]]\nid = "sup"\npriority = 100\n')
    observer.start_scans()
    # The robot has the scans before op starts: op's centred half second must find the sensor
    # fresh, or the robot holds for a centred stick that never comes (op's stick stays forward).
    observer.wait_for(
        "the robot's telemetry with a scan",
        lambda: (t := observer.last_telemetry()) is not None and len(t.scan_xy) > 0,
        30.0,
    )
    stick = joystick_file(tmp_path / "op.csv", [(0, 0, 0, 1), (0.5, 0.5, 0, 1), (60, 0.5, 0, 1)])
    with_status = [a for a in operator_args(port, "op", stick) if a != "--no-status"]
    procs.start("op", *with_status)
    observer.wait_for(
        "op driving",
        lambda: any(t.operator == "op" and t.v_cmd > 0.03 for t in observer.telemetry()),
        30.0,
    )
    centred = joystick_file(tmp_path / "sup.csv", [(0, 0, 0, 1), (60, 0, 0, 1)])
    procs.start("sup", *operator_args(port, "sup", centred))
    took = wait_state(observer, "the supervisor in control", lambda s: s.operator == "sup")
    assert took.state in ("DRIVING", "HOLD")
    deadline = time.monotonic() + 20
    while "TAKEN OVER: sup took control" not in procs.log("op"):
        assert time.monotonic() < deadline, procs.log("op")[-2000:]
        time.sleep(0.1)
    # op keeps its stick forward: it never gets control back while sup is there.
    time.sleep(1.0)
    assert all(t.operator == "sup" for t in observer.telemetry() if t.stamp_ns > took.stamp_ns)
    assert "operator sup took control from op (higher priority)" in procs.log("robot")
