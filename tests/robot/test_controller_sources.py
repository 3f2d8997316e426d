"""RobotController with command sources and locks (DESIGN 14), on a simulated clock.

A navigation source (``zenoh`` or ``ros2``) at priority 10, the operators' source at 100, locks
at 200; every velocity goes through the same pipeline, and the cycle after a source's timeout
or a lock's change already acts."""

from __future__ import annotations

import math

import msgpack
import numpy as np
import pytest
from egc_common.messages import decode_state, decode_telemetry
from egc_common.profiles import get_profile
from egc_common.scan import Scan
from egc_common.source_msg import SourceCommand, encode_lock
from egc_robot.controller import ControllerConfig, RobotController
from egc_robot.pipeline import PipelineConfig
from egc_robot.source_mux import LockSpec, MuxConfig, SourceSpec

MS = 1_000_000
T0 = 3600 * 1000 * MS
PROFILE = get_profile("pioneer3dx")
V_MAX = PROFILE.v_max_mps

NAV = SourceSpec("nav", "zenoh", 10, 0.5)
NAV_ROS = SourceSpec("nav", "ros2", 10, 0.5, topic="/cmd_vel_nav")
TELEOP = SourceSpec("teleop", "operator", 100, 0.3)
PAUSE = LockSpec("pause", 200, 1.0)
HEARTBEAT = LockSpec("hb", 300, 0.2)


def scan_at(r: float = 5.0, n: int = 360) -> Scan:
    return Scan.uniform(np.full(n, r), -math.pi, 2 * math.pi / n, 0.05, 10.0)


def wall_ahead(x_m: float, n: int = 360) -> Scan:
    """A wall across the x axis at ``x_m`` (nothing behind)."""
    angles = -math.pi + 2 * math.pi / n * np.arange(n)
    c = np.cos(angles)
    with np.errstate(divide="ignore"):
        ranges = np.where(c > 1e-6, x_m / c, np.inf)
    return Scan.uniform(np.minimum(ranges, 9.0), -math.pi, 2 * math.pi / n, 0.05, 10.0)


class Rig:
    def __init__(
        self,
        sources=(NAV, TELEOP),
        locks=(),
        operators=(),
        scan: Scan | None = None,
        **config: object,
    ) -> None:
        mux = MuxConfig(tuple(sources), tuple(locks))
        cfg = ControllerConfig(
            PipelineConfig(PROFILE),
            sources=mux,
            operator_priorities=tuple(operators),
            **config,  # type: ignore[arg-type]
        )
        self.now = T0
        self.c = RobotController(cfg, self.now)
        self.scan = scan or scan_at()
        self.nav_seq = 0
        self.op_seq: dict[str, int] = {}

    def nav(self, v: float, w: float = 0.0, stamp_ns: int | None = None):
        self.nav_seq += 1
        stamp = self.now - MS if stamp_ns is None else stamp_ns
        return self.c.on_source("nav", SourceCommand(self.nav_seq, stamp, v, w).encode(), self.now)

    def op(self, x: float = 0.0, op: str = "alice", **kw: object):
        self.op_seq[op] = self.op_seq.get(op, 0) + 1
        msg = {"v": 1, "seq": self.op_seq[op], "stamp_ns": self.now - MS, "x": x, "y": 0.0}
        msg |= {"mode": "shared", "deadman": True, "estop": False, "reset": False, "op": op}
        return self.c.on_command(msgpack.packb(msg | kw), self.now)

    def cycle(self, dt_ms: float = 50.0, scan: bool = True):
        self.now += int(dt_ms * MS)
        if scan:
            self.c.on_scan(self.scan, self.now)
        return self.c.step(self.now)

    def nav_drives(self, v: float = V_MAX, cycles: int = 20):
        out = None
        for _ in range(cycles):
            self.nav(v)
            out = self.cycle()
        return out


