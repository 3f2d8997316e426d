"""RobotController: acceptance rules, control ownership, watchdogs and outputs (DESIGN 7, 8).

Time is simulated: every call gets an explicit monotonic time, starting an hour in so that
stamps are large like a real monotonic clock.
"""

from __future__ import annotations

import math

import msgpack
import numpy as np
import pytest
from egc_common.messages import TELEMETRY_PINNED_KEYS, decode_telemetry
from egc_common.profiles import get_profile
from egc_common.scan import Scan
from egc_robot.controller import ControllerConfig, RobotController
from egc_robot.pipeline import PipelineConfig
from egc_robot.state_machine import State

MS = 1_000_000
T0 = 3600 * 1000 * MS
PROFILE = get_profile("pioneer3dx")


def raw(seq: int, stamp_ns: int, x: float = 0.0, y: float = 0.0, **kw: object) -> bytes:
    msg = {"v": 1, "seq": seq, "stamp_ns": stamp_ns, "x": x, "y": y, "mode": "shared"}
    msg |= {"deadman": True, "estop": False, "reset": False, "op": "alice"}
    msg |= kw
    return msgpack.packb(msg)


def open_scan(n: int = 360, r: float = 5.0) -> Scan:
    return Scan.uniform(np.full(n, r), -math.pi, 2 * math.pi / n, 0.05, 10.0)


class Rig:
    """A controller plus a simulated clock and an operator that stamps correctly."""

    def __init__(self, **config: object) -> None:
        cfg = ControllerConfig(PipelineConfig(PROFILE), **config)  # type: ignore[arg-type]
        self.now = T0
        self.c = RobotController(cfg, self.now)
        self.seq = 0

    def send(self, x: float = 0.0, y: float = 0.0, delay_ms: float = 1.0, **kw: object):
        self.seq += 1
        kw.setdefault("seq", self.seq)
        payload = raw(stamp_ns=self.now - int(delay_ms * MS), x=x, y=y, **kw)
        return self.c.on_command(payload, self.now)

    def cycle(self, dt_ms: float = 20.0, scan: bool = True):
        self.now += int(dt_ms * MS)
        if scan:
            self.c.on_scan(open_scan(), self.now)
        return self.c.step(self.now)

    def drive(self, x: float, cycles: int = 5):
        out = None
        for _ in range(cycles):
            self.send(x=x)
            out = self.cycle()
        return out


def driving_rig(**config: object) -> Rig:
    rig = Rig(**config)
    rig.send()
    assert rig.cycle().telemetry.state == "DRIVING"
    rig.drive(1.0, cycles=30)
    return rig


def test_centred_deadman_command_drives_and_telemetry_has_pinned_keys():
    rig = driving_rig()
    out = rig.drive(1.0)
    assert out.base.linear_mps == pytest.approx(PROFILE.v_max_mps)
    t = out.telemetry
    assert (t.state, t.mode, t.operator) == ("DRIVING", "shared", "alice")
    assert t.v_ref == pytest.approx(PROFILE.v_max_mps)
    assert t.w_si == 1.0
    decoded = msgpack.unpackb(t.encode())
    for key in TELEMETRY_PINNED_KEYS:
        assert key in decoded
    assert not isinstance(decode_telemetry(t.encode()), Exception)


def test_deflected_first_command_does_not_drive():
    rig = Rig()
    rig.send(x=1.0)
    out = rig.cycle()
    assert out.telemetry.state == "HOLD"
    assert out.base.linear_mps == 0.0
    assert rig.c.reason == "waiting for a centred stick"


@pytest.mark.parametrize(
    ("mode", "delay_ms", "link_aware", "accepted"),
    [
        # DESIGN 8: max_command_age is 300 ms in direct mode, 1.0 s in a filtered mode.
        ("direct", 290, True, True),
        ("direct", 310, True, False),
        ("direct", -310, True, False),
        ("shared", 310, True, True),
        ("shared", 990, True, True),
        ("shared", 1010, True, False),
        ("shared", -1010, True, False),
        # Link-aware driving off: one age for both modes, as before.
        ("shared", 310, False, False),
    ],
)
def test_age_rule_by_mode(mode, delay_ms, link_aware, accepted):
    rig = Rig(link_aware=link_aware)
    verdict = rig.send(delay_ms=delay_ms, mode=mode)
    assert verdict.accepted is accepted
    if not accepted:
        assert verdict.rejection.reason.value == "stale"
        assert rig.c.counters.rejected["stale"] == 1


