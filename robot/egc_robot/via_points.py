"""The operator's via points on the robot (DESIGN 7 ``egc/<robot>/goal``, issue 11), pure.

The operator in control sends an ordered list of via points in the ``odom`` frame (the base's
odometry) or the ``map`` frame (when the driver gives a map pose); an empty list clears them.
The robot works through them in order: the active one is handed to the filter in the robot
frame {R}, and when the robot is within ``tolerance_m`` of it the next one becomes active.
After the last one is reached there is no active via point (the route is done).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

Pose = tuple[float, float, float]  # x_m, y_m, theta_rad in a frame
XY = tuple[float, float]

DEFAULT_TOLERANCE_M = 0.3


@dataclass(frozen=True, slots=True)
class ViaPoints:
    """An operator's route: the points in ``frame``, and the index of the active one."""

    frame: str
    points: tuple[XY, ...]
    op: str = ""
    index: int = 0

    @property
    def active(self) -> XY | None:
        return self.points[self.index] if self.index < len(self.points) else None

    @property
    def remaining_after_active(self) -> int:
        return max(0, len(self.points) - self.index - 1)


NO_ROUTE = ViaPoints("odom", ())


def to_robot_frame(point: XY, pose: Pose) -> XY:
    """A point of the pose's frame in {R} of a robot at ``pose`` (x forward, y left)."""
    dx, dy = point[0] - pose[0], point[1] - pose[1]
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return (c * dx + s * dy, -s * dx + c * dy)


def advance(route: ViaPoints, pose: Pose | None, tolerance_m: float) -> ViaPoints:
    """The route with every via point the robot at ``pose`` has reached skipped past.

    Only the active point counts: a later point the robot happens to pass first does not skip
    the ones before it (the operator ordered them).
    """
    if pose is None:
        return route
    index = route.index
    while index < len(route.points):
        x, y = route.points[index]
        if math.hypot(x - pose[0], y - pose[1]) > tolerance_m:
            break
        index += 1
    return route if index == route.index else replace(route, index=index)
