"""The simulator's world: an occupancy grid in metres, plus what a scenario suggests.

Layout follows ``nav_msgs/OccupancyGrid`` (and therefore ROS map_server after it has flipped the
image): row 0 is the *bottom* row (lowest y) and cell ``(row, col)`` covers
``x in [origin_x + col * res, origin_x + (col + 1) * res)`` and the same in y with ``row``.

Unknown cells (map_server's -1) **block**: the robot cannot enter them and the lidar sees them as
walls. In real maps they are the outside of the building and the inside of pillars and furniture
the mapping laser could not see into; a simulator that let the robot drive there would report
success in places nobody has seen. Everything outside the grid counts as unknown too.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt
from egc_common.messages import MapMessage

BoolGrid = npt.NDArray[np.bool_]
Pose = tuple[float, float, float]


class WorldError(ValueError):
    """A world cannot be loaded or built; the message says which file or value and why."""


def read_world_text(path: Path, what: str) -> str:
    """A world description file as text; a WorldError naming ``what`` and the file if not."""
    try:
        return path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise WorldError(f"{what} not found: {path}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise WorldError(f"cannot read {what} {path}: {exc}") from None


@dataclass(frozen=True, slots=True)
class Area:
    """A named axis-aligned box in world coordinates (e.g. the paper's areas A-D of Fig. 9)."""

    name: str
    x_min_m: float
    y_min_m: float
    x_max_m: float
    y_max_m: float

    def contains(self, x_m: float, y_m: float) -> bool:
        return self.x_min_m <= x_m <= self.x_max_m and self.y_min_m <= y_m <= self.y_max_m


@dataclass(frozen=True, slots=True, eq=False)
class World:
    """An occupancy grid (True = blocks: occupied or unknown) and its placement in the world.

    ``start_pose`` (x_m, y_m, yaw_rad), ``goal`` (x_m, y_m) and ``goal_tolerance_m`` are the
    scenario's suggestions where the world defines them (the hallway, random worlds, TOML
    worlds); command-line values override them.
    """

    name: str
    occupancy: BoolGrid
    unknown: BoolGrid
    resolution_m: float
    origin_x_m: float
    origin_y_m: float
    start_pose: Pose | None = None
    goal: tuple[float, float] | None = None
    goal_tolerance_m: float | None = None
    areas: tuple[Area, ...] = ()

    def __post_init__(self) -> None:
        occ = np.asarray(self.occupancy, dtype=bool)
        unk = np.asarray(self.unknown, dtype=bool)
        if occ.ndim != 2 or occ.shape[0] < 1 or occ.shape[1] < 1:
            raise WorldError(
                f"world {self.name!r}: the occupancy grid must be a non-empty 2-D array"
            )
        if unk.shape != occ.shape:
            raise WorldError(f"world {self.name!r}: unknown mask shape differs from the grid's")
        if not (math.isfinite(self.resolution_m) and self.resolution_m > 0):
            raise WorldError(f"world {self.name!r}: resolution must be a positive number of metres")
        if not (math.isfinite(self.origin_x_m) and math.isfinite(self.origin_y_m)):
            raise WorldError(f"world {self.name!r}: origin must be finite")
        occ = occ | unk  # unknown always blocks
        occ.setflags(write=False)
        unk = unk.copy()
        unk.setflags(write=False)
        object.__setattr__(self, "occupancy", occ)
        object.__setattr__(self, "unknown", unk)

    @property
    def rows(self) -> int:
        return int(self.occupancy.shape[0])

    @property
    def cols(self) -> int:
        return int(self.occupancy.shape[1])

    @property
    def width_m(self) -> float:
        return self.cols * self.resolution_m

    @property
    def height_m(self) -> float:
        return self.rows * self.resolution_m

    @property
    def origin(self) -> tuple[float, float]:
        """World pose (x_m, y_m) of the lower-left corner of the lower-left cell (map_server)."""
        return (self.origin_x_m, self.origin_y_m)

    def outside_message(self, xy: tuple[float, float], what: str, name: str) -> str | None:
        """One line saying ``what`` at ``xy`` lies outside this map (named ``name``), or None.

        A goal there can never be reached: every run would time out (``episode`` and
        ``experiment`` refuse it up front with these words)."""
        x0, y0 = self.origin
        x1, y1 = x0 + self.width_m, y0 + self.height_m
        if x0 <= xy[0] <= x1 and y0 <= xy[1] <= y1:
            return None
        return (
            f"{what} {xy[0]:g},{xy[1]:g} is outside map {name!r} "
            f"(x {x0:g} to {x1:g}, y {y0:g} to {y1:g} m)"
        )

    @property
    def free(self) -> BoolGrid:
        """Cells the robot may occupy (map_server's 0)."""
        result: BoolGrid = ~self.occupancy
        return result

    @property
    def occupied(self) -> BoolGrid:
        """Cells known to be occupied (map_server's 100), without the unknown ones."""
        result: BoolGrid = self.occupancy & ~self.unknown
        return result

    def cell_of(self, x_m: float, y_m: float) -> tuple[int, int]:
        """(row, col) of the cell holding a point; may lie outside the grid."""
        res = self.resolution_m
        return (
            math.floor((y_m - self.origin_y_m) / res),
            math.floor((x_m - self.origin_x_m) / res),
        )

    def blocked_at(self, x_m: float, y_m: float) -> bool:
        """True if the point lies in a blocking cell or outside the grid."""
        row, col = self.cell_of(x_m, y_m)
        if not (0 <= row < self.rows and 0 <= col < self.cols):
            return True
        return bool(self.occupancy[row, col])


def map_message(world: World, stamp_ns: int = 0) -> MapMessage:
    """The world as the operator view's map (``egc/<robot>/map``): row 0 = top on the wire."""
    return MapMessage(
        stamp_ns=stamp_ns,
        resolution_m=world.resolution_m,
        origin_x_m=world.origin_x_m,
        origin_y_m=world.origin_y_m,
        blocked=np.flipud(world.occupancy),
        goal=world.goal,
    )


def world_id(world: World) -> str:
    """An id of the world's map frame (DESIGN 15 ``map`` in ``egc/<robot>/info``): the digest
    of its grid, resolution and origin. Simulated robots in the same world share a map frame
    and give the same id, whatever the file was called or where it was loaded from."""
    digest = hashlib.sha256()
    grid = np.ascontiguousarray(world.occupancy, dtype=np.bool_)
    digest.update(
        repr((grid.shape, world.resolution_m, world.origin_x_m, world.origin_y_m)).encode()
    )
    digest.update(grid.tobytes())
    return f"grid:{digest.hexdigest()[:16]}"