def test_shared_mode_with_no_filter_uses_the_direct_age():
    cfg = ControllerConfig(PipelineConfig(PROFILE, filter="none"))
    c = RobotController(cfg, T0)
    assert not c.on_command(raw(1, T0 - 400 * MS), T0).accepted


def test_unsynchronised_stamp_is_accepted_unless_sync_required():
    assert Rig().c.on_command(raw(1, 0), T0).accepted
    strict = Rig(require_clock_sync=True)
    assert strict.c.on_command(raw(1, 0), T0).rejection.reason.value == "stale"


def test_duplicate_and_out_of_order_seq():
    rig = Rig()
    assert rig.send(seq=10).accepted
    assert rig.send(seq=10).rejection.reason.value == "duplicate_seq"
    assert rig.send(seq=9).rejection.reason.value == "out_of_order"
    assert rig.send(seq=11).accepted
    assert rig.c.counters.rejected_total == 2


def test_restarted_operator_after_release_timeout_starts_a_new_seq_session():
    rig = Rig()
    assert rig.send(seq=500).accepted
    rig.now += 2100 * MS
    assert rig.send(seq=1).accepted


@pytest.mark.parametrize(
    "payload",
    [
        b"\xc1garbage",
        msgpack.packb([1, 2, 3]),
        raw(1, T0, x=float("nan")),
        raw(1, T0, x="fast"),
        raw(1, T0, x=2.0),
        raw(1, T0, op="x" * 1000),
        b"\x00" * 100_000,
    ],
)
def test_malformed_payloads_are_counted_and_change_nothing(payload):
    rig = driving_rig()
    before = rig.c.counters.accepted
    verdict = rig.c.on_command(payload, rig.now)
    assert not verdict.accepted
    assert rig.c.counters.rejected_total == 1
    assert rig.c.counters.accepted == before
    assert rig.cycle().telemetry.state == "DRIVING"


def test_second_operator_is_not_in_control():
    rig = driving_rig()
    verdict = rig.send(x=-1.0, op="mallory", seq=1)
    assert verdict.rejection.reason.value == "not_in_control"
    out = rig.cycle()
    assert out.base.linear_mps > 0
    assert out.telemetry.operator == "alice"


def test_control_needs_the_deadman():
    rig = Rig()
    assert rig.send(deadman=False).rejection.reason.value == "not_in_control"
    assert rig.c.operator is None
    assert rig.send().took_control


def test_watchdog_holds_and_decelerates_at_the_profile_limit():
    rig = driving_rig()
    v = rig.cycle(dt_ms=0).base.linear_mps
    out = rig.cycle(dt_ms=260)  # no command for 260 ms > command_timeout
    assert out.telemetry.state == "HOLD" and rig.c.reason == "command timeout"
    assert out.telemetry.limiter == "watchdog"
    assert out.base.linear_mps == pytest.approx(max(0.0, v - PROFILE.decel_max_mps2 * 0.26))
    for _ in range(20):
        out = rig.cycle()
    assert out.base.linear_mps == 0.0


def test_without_the_hold_ramp_a_hold_is_a_zero_command_at_once():
    # DESIGN 11: on a ROS 2 base the robot sends a zero twist in HOLD (the base brakes itself).
    rig = driving_rig(hold_ramp=False)
    assert rig.cycle(dt_ms=0).base.linear_mps > 0.1
    out = rig.cycle(dt_ms=260)
    assert out.telemetry.state == "HOLD" and out.telemetry.limiter == "watchdog"
    assert (out.base.linear_mps, out.base.angular_radps) == (0.0, 0.0)
    rig.send(x=1.0)  # back within the resume window: it ramps up from zero, not from before
    out = rig.cycle()
    assert out.telemetry.state == "DRIVING"
    assert 0 < out.base.linear_mps <= PROFILE.accel_max_mps2 * 0.02 + 1e-9


def test_resume_after_hold_needs_a_centred_stick_without_link_aware_driving():
    rig = driving_rig(link_aware=False)
    rig.cycle(dt_ms=300)
    rig.send(x=1.0)
    assert rig.cycle().telemetry.state == "HOLD"
    rig.send(x=0.0)
    assert rig.cycle().telemetry.state == "DRIVING"


