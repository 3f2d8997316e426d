"""The operator's via points (DESIGN 7 ``egc/<robot>/goal``, issue 11), pure: no IO, no clock.

- **Input**: ``--goal X,Y`` (repeatable, in order; ``-2,3`` is a value, see
  ``egc_common.cli_args``) or ``--route FILE`` (one point per line, ``x,y`` or ``x y``, ``#``
  comments and blank lines ignored, at most ``MAX_GOAL_POINTS``), in ``--goal-frame odom|map``.
  Numbers are plain ASCII decimals (``egc_common.cli_args.plain_float``: not ``1_000`` nor
  full-width digits); a file may start with a UTF-8 byte-order mark and is read with a bound
  (``MAX_ROUTE_FILE_BYTES``). Errors are ``RouteError`` with one clear line (a file's errors
  name ``file:line``).
- **What to send**: the whole route, in order, every time. The robot keeps its progress when
  the same route (same operator, frame and points) comes again, so the operator republishes it
  once a second: a robot that starts later, or control taken later, still gets it. The robot
  echoes the active via point (telemetry ``goal``) and how many follow it (``goals_left``).
- **Next** (a gamepad button): the route without the active via point and those before it
  (``after_next``), found from the robot's echo; a new route for the robot, which starts at
  its first point. With nothing active (route done, or not accepted yet) there is nothing to
  skip. **Clear**: the empty route (the robot drops its via points).
- ``RoutePlanner`` holds the route and numbers the GoalMessages (``seq`` increasing) and says
  when one is due: as soon as the robot is seen with this operator in control (the robot takes
  via points from the operator in control only; sending earlier would only be rejected and
  counted), then every ``REPUBLISH_NS``, and at once after next, clear and on taking control.
  An operator without a route sends nothing until it acts.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

from egc_common.cli_args import PLAIN_NUMBER, MiB, plain_float, read_input_file
from egc_common.messages import GOAL_FRAMES, MAX_GOAL_COORD_M, MAX_GOAL_POINTS, GoalMessage

XY = tuple[float, float]
REPUBLISH_NS = 1_000_000_000
# 64 points need a few hundred bytes; room for comments, and far less than a device can pour.
MAX_ROUTE_FILE_BYTES = 1 * MiB
SAME_POINT_M = 1e-6  # the robot echoes the floats it was sent; this only absorbs rounding


class RouteError(ValueError):
    """A bad --goal, --route file or frame: the message is one line for the user."""


@dataclass(frozen=True, slots=True)
class Route:
    """The operator's via points in ``frame`` (metres), in the order they are to be reached."""

    frame: str = "odom"
    points: tuple[XY, ...] = ()

    def __post_init__(self) -> None:
        if self.frame not in GOAL_FRAMES:
            raise RouteError(f"frame must be one of {', '.join(GOAL_FRAMES)}, got {self.frame!r}")
        if len(self.points) > MAX_GOAL_POINTS:
            raise RouteError(f"at most {MAX_GOAL_POINTS} via points, got {len(self.points)}")


_SEPARATOR = re.compile(r"\s*,\s*|\s+")


def _coordinate(text: str) -> float:
    value = plain_float(text)  # ValueError for anything but a plain ASCII decimal
    if not math.isfinite(value) or abs(value) > MAX_GOAL_COORD_M:
        raise ValueError(f"{text!r} is not a finite coordinate within {MAX_GOAL_COORD_M:g} m")
    return value


def parse_point(text: str, *, spaces: bool = False) -> XY:
    """``"X,Y"`` (or ``"X Y"`` with ``spaces``) in metres; ValueError with the reason."""
    stripped = text.strip()
    parts = _SEPARATOR.split(stripped) if spaces else [p.strip() for p in stripped.split(",")]
    if len(parts) != 2 or not all(parts):
        form = "'x,y' or 'x y'" if spaces else "X,Y"
        raise ValueError(f"expected {form}, got {text.strip()!r}")
    try:
        return _coordinate(parts[0]), _coordinate(parts[1])
    except ValueError as exc:
        if "finite" in str(exc):
            raise
        odd = [p for p in parts if _python_float(p) and not PLAIN_NUMBER.fullmatch(p)]
        why = f" ({odd[0]!r}: digits 0-9 only, no '_')" if odd else ""
        what = "two plain decimal numbers" if odd else "two numbers"
        raise ValueError(f"expected {what}, got {text.strip()!r}{why}") from None


def _python_float(text: str) -> bool:
    """Whether ``float()`` alone would take ``text`` (``1_000``, full-width digits)."""
    try:
        float(text)
    except ValueError:
        return False
    return True


def parse_goals(values: list[str]) -> tuple[XY, ...]:
    """The points of repeated ``--goal X,Y`` options, in order."""
    points = []
    for value in values:
        try:
            points.append(parse_point(value))
        except ValueError as exc:
            raise RouteError(f"--goal: {exc}") from None
    return tuple(points)