def test_a_navigation_source_drives_at_once_and_ramps_at_the_profiles_limits():
    rig = Rig()
    rig.nav(V_MAX)
    first = rig.cycle()
    t = first.telemetry
    assert (t.state, t.reason, t.source, t.mode) == ("DRIVING", "source nav", "nav", "shared")
    assert t.v_ref == pytest.approx(V_MAX)  # no eq. 4: the velocity as the source gave it
    # Ramped from standstill at the acceleration limit, not a jump to the command.
    assert 0.0 < first.base.linear_mps <= PROFILE.accel_max_mps2 * 0.05 + 1e-9
    out = rig.nav_drives()
    assert out.base.linear_mps == pytest.approx(V_MAX)
    assert out.telemetry.operator is None
    assert out.telemetry.seq == rig.nav_seq
    assert out.telemetry.source_age_ms == pytest.approx(50.0)


def test_a_ros2_source_drives_through_the_same_pipeline():
    rig = Rig(sources=(NAV_ROS, TELEOP))
    for _ in range(20):
        assert rig.c.on_source_velocity("nav", 0.1, 0.2, rig.now).accepted
        out = rig.cycle()
    assert (out.base.linear_mps, out.base.angular_radps) == pytest.approx((0.1, 0.2))
    assert out.telemetry.source == "nav"
    # The zenoh key of the same name is not this source.
    assert not rig.c.on_source("nav", SourceCommand(1, 0, 0.1, 0.0).encode(), rig.now).accepted
    for bad in (math.nan, math.inf, 1e9):
        assert not rig.c.on_source_velocity("nav", bad, 0.0, rig.now).accepted
    assert rig.c.counters.rejected["source_out_of_range"] == 3


def test_an_operator_of_higher_priority_takes_over_in_the_cycle_of_its_first_command():
    rig = Rig()
    rig.nav_drives()
    verdict = rig.op(x=0.0)
    assert verdict.accepted and verdict.took_control
    rig.nav(V_MAX)
    out = rig.cycle()
    t = out.telemetry
    assert (t.state, t.source, t.operator) == ("DRIVING", "teleop", "alice")
    assert out.state_changed is not None and out.state_changed.source == "teleop"
    # Centred stick: the base ramps down at the deceleration limit, not a jump to zero.
    assert V_MAX - PROFILE.decel_max_mps2 * 0.05 - 1e-9 <= out.base.linear_mps < V_MAX


def test_an_operator_taking_over_with_a_deflected_stick_holds_until_it_is_centred():
    rig = Rig()
    rig.nav_drives()
    rig.op(x=1.0)
    rig.nav(V_MAX)
    t = rig.cycle().telemetry
    assert (t.state, t.reason, t.source) == ("HOLD", "waiting for a centred stick", "teleop")


def test_a_silent_operator_hands_back_at_the_first_cycle_after_its_timeout():
    rig = Rig()
    rig.nav_drives(cycles=5)
    rig.op()
    last_op_ns = rig.now
    for _ in range(3):
        rig.nav(V_MAX)
        assert rig.cycle(dt_ms=10).telemetry.source == "teleop"
    # The operator falls silent; navigation keeps sending.
    while rig.now + 10 * MS <= last_op_ns + TELEOP.timeout_ns:
        rig.nav(V_MAX)
        assert rig.cycle(dt_ms=10).telemetry.source == "teleop"
    rig.nav(V_MAX)
    out = rig.cycle(dt_ms=10)
    assert rig.now > last_op_ns + TELEOP.timeout_ns
    assert (out.telemetry.source, out.telemetry.reason) == ("nav", "source nav")
    assert out.state_changed is not None


