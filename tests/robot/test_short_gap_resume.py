"""Short-gap resume (DESIGN 8, issue 12): every path into and out of a HOLD from the link.

State machine level first (pure transitions), then the controller with a simulated clock.
"""

from __future__ import annotations

import dataclasses

import pytest
from egc_robot.state_machine import (
    COMMAND_TIMEOUT,
    RESUMED,
    STALE_COMMANDS,
    Inputs,
    State,
    Transition,
    next_state,
)

from tests.robot.test_controller import PROFILE, driving_rig

GOOD = Inputs(
    operator_present=True,
    command_fresh=True,
    deadman=True,
    centred=False,  # the operator keeps the stick forward through the gap
    scan_fresh=True,
    estop=False,
    reset=False,
    base_stopped=False,
    same_control=False,  # never DRIVING on the previous cycle while in HOLD
    session_kept=True,
    resume_allowed=True,
)
DRIVING = Transition(State.DRIVING, "fresh centred command")


def with_(**changes: object) -> Inputs:
    return dataclasses.replace(GOOD, **changes)  # type: ignore[arg-type]


@pytest.mark.parametrize("reason", [COMMAND_TIMEOUT, STALE_COMMANDS])
def test_link_hold_from_driving_is_resumable(reason):
    t = next_state(DRIVING, with_(command_fresh=False, stale_reason=reason))
    assert t == Transition(State.HOLD, reason, resumable=True)


def test_link_hold_resumes_without_centring_when_allowed():
    hold = Transition(State.HOLD, COMMAND_TIMEOUT, resumable=True)
    assert next_state(hold, GOOD) == Transition(State.DRIVING, RESUMED)


def test_link_hold_stays_resumable_while_the_reason_switches_between_link_reasons():
    hold = Transition(State.HOLD, COMMAND_TIMEOUT, resumable=True)
    t = next_state(hold, with_(command_fresh=False, stale_reason=STALE_COMMANDS))
    assert t == Transition(State.HOLD, STALE_COMMANDS, resumable=True)


def test_window_closed_needs_a_centred_stick():
    hold = Transition(State.HOLD, COMMAND_TIMEOUT, resumable=True)
    t = next_state(hold, with_(resume_allowed=False))
    assert t == Transition(State.HOLD, "waiting for a centred stick")
    assert next_state(t, with_(resume_allowed=False, centred=True)).state is State.DRIVING


@pytest.mark.parametrize(
    ("change", "reason"),
    [
        ({"deadman": False}, "deadman released"),
        ({"scan_fresh": False}, "sensor stale"),
        ({"operator_present": False, "no_operator_reason": "operator a lost"}, "operator a lost"),
    ],
)
def test_any_other_reason_on_the_way_makes_the_hold_non_resumable(change, reason):
    hold = Transition(State.HOLD, COMMAND_TIMEOUT, resumable=True)
    t = next_state(hold, with_(**change))
    assert t.state is State.HOLD and t.reason == reason and not t.resumable
    # ... for good: a fresh deflected command later does not resume.
    assert next_state(t, GOOD) == Transition(State.HOLD, "waiting for a centred stick")


def test_estop_during_a_link_hold_is_not_resumable():
    hold = Transition(State.HOLD, COMMAND_TIMEOUT, resumable=True)
    t = next_state(hold, with_(estop=True))
    assert t.state is State.ESTOP and not t.resumable


def test_hold_waiting_for_centre_does_not_become_resumable_through_a_timeout():
    waiting = Transition(State.HOLD, "waiting for a centred stick")
    t = next_state(waiting, with_(command_fresh=False))
    assert t == Transition(State.HOLD, COMMAND_TIMEOUT)
    assert next_state(t, GOOD).reason == "waiting for a centred stick"


def test_link_hold_without_session_kept_is_not_resumable():
    t = next_state(DRIVING, with_(command_fresh=False, session_kept=False))
    assert t == Transition(State.HOLD, COMMAND_TIMEOUT)


# -- the controller, simulated clock -------------------------------------------------------------


def gap(rig, ms: float) -> None:
    """No command for ``ms``, cycles at 20 ms."""
    for _ in range(int(ms // 20)):
        rig.cycle()


def test_controller_short_gap_resumes_with_the_stick_forward_and_ramps():
    rig = driving_rig()
    gap(rig, 1000)
    assert rig.c.state is State.HOLD and rig.c.reason == COMMAND_TIMEOUT
    out = None
    for _ in range(3):
        rig.send(x=1.0)
        out = rig.cycle()
    assert out.telemetry.state == "DRIVING" and out.telemetry.reason == RESUMED
    # The base ramps up at the acceleration limit from standstill, not a jump to v_max.
    assert 0 < out.base.linear_mps <= 3 * 0.02 * PROFILE.accel_max_mps2 + 1e-9


def test_controller_gap_longer_than_the_resume_window_needs_centring():
    rig = driving_rig()
    gap(rig, 2100)  # > resume_window 2 s (and release_timeout: control is released too)
    rig.send(x=1.0)
    out = rig.cycle()
    assert out.telemetry.state == "HOLD" and rig.c.reason == "waiting for a centred stick"


def test_controller_resume_window_is_configurable():
    rig = driving_rig(resume_window_s=0.5)
    gap(rig, 700)
    rig.send(x=1.0)
    assert rig.cycle().telemetry.state == "HOLD"
    assert rig.c.reason == "waiting for a centred stick"


def test_controller_deadman_released_during_the_gap_needs_centring():
    rig = driving_rig()
    gap(rig, 400)
    rig.send(x=1.0, deadman=False)
    rig.cycle()
    rig.send(x=1.0)
    assert rig.cycle().telemetry.state == "HOLD"
    assert rig.c.reason == "waiting for a centred stick"


def test_controller_operator_lost_during_the_gap_needs_centring():
    rig = driving_rig()
    gap(rig, 400)
    rig.c.on_operator_alive("alice", False)
    rig.cycle()
    rig.c.on_operator_alive("alice", True)
    rig.send(x=1.0, seq=1)
    assert rig.cycle().telemetry.state == "HOLD"
    assert rig.c.reason == "waiting for a centred stick"


def test_controller_stale_commands_hold_then_resume_when_fresh_again():
    rig = driving_rig()  # shared mode: max age 1 s
    for _ in range(20):
        rig.send(x=1.0, delay_ms=1200)  # arriving, but too old
        out = rig.cycle()
    assert out.telemetry.state == "HOLD"
    assert rig.c.counters.rejected["stale"] == 20
    rig.send(x=1.0, delay_ms=200)
    assert rig.cycle().telemetry.state == "DRIVING"


def test_controller_link_aware_off_never_resumes():
    rig = driving_rig(link_aware=False)
    gap(rig, 400)
    rig.send(x=1.0)
    assert rig.cycle().telemetry.state == "HOLD"


def test_controller_delay_alone_does_not_trip_the_watchdog_in_shared_mode():
    rig = driving_rig()
    for _ in range(100):  # 2 s of commands 700 ms old, one every 20 ms
        rig.send(x=1.0, delay_ms=700)
        out = rig.cycle()
        assert out.telemetry.state == "DRIVING"
    assert rig.c.counters.rejected_total == 0


def test_watchdog_time_is_unchanged_by_link_aware_driving():
    rig = driving_rig()  # its last command arrived 20 ms before the last cycle
    rig.cycle(dt_ms=220)  # 240 ms without a command
    assert rig.c.state is State.DRIVING
    rig.cycle(dt_ms=20)  # 260 ms > command_timeout 250 ms
    assert rig.c.state is State.HOLD and rig.c.reason == COMMAND_TIMEOUT