def parse_route_text(text: str, name: str = "<route>") -> tuple[XY, ...]:
    """A route file's points: one ``x,y`` or ``x y`` per line; ``#`` comments, blank lines."""
    points: list[XY] = []
    text = text.removeprefix("\ufeff")  # a byte-order mark some editors write
    for line_no, line in enumerate(text.splitlines(), start=1):
        content = line.split("#", 1)[0].strip()
        if not content:
            continue
        try:
            points.append(parse_point(content, spaces=True))
        except ValueError as exc:
            raise RouteError(f"{name}:{line_no}: {exc}") from None
        if len(points) > MAX_GOAL_POINTS:
            raise RouteError(f"{name}:{line_no}: more than {MAX_GOAL_POINTS} via points")
    if not points:
        raise RouteError(f"{name}: no via points (one 'x,y' or 'x y' per line)")
    return tuple(points)


def load_route_file(path: str | Path) -> tuple[XY, ...]:
    try:
        text = read_input_file(path, "route file", MAX_ROUTE_FILE_BYTES)
    except ValueError as exc:
        raise RouteError(str(exc)) from None
    return parse_route_text(text, str(path))


def route_from_options(goals: list[str] | None, route_file: str | None, frame: str) -> Route:
    """The route of ``--goal`` (repeatable) or ``--route FILE``, in ``--goal-frame``."""
    if goals and route_file is not None:
        raise RouteError("--goal and --route: give the via points one way, not both")
    points = load_route_file(route_file) if route_file is not None else parse_goals(goals or [])
    if len(points) > MAX_GOAL_POINTS:
        raise RouteError(f"at most {MAX_GOAL_POINTS} via points, got {len(points)}")
    return Route(frame, points)


def active_index(
    route: Route, goal: XY | None, goal_frame: str | None, goals_left: int
) -> int | None:
    """Which of ``route.points`` the robot reports active (telemetry goal, goals_left), or None.

    None when the robot has no active via point, or its echo is not of this route (another
    frame, or a point this route does not have at that place).
    """
    if goal is None or goal_frame != route.frame:
        return None
    index = len(route.points) - 1 - goals_left
    if 0 <= index < len(route.points) and _same(route.points[index], goal):
        return index
    return None


def _same(a: XY, b: XY) -> bool:
    return abs(a[0] - b[0]) <= SAME_POINT_M and abs(a[1] - b[1]) <= SAME_POINT_M


def after_next(route: Route, goal: XY | None, goal_frame: str | None, goals_left: int) -> Route:
    """The route after "next": without the active via point and those before it.

    Unchanged when nothing is active (see ``active_index``): skipping blind could send the robot
    back over points it has passed, because a changed route starts again at its first point.
    """
    index = active_index(route, goal, goal_frame, goals_left)
    if index is None:
        return route
    return Route(route.frame, route.points[index + 1 :])


def after_clear(route: Route) -> Route:
    return Route(route.frame, ())


class RoutePlanner:
    """The operator's route, its GoalMessages (seq increasing) and when to send one."""

    def __init__(self, route: Route | None = None, first_seq: int = 1) -> None:
        self._route = route or Route()
        # Nothing to say until there is a route, or the operator cleared or skipped.
        self._engaged = bool(self._route.points)
        self._seq = first_seq - 1
        self._sent_ns: int | None = None
        self._urgent = False

    @property
    def route(self) -> Route:
        return self._route

    @property
    def engaged(self) -> bool:
        return self._engaged

    def next(self, goal: XY | None, goal_frame: str | None, goals_left: int) -> bool:
        """The operator skips the active via point; True when the route changed."""
        changed = after_next(self._route, goal, goal_frame, goals_left)
        if changed == self._route:
            return False
        self._route, self._engaged, self._urgent = changed, True, True
        return True

    def clear(self) -> None:
        """The operator clears the via points (sent at once, even when already empty)."""
        self._route, self._engaged, self._urgent = after_clear(self._route), True, True

    def resend(self) -> None:
        """Send at once when next due (this operator has just taken control)."""
        self._urgent = True

    def due(self, now_ns: int, robot_present: bool) -> bool:
        """A GoalMessage is due: the robot is there (and listens to this operator) and the
        route is new, changed or 1 s old."""
        if not self._engaged or not robot_present:
            return False
        return self._urgent or self._sent_ns is None or now_ns - self._sent_ns >= REPUBLISH_NS

    def message(self, op: str, stamp_ns: int, now_ns: int) -> GoalMessage:
        """The route as the next GoalMessage (and it counts as sent at ``now_ns``)."""
        self._seq += 1
        self._sent_ns, self._urgent = now_ns, False
        return GoalMessage(self._seq, stamp_ns, op, self._route.frame, self._route.points)