def test_an_operator_that_releases_the_deadman_hands_back_after_its_timeout():
    rig = Rig()
    rig.nav_drives(cycles=5)
    rig.op()
    claim_ns = rig.now  # the last command with the deadman held
    rig.nav(V_MAX)
    assert rig.cycle().telemetry.source == "teleop"
    sources = []
    while rig.now < claim_ns + 600 * MS:
        rig.op(deadman=False)
        rig.nav(V_MAX)
        t = rig.cycle().telemetry
        sources.append((rig.now - claim_ns, t.source, t.state, t.reason))
    for dt, source, state, reason in sources:
        if dt <= TELEOP.timeout_ns:  # within the timeout, as the operator asked: a stop
            assert (source, state, reason) == ("teleop", "HOLD", "deadman released"), dt
        elif dt > TELEOP.timeout_ns + 50 * MS:
            assert (source, state) == ("nav", "DRIVING"), dt


def test_a_lock_stops_everything_at_once_and_releasing_it_lets_navigation_drive():
    rig = Rig(locks=(PAUSE,))
    rig.c.on_lock("pause", encode_lock(False), rig.now)
    rig.nav_drives()
    verdict = rig.c.on_lock("pause", encode_lock(True), rig.now)
    assert verdict.accepted and verdict.urgent
    rig.nav(V_MAX)
    rig.op()  # an operator below the lock's priority is blocked too
    out = rig.cycle()
    assert (out.base.linear_mps, out.base.angular_radps) == (0.0, 0.0)  # zero at once
    t = out.telemetry
    assert (t.state, t.reason, t.source, t.lock) == ("HOLD", "lock pause: true", None, "pause")
    state = decode_state(out.state_changed.encode())
    assert (state.source, state.lock) == (None, "pause")
    for _ in range(5):
        rig.c.on_lock("pause", encode_lock(True), rig.now)
        rig.nav(V_MAX)
        assert rig.cycle().base.linear_mps == 0.0
    assert not rig.c.on_lock("pause", encode_lock(True), rig.now).urgent  # no change
    assert rig.c.on_lock("pause", encode_lock(False), rig.now).urgent
    rig.nav(V_MAX)
    t = rig.cycle().telemetry
    assert (t.state, t.source, t.lock) == ("DRIVING", "nav", None)


def test_a_lock_whose_feed_falls_silent_locks_and_stays_locked():
    rig = Rig(locks=(HEARTBEAT,))
    rig.nav(V_MAX)
    assert rig.cycle().telemetry.reason == "lock hb: never heard"
    beats = []
    for _ in range(20):
        rig.c.on_lock("hb", encode_lock(False), rig.now)
        beats.append(rig.now)
        rig.nav(V_MAX)
        assert rig.cycle().telemetry.source == "nav"
    for _ in range(40):  # the heartbeat stops; navigation goes on
        rig.nav(V_MAX)
        out = rig.cycle()
        if rig.now - beats[-1] > HEARTBEAT.timeout_ns:
            assert out.base.linear_mps == 0.0 and out.telemetry.lock == "hb"
            assert out.telemetry.reason.startswith("lock hb: silent for")


def test_when_no_source_is_fresh_the_base_gets_zero_at_once_then_the_robot_is_idle():
    rig = Rig()
    rig.nav_drives()
    last_ns = rig.now - 50 * MS  # navigation's last command, before the last cycle
    outs = []
    for _ in range(15):
        outs.append((rig.now + 50 * MS - last_ns, rig.cycle()))
    for dt, out in outs:
        if dt <= NAV.timeout_ns:
            assert out.base.linear_mps > 0.0 and out.telemetry.source == "nav"
        else:
            assert (out.base.linear_mps, out.base.angular_radps) == (0.0, 0.0), dt
    assert outs[-1][1].telemetry.state == "IDLE"
    assert outs[-1][1].telemetry.reason == "no source fresh"