def test_deadman_release_holds():
    rig = driving_rig()
    rig.send(x=1.0, deadman=False)
    assert rig.cycle().telemetry.state == "HOLD"
    assert rig.c.reason == "deadman released"


def test_sensor_stale_holds():
    rig = driving_rig()
    rig.send(x=1.0)
    rig.cycle(dt_ms=250, scan=False)
    assert rig.c.state is State.HOLD and rig.c.reason == "sensor stale"
    assert rig.c.scan_age_ms(rig.now) == 250.0  # the robot's log says how stale


def test_the_scan_age_is_none_before_the_first_scan():
    rig = Rig()
    assert rig.c.scan_age_ms(rig.now) is None
    rig.c.on_scan(open_scan(), rig.now)
    assert rig.c.scan_age_ms(rig.now + 30 * MS) == 30.0


def test_operator_liveliness_lost_holds_at_once_and_releases_control():
    rig = driving_rig()
    rig.c.on_operator_alive("alice", True)
    rig.c.on_operator_alive("alice", False)
    out = rig.cycle()
    assert out.telemetry.state == "HOLD" and out.telemetry.operator is None
    assert "alice lost" in rig.c.reason
    assert rig.send(op="bob", seq=1).took_control


def test_a_departed_operator_cannot_take_control_again_until_its_token_is_back():
    """Outside check: an operator ended with its stick forward; a command of it still in
    flight after its token went away gave it control again (then HOLD, then IDLE 2 s later)."""
    rig = driving_rig()
    rig.c.on_operator_alive("alice", True)
    rig.c.on_operator_alive("alice", False)
    rig.cycle()
    late = rig.send(x=1.0, seq=999)
    assert not late.accepted and not late.took_control
    assert "liveliness token is gone" in late.rejection.detail
    assert rig.cycle().telemetry.operator is None
    rig.c.on_operator_alive("alice", True)  # the same operator back (restarted or reconnected)
    assert rig.send(seq=1).took_control
    rig.c.on_operator_alive("bob", False)  # a watcher that leaves does not disturb control
    assert rig.send(seq=2).accepted


@pytest.mark.parametrize(
    "mode, ahead_ms", [("shared", 500.0), ("shared", 600.0), ("direct", 280.0)]
)
def test_commands_stamped_ahead_of_the_robot_clock_leave_the_governor_working(mode, ahead_ms):
    """Outside check: stamps up to max_command_age ahead are accepted; their negative ages
    made tau negative and every cycle raised in the latency governor (telemetry went silent)."""
    rig = driving_rig()
    for _ in range(100):  # 2 s: the link window holds only these
        rig.send(x=1.0, delay_ms=-ahead_ms, mode=mode, view_age_ms=0)
        out = rig.cycle()
    assert out.telemetry.state == "DRIVING" and out.base.linear_mps > 0.0
    assert out.telemetry.loop_delay_ms >= 250.0  # the reaction time at least


def test_a_failed_cycle_makes_the_next_one_ramp_up_from_standstill():
    rig = driving_rig()
    rig.drive(1.0, cycles=40)
    fast = rig.cycle().base.linear_mps
    rig.c.on_base_stopped()  # the node sent zero after a failed cycle
    rig.send(x=1.0)
    after = rig.cycle().base.linear_mps
    assert 0.0 < after < fast


def test_silent_operator_loses_control_and_robot_goes_idle():
    rig = driving_rig()
    for _ in range(110):  # 2.2 s > release_timeout
        out = rig.cycle()
    assert out.telemetry.state == "IDLE" and out.base.linear_mps == 0.0


def test_estop_from_anyone_latches_and_reset_needs_centred_deadman():
    rig = driving_rig()
    verdict = rig.send(op="watcher", seq=1, estop=True, deadman=False)
    assert not verdict.accepted  # not in control, but the e-stop is honoured
    out = rig.cycle()
    assert out.telemetry.state == "ESTOP" and out.base.linear_mps == 0.0
    rig.drive(1.0, cycles=3)
    assert rig.c.state is State.ESTOP
    rig.send(x=1.0, reset=True)
    assert rig.cycle().telemetry.state == "ESTOP"
    rig.send(reset=True)
    assert rig.cycle().telemetry.state == "HOLD"
    rig.send()
    assert rig.cycle().telemetry.state == "DRIVING"


