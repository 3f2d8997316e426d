"""Predictive display (DESIGN 9): open-loop replay of the sent commands from the newest pose."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest
from egc_common.kinematics import integrate_arc
from egc_common.messages import Telemetry
from egc_common.profiles import JACKAL, PIONEER3DX
from egc_operator.prediction import (
    MAX_HORIZON_S,
    CommandHistory,
    SentCommand,
    command_velocity,
    predict,
    predict_from_telemetry,
    uplink_estimate_ms,
)

MS = 1_000_000
T0 = 50_000 * MS  # the telemetry's stamp (robot clock)
P = PIONEER3DX
V, W = P.v_max_mps, P.w_max_radps


def stream(x: float, y: float, start_ns: int, end_ns: int, **kw: object) -> list[SentCommand]:
    """Commands at 50 Hz from start to end (inclusive), all the same stick."""
    return [
        SentCommand(s, x, y, **kw)  # type: ignore[arg-type]
        for s in range(start_ns, end_ns + 1, 20 * MS)
    ]


def run(commands: list[SentCommand], **kw: object):  # type: ignore[no-untyped-def]
    args: dict[str, object] = {
        "pose": (1.0, 2.0, 0.0),
        "stamp_ns": T0,
        "state": "DRIVING",
        "velocity": (V, 0.0),
        "reference": (V, 0.0),
        "commands": commands,
        "now_ns": T0 + 300 * MS,
        "uplink_ns": 200 * MS,
        "profile": P,
    }
    args.update(kw)
    return predict(**args)  # type: ignore[arg-type]


def test_straight_line_at_full_stick_covers_v_max_times_view_age_plus_uplink() -> None:
    pred = run(stream(1.0, 0.0, T0 - 400 * MS, T0 + 300 * MS))
    assert pred.end_ns == T0 + 500 * MS
    assert pred.pose == pytest.approx((1.0 + V * 0.5, 2.0, 0.0), abs=1e-9)
    assert pred.path[0] == (1.0, 2.0, 0.0) and pred.path[-1] == pred.pose
    assert all(b[0] > a[0] for a, b in zip(pred.path, pred.path[1:], strict=False))
    assert not pred.stopping and not pred.clamped
    assert pred.velocity == pytest.approx((V, 0.0))


def test_arc_is_integrated_exactly() -> None:
    start = (0.0, 0.0, 0.3)
    pred = run(
        stream(1.0, 1.0, T0 - 400 * MS, T0 + 300 * MS),
        pose=start,
        velocity=(V, W),
        reference=(V, W),
    )
    assert pred.pose == pytest.approx(integrate_arc(start, V, W, 0.5), abs=1e-9)
    # every point of the path lies on the circle of radius V / W around the same centre
    r = V / W
    cx, cy = -r * math.sin(0.3), r * math.cos(0.3)
    for x, y, _ in pred.path:
        assert math.hypot(x - cx, y - cy) == pytest.approx(r, abs=1e-9)


def test_commands_take_effect_after_the_uplink_and_ramp_at_the_profiles_limits() -> None:
    """The robot drove straight; the operator turned full left 100 ms after the stamp."""
    commands = stream(1.0, 0.0, T0 - 400 * MS, T0 + 80 * MS)
    commands += stream(1.0, 1.0, T0 + 100 * MS, T0 + 300 * MS)
    pred = run(commands)
    # the turn reaches the robot at T0 + 300 ms; w ramps at 1.5 rad/s^2 for 0.2 s = 0.3 rad/s
    assert pred.velocity == pytest.approx((V, 0.3), abs=1e-9)
    straight = [p for p in pred.path if p[2] == 0.0]
    assert straight[-1][0] == pytest.approx(1.0 + V * 0.3, abs=1e-9)
    assert pred.pose[1] > 2.0 and 0.0 < pred.pose[2] < W * 0.2


@pytest.mark.parametrize("state", ["HOLD", "ESTOP", "IDLE"])
def test_a_robot_that_is_not_driving_is_predicted_to_stop(state: str) -> None:
    pred = run(stream(1.0, 0.5, T0 - 400 * MS, T0 + 300 * MS), state=state, velocity=(V, 0.0))
    braking = V * V / (2 * P.decel_max_mps2)  # 1.96 cm
    assert pred.stopping
    assert pred.velocity == (0.0, 0.0)
    assert pred.pose[0] - 1.0 == pytest.approx(braking, abs=V * 0.02)  # within one step
    assert pred.pose[1] == 2.0 and pred.pose[2] == 0.0  # the stick's turn is ignored


def test_deadman_release_stops_until_a_centred_command_and_estop_for_good() -> None:
    released = stream(1.0, 0.0, T0 - 400 * MS, T0 - 100 * MS)
    released += stream(1.0, 0.0, T0 - 80 * MS, T0 + 300 * MS, deadman=False)
    assert run(released).stopping and run(released).velocity == (0.0, 0.0)
    recentred = released[:16] + stream(0.0, 0.0, T0 - 80 * MS, T0 - 60 * MS)
    recentred += stream(1.0, 0.0, T0 - 40 * MS, T0 + 300 * MS)
    assert not run(recentred).stopping and run(recentred).velocity[0] == pytest.approx(V)
    estop = stream(1.0, 0.0, T0 - 400 * MS, T0 - 100 * MS)
    estop += stream(0.0, 0.0, T0 - 80 * MS, T0 - 60 * MS, estop=True)
    estop += stream(1.0, 0.0, T0 - 40 * MS, T0 + 300 * MS)
    assert run(estop).stopping and run(estop).velocity == (0.0, 0.0)


def test_latency_cap_scales_the_command_as_a_whole() -> None:
    assert command_velocity(SentCommand(0, 1.0, 1.0), P, 0.07) == pytest.approx((0.07, 0.25))
    assert command_velocity(SentCommand(0, -1.0, 0.0), P, 0.07) == pytest.approx((-0.07, 0.0))
    assert command_velocity(SentCommand(0, 0.5, 0.2), P, 1.0) == pytest.approx((0.07, 0.1))
    pred = run(stream(1.0, 0.0, T0 - 400 * MS, T0 + 300 * MS), v_lim=0.07, velocity=(0.07, 0.0))
    assert pred.pose[0] == pytest.approx(1.0 + 0.07 * 0.5, abs=1e-9)


def test_turn_cap_scales_the_command_as_the_robot_does() -> None:
    # The robot's governor caps the turn rate too (w_lim_latency): the ghost follows it.
    assert command_velocity(SentCommand(0, 1.0, 1.0), P, 1.0, 0.1) == pytest.approx((0.028, 0.1))
    assert command_velocity(SentCommand(0, 0.0, -1.0), P, 0.07, 0.1) == pytest.approx((0.0, -0.1))
    assert command_velocity(SentCommand(0, 1.0, 0.2), P, 0.07, 0.5) == pytest.approx((0.07, 0.05))
    spin = stream(0.0, 1.0, T0 - 400 * MS, T0 + 300 * MS)
    free = run(spin, velocity=(0.0, 0.1))
    capped = run(spin, velocity=(0.0, 0.1), w_lim=0.1)
    assert capped.pose[2] == pytest.approx(0.1 * 0.5, abs=1e-9)
    assert free.pose[2] > 2 * capped.pose[2]


def test_empty_history_keeps_the_reference_the_telemetry_reports() -> None:
    pred = run([], velocity=(0.0, 0.0), reference=(V, 0.0))
    assert pred.velocity == pytest.approx((V, 0.0))  # reached after 0.47 s at 0.3 m/s^2
    assert 1.0 < pred.pose[0] < 1.0 + V * 0.5
    still = run([], velocity=(0.0, 0.0), reference=(0.0, 0.0))
    assert still.pose == (1.0, 2.0, 0.0) and still.path[-1] == still.pose


def test_nothing_to_predict_when_the_telemetry_is_newer_than_now_plus_uplink() -> None:
    pred = run([], now_ns=T0 - 500 * MS)
    assert pred.path == ((1.0, 2.0, 0.0),) and pred.end_ns == T0


def test_very_old_telemetry_is_clamped_to_the_maximum_horizon() -> None:
    pred = run([], now_ns=T0 + 60_000 * MS)
    assert pred.clamped and pred.end_ns - T0 == MAX_HORIZON_S * 1e9
    assert len(pred.path) == round(MAX_HORIZON_S / 0.02) + 1


def test_uplink_estimate_prefers_the_robots_median_command_age() -> None:
    assert uplink_estimate_ms(210.0, 600.0) == 210.0
    assert uplink_estimate_ms(None, 600.0) == 300.0
    assert uplink_estimate_ms(None, None) is None
    assert uplink_estimate_ms(-5.0, None) == 0.0  # clock-sync error can make ages negative


def test_from_telemetry_needs_a_pose_and_a_known_profile() -> None:
    t = Telemetry(
        seq=1,
        stamp_ns=T0,
        state="DRIVING",
        mode="shared",
        v_ref=2.0,
        w_ref=0.0,
        v_cmd=2.0,
        w_cmd=0.0,
        w_si=1.0,
        pose=(0.0, 0.0, 0.0),
        profile="jackal",
    )
    commands = stream(1.0, 0.0, T0 - 400 * MS, T0 + 300 * MS)
    pred = predict_from_telemetry(t, commands, T0 + 300 * MS, rtt_ms=400.0)
    assert pred is not None and pred.uplink_ns == 200 * MS
    assert pred.pose[0] == pytest.approx(JACKAL.v_max_mps * 0.5)
    capped = replace(t, cmd_age_p50_ms=100.0, v_lim_latency=1.0, v_cmd=1.0)
    pred = predict_from_telemetry(capped, commands, T0 + 300 * MS, rtt_ms=400.0)
    assert pred is not None and pred.pose[0] == pytest.approx(0.4)
    assert predict_from_telemetry(replace(t, pose=None), commands, T0, None) is None
    assert predict_from_telemetry(replace(t, profile="nope"), commands, T0, None) is None
    assert predict_from_telemetry(replace(t, profile=""), commands, T0, None) is None


def test_history_is_bounded_by_age_and_length_and_restarts_on_a_clock_jump() -> None:
    history = CommandHistory(max_age_ns=1000 * MS, max_len=100)
    for c in stream(0.5, 0.0, 0, 3000 * MS):
        history.add(c)
    assert len(history) == 51  # 1 s at 50 Hz, both ends included
    since = history.since(2500 * MS - 10 * MS)
    assert since[0].stamp_ns == 2480 * MS and since[-1].stamp_ns == 3000 * MS
    assert history.since(5000 * MS) == (history.newest,)
    small = CommandHistory(max_len=10)
    for c in stream(0.5, 0.0, 0, 1000 * MS):
        small.add(c)
    assert len(small) == 10
    small.add(SentCommand(5 * MS, 0.0, 0.0))  # the robot's clock went back: a new boot
    assert len(small) == 1
    assert CommandHistory().since(0) == () and CommandHistory().newest is None
    with pytest.raises(ValueError):
        CommandHistory(max_age_ns=0)
