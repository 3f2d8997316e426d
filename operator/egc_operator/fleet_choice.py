"""Which robot an operator drives (DESIGN 15): the listing, the typed commands and the cycle.

Pure: the robots are given (ids in listing order, ``FleetWatch.snapshot``), nothing here reads
a clock or the network.

- ``listing``: the numbered list the terminal shows (``1) r1  IDLE  pioneer3dx, ...``).
- ``parse_typed``: a line typed on the terminal: ``robot NAME``, ``robot N`` (the listing's
  number), a bare ``NAME`` or ``N``, ``next`` / ``n``, ``prev`` / ``previous`` / ``p``,
  ``list`` / ``ls``, ``help`` / ``?``; anything else is a ``TypedError`` that says what is
  accepted.
- ``resolve``: a name or a listing number to a robot id of the listing.
- ``cycled``: the robot ``step`` places after the driven one (the gamepad's button pair, the
  typed ``next`` / ``prev``), wrapping around; a driven robot that left the listing counts
  where its id would sort.
"""

from __future__ import annotations

import bisect
from collections.abc import Sequence
from dataclasses import dataclass

from egc_common.robot_info import RobotInfo

HELP = (
    "type 'robot NAME' or 'robot N' (or just NAME or N) to drive another robot, 'next' or "
    "'prev' to cycle, 'list' to list them"
)


@dataclass(frozen=True, slots=True)
class Pick:
    """Drive the robot named (or numbered, 1-based, in the listing) ``which``."""

    which: str


@dataclass(frozen=True, slots=True)
class Step:
    """Drive the robot ``step`` places after the driven one (+1 next, -1 previous)."""

    step: int


@dataclass(frozen=True, slots=True)
class ListRobots:
    pass


@dataclass(frozen=True, slots=True)
class Help:
    pass


@dataclass(frozen=True, slots=True)
class TypedError:
    text: str


Typed = Pick | Step | ListRobots | Help | TypedError

_NEXT = {"next", "n", "+"}
_PREV = {"prev", "previous", "p", "-"}


def parse_typed(line: str) -> Typed | None:
    """One typed line; None for a blank one."""
    words = line.split()
    if not words:
        return None
    head = words[0].lower()
    if len(words) == 1:
        if head in _NEXT:
            return Step(+1)
        if head in _PREV:
            return Step(-1)
        if head in ("list", "ls"):
            return ListRobots()
        if head in ("help", "?", "h"):
            return Help()
        if head == "robot":
            return TypedError("'robot' needs a name or a number: 'robot r2', 'robot 2'")
        return Pick(words[0])
    if head == "robot" and len(words) == 2:
        return Pick(words[1])
    return TypedError(f"not understood: {line.strip()!r}; {HELP}")


def resolve(robots: Sequence[str], which: str) -> str | TypedError:
    """A robot id of ``robots`` by its id or its number in the listing (1-based)."""
    if which in robots:
        return which
    if which.isdecimal():
        number = int(which)
        if 1 <= number <= len(robots):
            return robots[number - 1]
        if not robots:
            return TypedError(f"no robot number {number}: no robots are seen")
        return TypedError(f"no robot number {number}: the listing has 1 to {len(robots)}")
    seen = ", ".join(robots) if robots else "none"
    return TypedError(f"no robot {which!r} is seen (robots: {seen})")


def cycled(robots: Sequence[str], current: str | None, step: int) -> str | None:
    """The robot ``step`` places after ``current`` in ``robots`` (sorted ids), wrapping; None
    when there is no other robot to go to."""
    ordered = sorted(robots)
    if not ordered or step == 0:
        return None
    if current is None:
        return ordered[0] if step > 0 else ordered[-1]
    if current in ordered:
        index = ordered.index(current)
        target = ordered[(index + step) % len(ordered)]
    else:  # the driven robot left: count from where it would sort
        index = bisect.bisect_left(ordered, current)
        target = ordered[(index + (step if step < 0 else step - 1)) % len(ordered)]
    return None if target == current else target


def robot_summary(robot: str, info: RobotInfo | None, state: str | None = None) -> str:
    """One robot as the listing shows it; ``state`` (the newest state message) wins over the
    info reply's snapshot."""
    if info is None:
        return f"{robot}  {state or '?'}  (no info reply yet)"
    who = f", operator {info.operator}" if info.operator else ""
    return (
        f"{robot}  {state or info.state}  {info.profile}, driver {info.driver}, filter "
        f"{info.filter}, camera {info.camera}{who}"
    )


def listing(
    robots: Sequence[tuple[str, RobotInfo | None]],
    driven: str | None,
    states: dict[str, str] | None = None,
) -> list[str]:
    """The numbered lines of the terminal's list, the driven robot marked with ``*``."""
    states = states or {}
    return [
        f"{'*' if robot == driven else ' '}{number}) {robot_summary(robot, info, states.get(robot))}"
        for number, (robot, info) in enumerate(robots, start=1)
    ]