def test_a_navigation_command_into_a_wall_is_stopped_by_the_filter_like_an_operators():
    """The same wall 0.6 m ahead, full speed ahead: navigation's velocity and the operator's
    full stick give the base the very same commands, and both stop short of the wall."""

    def run(use_nav: bool) -> list[float]:
        rig = Rig(scan=wall_ahead(0.6))
        sent = []
        if not use_nav:
            rig.op(x=0.0)
            rig.cycle()
        for _ in range(60):
            if use_nav:
                rig.nav(V_MAX)
            else:
                rig.op(x=1.0)
            out = rig.cycle()
            assert out.telemetry.state == "DRIVING"
            sent.append(out.base.linear_mps)
        return sent

    nav, op = run(True), run(False)
    assert nav[1:] == pytest.approx(op[1:])  # the operator's first cycle was its centring
    assert max(nav) < V_MAX * 0.9  # the filter acted
    travelled = sum(v * 0.05 for v in nav)
    assert travelled < 0.6 - PROFILE.half_size_m[0], travelled


def test_an_estop_from_any_operator_latches_everything_and_the_operator_in_control_resets():
    rig = Rig()
    rig.nav_drives()
    rig.op(op="bob", deadman=False, estop=True)  # not in control, not even asking to drive
    rig.nav(V_MAX)
    out = rig.cycle()
    assert (out.telemetry.state, out.base.linear_mps) == ("ESTOP", 0.0)
    for _ in range(10):
        rig.nav(V_MAX)
        assert rig.cycle().base.linear_mps == 0.0
    rig.op(op="alice", reset=True)  # takes control, centred, deadman: resets
    rig.nav(V_MAX)
    assert rig.cycle().telemetry.state == "HOLD"


def test_a_stale_scan_holds_a_navigation_source():
    rig = Rig()
    rig.nav_drives()
    for _ in range(6):
        rig.nav(V_MAX)
        out = rig.cycle(scan=False)
    assert (out.telemetry.state, out.telemetry.reason) == ("HOLD", "sensor stale")


def test_zenoh_source_messages_are_vetted_like_commands():
    rig = Rig()
    assert rig.nav(0.1).accepted
    seq = rig.nav_seq
    dup = rig.c.on_source("nav", SourceCommand(seq, rig.now, 0.1, 0).encode(), rig.now)
    old = rig.c.on_source("nav", SourceCommand(seq - 1, rig.now, 0.1, 0).encode(), rig.now)
    stale = rig.nav(0.1, stamp_ns=rig.now - 2000 * MS)
    ahead = rig.nav(0.1, stamp_ns=rig.now + 2000 * MS)
    unknown = rig.c.on_source("dock", SourceCommand(1, 0, 0.1, 0).encode(), rig.now)
    junk = rig.c.on_source("nav", b"\xc1", rig.now)
    too_fast = rig.c.on_source("nav", SourceCommand(99, 0, 1e3, 0).encode(), rig.now)
    assert [v.accepted for v in (dup, old, stale, ahead, unknown, junk, too_fast)] == [False] * 7
    counts = rig.c.counters.rejected
    assert counts["source_duplicate_seq"] == 1 and counts["source_out_of_order"] == 1
    assert counts["source_stale"] == 2 and counts["source_not_in_control"] == 1
    # A source silent past its timeout starts a new session: seq 1 again is accepted.
    rig.now += NAV.timeout_ns + MS
    assert rig.c.on_source("nav", SourceCommand(1, 0, 0.1, 0).encode(), rig.now).accepted
    assert not rig.c.on_lock("pause", encode_lock(True), rig.now).accepted
    assert not rig.c.on_lock("x", b"\x01", rig.now).accepted
    assert rig.c.counters.rejected["lock_wrong_type"] == 1


def test_urgent_says_when_a_source_message_may_change_what_drives():
    rig = Rig(sources=(NAV, SourceSpec("dock", "zenoh", 50, 0.5), TELEOP))
    assert rig.nav(0.1).urgent  # nothing drives yet
    rig.cycle()
    assert rig.nav(0.1).urgent  # the source that drives
    dock = SourceCommand(1, 0, 0.1, 0.0).encode()
    assert rig.c.on_source("dock", dock, rig.now).urgent  # outranks it
    rig.cycle()
    assert not rig.nav(0.1).urgent  # below the one that drives


