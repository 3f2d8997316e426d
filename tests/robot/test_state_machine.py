"""DESIGN 8 state machine: every transition rule, and the no-jump resume rule."""

from __future__ import annotations

import dataclasses

import pytest
from egc_robot.state_machine import Inputs, State, Transition, hold_reason, next_state

GOOD = Inputs(
    operator_present=True,
    command_fresh=True,
    deadman=True,
    centred=True,
    scan_fresh=True,
    estop=False,
    reset=False,
    base_stopped=True,
)


def at(state: State, reason: str = "x") -> Transition:
    return Transition(state, reason)


def with_(**changes: object) -> Inputs:
    return dataclasses.replace(GOOD, **changes)  # type: ignore[arg-type]


def test_idle_to_driving_on_fresh_centred_deadman_command():
    assert next_state(at(State.IDLE), GOOD).state is State.DRIVING


@pytest.mark.parametrize("start", [State.IDLE, State.HOLD])
def test_no_jump_deflected_stick_does_not_start_driving(start):
    t = next_state(at(start), with_(centred=False))
    assert t == Transition(State.HOLD, "waiting for a centred stick")


def test_driving_keeps_driving_with_deflected_stick():
    current = at(State.DRIVING, "fresh centred command")
    assert next_state(current, with_(centred=False)) is current


@pytest.mark.parametrize(
    ("change", "reason"),
    [
        ({"command_fresh": False}, "command timeout"),
        ({"deadman": False}, "deadman released"),
        ({"scan_fresh": False}, "sensor stale"),
    ],
)
def test_driving_to_hold(change, reason):
    assert next_state(at(State.DRIVING), with_(**change)) == Transition(State.HOLD, reason)


def test_operator_lost_holds_until_stopped_then_idles():
    lost = with_(operator_present=False, base_stopped=False, no_operator_reason="op lost")
    t = next_state(at(State.DRIVING), lost)
    assert t == Transition(State.HOLD, "op lost")
    assert next_state(t, dataclasses.replace(lost, base_stopped=True)).state is State.IDLE


@pytest.mark.parametrize("start", list(State))
def test_estop_from_every_state(start):
    assert next_state(at(start), with_(estop=True)).state is State.ESTOP


def test_estop_is_latched_without_reset():
    t = at(State.ESTOP, "estop")
    assert next_state(t, GOOD) is t


@pytest.mark.parametrize(
    "missing",
    [
        {"deadman": False},
        {"centred": False},
        {"command_fresh": False},
        {"operator_present": False},
        {"estop": True},
    ],
)
def test_estop_reset_needs_every_condition(missing):
    t = next_state(at(State.ESTOP, "estop"), with_(reset=True, **missing))
    assert t.state is State.ESTOP


def test_estop_reset_goes_to_hold_then_drives_on_the_next_good_cycle():
    t = next_state(at(State.ESTOP, "estop"), with_(reset=True))
    assert t == Transition(State.HOLD, "estop reset")
    assert next_state(t, GOOD).state is State.DRIVING


def test_hold_reason_order():
    assert hold_reason(GOOD) is None
    everything_wrong = with_(operator_present=False, command_fresh=False, deadman=False)
    assert hold_reason(everything_wrong) == "no operator"
    assert hold_reason(with_(command_fresh=False, deadman=False)) == "command timeout"


def test_unchanged_transition_is_the_same_object():
    t = Transition(State.HOLD, "deadman released")
    assert next_state(t, with_(deadman=False)) is t


def test_driving_is_not_inherited_when_control_changed_hands():
    t = next_state(at(State.DRIVING), with_(centred=False, same_control=False))
    assert t == Transition(State.HOLD, "waiting for a centred stick")


# -- command sources (DESIGN 14) ----------------------------------------------------------------


@pytest.mark.parametrize("start", [State.IDLE, State.HOLD])
def test_a_source_other_than_the_operator_drives_at_once_without_a_stick(start):
    t = next_state(at(start), with_(source="nav", same_control=False))
    assert t == Transition(State.DRIVING, "source nav")


def test_a_switch_of_source_is_a_new_driving_episode():
    current = at(State.DRIVING, "source nav")
    assert next_state(current, with_(source="nav")) is current
    assert next_state(current, with_(same_control=False)).reason == "fresh centred command"


def test_a_source_still_needs_a_fresh_scan():
    t = next_state(at(State.DRIVING, "source nav"), with_(source="nav", scan_fresh=False))
    assert t == Transition(State.HOLD, "sensor stale")


@pytest.mark.parametrize("start", [State.IDLE, State.DRIVING, State.HOLD])
def test_a_lock_holds_whatever_drove(start):
    t = next_state(at(start), with_(operator_present=False, lock_reason="lock pause: true"))
    assert t == Transition(State.HOLD, "lock pause: true")


def test_an_estop_outranks_a_lock_and_a_lock_does_not_reset_it():
    locked = with_(operator_present=False, lock_reason="lock pause: true")
    assert next_state(at(State.HOLD), dataclasses.replace(locked, estop=True)).state is State.ESTOP
    estop = at(State.ESTOP, "estop")
    assert next_state(estop, dataclasses.replace(locked, reset=True)) is estop