def test_state_message_only_on_change():
    rig = Rig()
    rig.send()
    assert rig.cycle().state_changed.state == "DRIVING"
    rig.send()
    assert rig.cycle().state_changed is None


def test_handover_between_two_cycles_does_not_inherit_driving():
    """Found by the integration test: loss and a new operator's deflected command in one batch."""
    rig = driving_rig()
    rig.c.on_operator_alive("alice", True)
    rig.c.on_operator_alive("alice", False)
    assert rig.send(x=-1.0, op="bob", seq=1).took_control
    out = rig.cycle()
    assert out.telemetry.state == "HOLD" and out.telemetry.operator == "bob"
    assert rig.c.reason == "waiting for a centred stick"
    assert out.base.linear_mps >= 0.0


def test_same_operator_lost_and_back_in_one_batch_must_centre_again():
    rig = driving_rig()
    rig.c.on_operator_alive("alice", False)
    rig.c.on_operator_alive("alice", True)
    rig.send(x=1.0)
    assert rig.cycle().telemetry.state == "HOLD"


def test_telemetry_is_the_cycle_snapshot_even_when_built_later():
    rig = driving_rig()
    out = rig.cycle()
    # Later inputs must not leak into the telemetry of a cycle that already ran.
    rig.c.on_scan(Scan.uniform(np.full(10, 0.3), -math.pi, 0.1, 0.05, 10.0), rig.now + MS)
    rig.c.on_command(b"\x00garbage", rig.now + MS)
    rig.c.on_operator_alive("alice", False)
    t = out.telemetry
    assert t.state == "DRIVING" and t.operator == "alice" and t.rejected == 0
    assert t.cycle == out.base.seq and len(t.scan_xy) == 180  # 360 beams, decimation 2
    assert out.telemetry is t  # built once


def test_telemetry_says_which_filter_ran():
    rig = driving_rig()
    assert rig.drive(1.0).telemetry.filter == "egc"
    rig.send(x=1.0, mode="direct")
    assert rig.cycle().telemetry.filter == "none"


def test_a_skipped_telemetry_is_never_built_and_the_facts_match_a_built_one(monkeypatch):
    """The robot sends telemetry at telemetry_hz, not every cycle: a cycle whose telemetry is
    skipped costs no telemetry, cannot be asked for it later (its state is gone) and still
    gives the statistics the values a telemetry would have carried."""
    rig = driving_rig()
    built = []
    build = RobotController._telemetry

    def counted(self, *args):
        built.append(args[0])
        return build(self, *args)

    monkeypatch.setattr(RobotController, "_telemetry", counted)
    skipped = rig.drive(1.0, cycles=1)
    rig.c.skip_telemetry(skipped)
    rig.send(x=0.5, view_age_ms=120)  # an input: would build the last cycle's telemetry
    kept = rig.cycle()
    assert built == []
    with pytest.raises(RuntimeError, match="skipped"):
        skipped.telemetry  # noqa: B018
    t = kept.telemetry
    facts = kept.facts
    assert built == [kept.base.stamp_ns]
    assert (facts.stamp_ns, facts.state, facts.limiter) == (t.stamp_ns, t.state, t.limiter)
    assert facts.loop_delay_ms == t.loop_delay_ms and facts.view_age_ms == t.view_age_ms == 120


def test_an_operator_that_released_the_deadman_then_went_quiet_was_not_lost_while_driving():
    """The robot counts an operator lost while driving (the summary's ``operator_lost``) only
    when the drive was on: DRIVING, or held by the link alone with the deadman still held. A
    script that releases the deadman and closes goes quiet for longer than the command timeout
    on a slow link before its session ends: not lost (the demo at 192 kbit/s counted it)."""
    rig = driving_rig()
    assert rig.c.driving_for_operator
    rig.send(deadman=False)
    rig.cycle()
    assert rig.c.state is State.HOLD and rig.c.reason == "deadman released"
    assert not rig.c.driving_for_operator
    for _ in range(20):  # 400 ms without a command: the command timeout
        rig.cycle()
    assert rig.c.reason == "command timeout" and not rig.c.driving_for_operator

    held = driving_rig()
    for _ in range(20):  # the link went quiet with the deadman held
        held.cycle()
    assert held.c.state is State.HOLD and held.c.reason == "command timeout"
    assert held.c.driving_for_operator
