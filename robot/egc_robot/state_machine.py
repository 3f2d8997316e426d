"""The robot's safety state machine (DESIGN 8), a pure function of the state and one snapshot.

States:

- ``IDLE``: no operator holds control and the base is stopped (the reason says why: none came
  yet, or the last one was lost or fell silent).
- ``DRIVING``: the controlling operator's newest command is fresh, its deadman is held and the
  scan is fresh; the command pipeline drives the base.
- ``HOLD``: stop, decelerating at the profile's limit: the command is stale or missing
  (watchdog), the deadman is released, the operator is gone (liveliness lost or silent; the
  robot holds until the base is stopped, then goes IDLE), or the scan is stale.
- ``ESTOP``: latched by any e-stop request; the base is sent zero at once. It is left (to
  HOLD) only when the controlling operator sends a fresh ``reset`` with the deadman held, the
  stick centred and the e-stop released.

Resuming: from IDLE or HOLD the robot enters DRIVING only on a fresh, deadman-held command with
the stick **centred**, so an operator who returns (after a crash, a hang, a long gap or an
e-stop) with the stick deflected cannot make the robot jump. The same holds when control changes
hands between two cycles (``same_control`` false): DRIVING is never inherited by the next
operator.

The one exception is **short-gap resume** (DESIGN 8, link-aware driving): a HOLD entered from
DRIVING because of the link alone (no command for ``command_timeout``, or only stale commands) is
*resumable*. It ends without re-centring when a fresh, deadman-held command arrives while the
controller says the resume window is still open (``resume_allowed``: same operator session still
in control, gap shorter than ``resume_window``). Any other reason met on the way (deadman
released, sensor stale, operator lost, e-stop, control changing hands) makes the HOLD
non-resumable for good, and the centred-stick rule applies again.

Command sources (DESIGN 14, only with ``[[source]]`` tables): the controller asks
``egc_robot.source_mux`` which source drives and gives the machine that source's snapshot.

- The ``operator`` source: the snapshot above, unchanged (deadman, centred stick, resume).
- Another source (``source`` names it: a navigation stack, an autonomy stack) has no stick and
  no deadman: its command is fresh by the arbitration's judgement (its ``timeout_s``), so the
  robot enters DRIVING from IDLE or HOLD at once, reason ``source <name>``, and the pipeline
  ramps the base from what it had at the profile's limits. The scan must still be fresh.
  A switch of source counts as control changing hands (``same_control`` false), so an operator
  who takes over from a source needs a centred stick, as any operator taking control does.
- No source may drive because a lock is active (``lock_reason``): HOLD with that reason.
  No source fresh and no lock: as "no operator" (IDLE once the base is stopped).
- ESTOP latches everything whatever drives; only the operator in control leaves it (``reset``
  is the controller's judgement of that operator's newest command).

The function reads no clock: the controller computes the snapshot (freshness, presence) from
monotonic times it is given.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

COMMAND_TIMEOUT = "command timeout"
STALE_COMMANDS = "stale commands"
LINK_REASONS = (COMMAND_TIMEOUT, STALE_COMMANDS)
RESUMED = "resumed after a link gap"


class State(enum.Enum):
    IDLE = "IDLE"
    DRIVING = "DRIVING"
    HOLD = "HOLD"
    ESTOP = "ESTOP"


@dataclass(frozen=True, slots=True)
class Inputs:
    """What the state machine looks at in one control cycle."""

    operator_present: bool
    command_fresh: bool
    deadman: bool
    centred: bool
    scan_fresh: bool
    estop: bool
    reset: bool
    base_stopped: bool
    same_control: bool = True  # control has not changed hands since the previous cycle
    no_operator_reason: str = "no operator"
    stale_reason: str = COMMAND_TIMEOUT  # why the command is not fresh (a LINK_REASONS entry)
    # Short-gap resume (controller's judgement): ``session_kept``: link-aware driving is on and
    # control has not changed hands since the robot last drove; ``resume_allowed``: that, and the
    # gap is still shorter than ``resume_window``.
    session_kept: bool = False
    resume_allowed: bool = False
    # DESIGN 14: the source that drives when it is not the operator (no deadman, no stick), and
    # the reason when a lock keeps every source from driving.
    source: str | None = None
    lock_reason: str | None = None


@dataclass(frozen=True, slots=True)
class Transition:
    state: State
    reason: str
    resumable: bool = False  # a HOLD from the link alone, entered from DRIVING (DESIGN 8)


def hold_reason(inputs: Inputs) -> str | None:
    """The first DESIGN 8 condition that forbids driving, or None if driving is allowed."""
    if not inputs.operator_present:
        return inputs.no_operator_reason
    if not inputs.command_fresh:
        return inputs.stale_reason
    if not inputs.deadman:
        return "deadman released"
    if not inputs.scan_fresh:
        return "sensor stale"
    return None


def next_state(current: Transition, inputs: Inputs) -> Transition:
    """One step of the DESIGN 8 state machine; returns ``current`` itself when nothing changes."""
    if inputs.estop:
        return _keep(current, State.ESTOP, "estop")
    if current.state is State.ESTOP:
        if (
            inputs.operator_present
            and inputs.command_fresh
            and inputs.reset
            and inputs.deadman
            and inputs.centred
        ):
            return Transition(State.HOLD, "estop reset")
        return current
    if inputs.lock_reason is not None:
        return _keep(current, State.HOLD, inputs.lock_reason)
    reason = hold_reason(inputs)
    if not inputs.operator_present:
        if inputs.base_stopped:
            return _keep(current, State.IDLE, inputs.no_operator_reason)
        return _keep(current, State.HOLD, inputs.no_operator_reason)
    if reason is not None:
        if (
            reason in LINK_REASONS
            and inputs.session_kept
            and (current.state is State.DRIVING or current.resumable)
        ):
            return _keep(current, State.HOLD, reason, resumable=True)
        return _keep(current, State.HOLD, reason)
    if current.state is State.DRIVING and inputs.same_control:
        return current
    if current.resumable and inputs.resume_allowed:
        return Transition(State.DRIVING, RESUMED)
    if inputs.source is not None:
        return Transition(State.DRIVING, f"source {inputs.source}")
    if inputs.centred:
        return Transition(State.DRIVING, "fresh centred command")
    return _keep(current, State.HOLD, "waiting for a centred stick")


def _keep(current: Transition, state: State, reason: str, resumable: bool = False) -> Transition:
    if current.state is state and current.reason == reason and current.resumable == resumable:
        return current
    return Transition(state, reason, resumable)