# -- operators among themselves (DESIGN 14 [[operator]]) --------------------------------------


def test_a_supervisor_takes_control_at_once_and_equal_ones_keep_first_come():
    rig = Rig(operators=(("sup", 100), ("carol", 0)))
    rig.op(op="alice")
    assert rig.cycle().telemetry.operator == "alice"
    equal = rig.op(op="carol")
    assert not equal.accepted and rig.c.operator == "alice"
    verdict = rig.op(op="sup", x=1.0)
    assert verdict.took_control and verdict.took_from == "alice"
    t = rig.cycle().telemetry
    assert (t.operator, t.state, t.reason) == ("sup", "HOLD", "waiting for a centred stick")
    assert not rig.op(op="alice").accepted  # now it watches
    # Without the deadman a supervisor does not take control.
    rig2 = Rig(operators=(("sup", 100),))
    rig2.op(op="alice")
    assert not rig2.op(op="sup", deadman=False).accepted and rig2.c.operator == "alice"


# -- without [[source]] tables ------------------------------------------------------------------


def test_without_sources_nothing_new_is_sent():
    cfg = ControllerConfig(PipelineConfig(PROFILE))
    c = RobotController(cfg, T0)
    c.on_scan(scan_at(), T0)
    out = c.step(T0 + 50 * MS)
    raw = msgpack.unpackb(out.telemetry.encode())
    assert not {"source", "lock", "source_age_ms"} & set(raw)
    assert not {"source", "lock"} & set(msgpack.unpackb(c.state_message(T0).encode()))
    assert c.verdict is None
    assert not c.on_source("nav", SourceCommand(1, 0, 0.1, 0).encode(), T0).accepted
    assert decode_telemetry(out.telemetry.encode()).source is None


def test_a_sources_own_loop_delay_reaches_a_delay_aware_filter():
    """cbf's margin grows with the loop delay (DESIGN 13): a source's own tau goes to it, as
    the operator's does (unstamped: command_timeout; stamped: its commands' ages). Driving at
    v_max, a wall appears 0.4 m ahead: at tau 0.25 s cbf lets the robot go on this cycle, at
    0.7 s it brakes (the governor caps neither: its limit is above v_max at both)."""
    from egc_robot.pipeline import filter_velocity

    wall = wall_ahead(0.4)
    pipeline = PipelineConfig(PROFILE, filter="cbf")

    def at_the_wall(age_ms: float | None) -> float:
        rig = Rig()
        rig.c = RobotController(ControllerConfig(pipeline, sources=MuxConfig((NAV, TELEOP))), T0)
        for _ in range(20):
            stamp = 0 if age_ms is None else rig.now - int(age_ms * MS)
            rig.nav(V_MAX, stamp_ns=stamp)
            out = rig.cycle()
        assert out.base.linear_mps == pytest.approx(V_MAX)
        rig.scan = wall
        stamp = 0 if age_ms is None else rig.now - int(age_ms * MS)
        rig.nav(V_MAX, stamp_ns=stamp)
        out = rig.cycle()
        assert (out.telemetry.filter, out.telemetry.source) == ("cbf", "nav")
        return out.base.linear_mps

    def expected(tau_s: float) -> float:
        return filter_velocity(
            pipeline, V_MAX, 0.0, "shared", wall.obstacles(), (V_MAX, 0.0), 0.05,
            filter_name="cbf", loop_delay_s=tau_s,
        ).v_cmd_mps  # fmt: skip

    assert expected(0.25) > expected(0.7) + 0.01  # the scene makes tau matter
    assert at_the_wall(None) == pytest.approx(expected(0.25))  # unknown age: command_timeout
    assert at_the_wall(700.0) == pytest.approx(expected(0.7))
