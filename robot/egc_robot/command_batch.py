"""Which of a batch of operator commands needs a control cycle of its own (DESIGN 7, 8).

The robot vets every command that reaches it, one by one, in order (seq gaps counted, stale
ones dropped), but a control cycle on each one is only worth its cost while the robot keeps up.
When commands queue (a busy machine: a DWA cycle took 19 ms p50 and 37 ms p90 at load 6.6, at
50 commands/s), a cycle per queued command made the queue stand: every command waited for the
cycles of all those before it, and the robot drove on commands ~1 s old, the stale limit of a
filtered mode, where dropping them was finally cheap enough to keep up. So the robot's command
thread takes all that is queued at once (``egc_robot.zenoh_node``), vets each, and runs a cycle
on the newest: a newer command from the same operator with the same control bits makes the
stick of an older one worthless (DESIGN 9: a fresh command makes the one before it worthless).

What must not be skipped is a change the state machine (DESIGN 8) acts on: the deadman released
or pressed, an e-stop, a reset, the stick centred or not (leaving HOLD needs a centred stick),
a mode switch, or another operator. A command whose ``ControlBits`` differ from the next one's
gets its own cycle before the next is vetted, so the state machine sees the same sequence of
states as with one cycle per command, only without the intermediate stick values.
"""

from __future__ import annotations

from dataclasses import dataclass

from egc_common.messages import OperatorCommand, Rejection


@dataclass(frozen=True, slots=True)
class ControlBits:
    """What of a command the state machine (DESIGN 8) reacts to, beyond the stick's value."""

    op: str
    mode: str
    deadman: bool
    estop: bool
    reset: bool
    centred: bool


def control_bits(command: OperatorCommand, centre_tolerance: float) -> ControlBits:
    """``command``'s control bits; centred as the controller judges it (``centre_tolerance``)."""
    return ControlBits(
        op=command.op,
        mode=command.mode,
        deadman=command.deadman,
        estop=command.estop,
        reset=command.reset,
        centred=abs(command.x) <= centre_tolerance and abs(command.y) <= centre_tolerance,
    )


def decoded_control_bits(
    decoded: OperatorCommand | Rejection, centre_tolerance: float
) -> ControlBits | None:
    """The control bits of a decoded command payload, None when it did not decode (it will be
    rejected, so it changes nothing and needs no cycle before it)."""
    if isinstance(decoded, Rejection):
        return None
    return control_bits(decoded, centre_tolerance)


def cycle_before(pending: ControlBits | None, following: ControlBits | None) -> bool:
    """Whether the accepted command not yet cycled on (``pending``, None: there is none) needs
    its cycle before the ``following`` command (None: undecodable) is vetted."""
    return pending is not None and following is not None and following != pending
