"""A planar lidar on an occupancy grid: exact ray casting against the blocked cells' boundary.

The boundary of the blocked region of a grid is made of cell faces. ``Raycaster`` extracts them
once per world, merges collinear neighbours into maximal axis-aligned segments and keeps, for
each, the side free space lies on. A scan then

1. keeps the segments that face the sensor (the sensor is on their free side) and come within
   ``range_max`` of it: a ray leaving free space can only cross into an obstacle through one;
2. turns each segment into the interval of beam indices it subtends;
3. intersects every (segment, beam) pair in closed form (``t = (X - x) / cos(theta)`` for a
   vertical face at X, the same with y and sin for a horizontal one) and keeps the nearest per
   beam.

Ranges are therefore exact (floating point), not just to a cell, in time that grows with the
number of visible faces rather than with the range. Everything outside the grid is blocked
(``grid_world``), so every ray ends within the padded map. A sensor inside a blocked cell reads
0 on every beam (a real lidar pressed against a wall reads below its minimum range).

``LidarConfig`` describes the sensor as a ROS ``LaserScan`` would: beams over a field of view
centred on the robot's x axis, ``range_min``/``range_max``, Gaussian range noise, and how a beam
with no return within ``range_max`` is reported (``inf``, as the REP 117 drivers do, or
``range_max + 1`` as some older drivers do). Both encodings are dropped by the scan consumers
(``egc_common.scan``), and the simulator declares no-return as free: within ``range_max`` it
truly is.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from egc_common.scan import Scan

from egc_sim.grid_world import World

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

NO_RETURN = ("inf", "range_max_plus_one")
_TWO_PI = 2.0 * math.pi
_ANGLE_EPS = 1e-9


@dataclass(frozen=True, slots=True)
class LidarConfig:
    """A planar laser scanner mounted at the robot's centre, facing +x of {R}."""

    beams: int = 360
    fov_rad: float = _TWO_PI
    range_min_m: float = 0.05
    range_max_m: float = 10.0
    noise_std_m: float = 0.0
    no_return: str = "inf"

    def __post_init__(self) -> None:
        if not isinstance(self.beams, int) or not 1 <= self.beams <= 100_000:
            raise ValueError(f"lidar beams must be an integer in [1, 100000], got {self.beams}")
        if not (math.isfinite(self.fov_rad) and 0.0 < self.fov_rad <= _TWO_PI):
            raise ValueError(f"lidar fov must be in (0, 2 pi] rad, got {self.fov_rad}")
        if not (
            math.isfinite(self.range_min_m)
            and math.isfinite(self.range_max_m)
            and 0.0 <= self.range_min_m < self.range_max_m
        ):
            raise ValueError("lidar needs finite 0 <= range_min < range_max")
        if not (math.isfinite(self.noise_std_m) and self.noise_std_m >= 0.0):
            raise ValueError(f"lidar noise std must be >= 0, got {self.noise_std_m}")
        if self.no_return not in NO_RETURN:
            raise ValueError(f"lidar no_return must be one of {', '.join(NO_RETURN)}")

    @property
    def full_circle(self) -> bool:
        return self.fov_rad >= _TWO_PI

    @property
    def angle_min_rad(self) -> float:
        return -math.pi if self.full_circle else -0.5 * self.fov_rad

    @property
    def angle_increment_rad(self) -> float:
        """A full circle has ``beams`` equal gaps; a partial fov puts beams on both edges."""
        if self.full_circle:
            return _TWO_PI / self.beams
        return self.fov_rad / (self.beams - 1) if self.beams > 1 else 0.0

    @property
    def no_return_value(self) -> float:
        return math.inf if self.no_return == "inf" else self.range_max_m + 1.0


def _runs(mask: npt.NDArray[np.bool_]) -> tuple[IntArray, IntArray, IntArray]:
    """Maximal runs of True along axis 1: (line index, first, one past last)."""
    padded = np.zeros((mask.shape[0], mask.shape[1] + 2), dtype=np.int8)
    padded[:, 1:-1] = mask
    step = np.diff(padded, axis=1)
    line, first = np.nonzero(step == 1)
    _, end = np.nonzero(step == -1)
    return line.astype(np.int64), first.astype(np.int64), end.astype(np.int64)


class Raycaster:
    """Exact ray casting against a world's blocked cells (module docstring)."""

    def __init__(self, world: World) -> None:
        self.world = world
        res, ox, oy = world.resolution_m, world.origin_x_m, world.origin_y_m
        padded = np.pad(world.occupancy, 1, constant_values=True)
        left, right = padded[1:-1, :-1], padded[1:-1, 1:]  # across vertical grid lines
        below, above = padded[:-1, 1:-1], padded[1:, 1:-1]  # across horizontal grid lines
        vertical: list[FloatArray] = []
        horizontal: list[FloatArray] = []
        for mask, normal in ((left & ~right, 1.0), (~left & right, -1.0)):
            k, r0, r1 = _runs(mask.T)  # along the rows of vertical line k
            vertical.append(
                np.stack([ox + k * res, oy + r0 * res, oy + r1 * res, np.full(k.size, normal)])
            )
        for mask, normal in ((below & ~above, 1.0), (~below & above, -1.0)):
            k, c0, c1 = _runs(mask)  # along the columns of horizontal line k
            horizontal.append(
                np.stack([oy + k * res, ox + c0 * res, ox + c1 * res, np.full(k.size, normal)])
            )
        v = np.concatenate(vertical, axis=1)
        h = np.concatenate(horizontal, axis=1)
        n_v = v.shape[1]
        self.is_vertical = np.concatenate([np.ones(n_v, bool), np.zeros(h.shape[1], bool)])
        # Endpoints (x0, y0) -> (x1, y1), the line coordinate and the free side's normal sign.
        self.x0 = np.concatenate([v[0], h[1]])
        self.x1 = np.concatenate([v[0], h[2]])
        self.y0 = np.concatenate([v[1], h[0]])
        self.y1 = np.concatenate([v[2], h[0]])
        self.normal = np.concatenate([v[3], h[3]])

    def cast(
        self,
        x_m: float,
        y_m: float,
        yaw_rad: float,
        angle_min_rad: float,
        angle_increment_rad: float,
        beams: int,
        range_max_m: float,
    ) -> FloatArray:
        """True ranges of ``beams`` rays from (x, y); inf where nothing lies within range_max."""
        ranges = np.full(beams, np.inf)
        if self.world.blocked_at(x_m, y_m):
            ranges[:] = 0.0
            return ranges
        vert = self.is_vertical
        ahead = np.where(vert, x_m - self.x0, y_m - self.y0) * self.normal > 0.0
        dx = np.clip(x_m, self.x0, self.x1) - x_m
        dy = np.clip(y_m, self.y0, self.y1) - y_m
        keep = np.flatnonzero(ahead & (dx * dx + dy * dy <= range_max_m * range_max_m))
        if keep.size == 0:
            return ranges
        ax, ay = self.x0[keep] - x_m, self.y0[keep] - y_m
        bx, by = self.x1[keep] - x_m, self.y1[keep] - y_m
        base = yaw_rad + angle_min_rad
        a0 = np.mod(np.arctan2(ay, ax) - base, _TWO_PI)
        a1 = np.mod(np.arctan2(by, bx) - base, _TWO_PI)
        ccw = ax * by - ay * bx >= 0.0  # a segment that faces the sensor subtends < pi
        lo = np.where(ccw, a0, a1) - _ANGLE_EPS
        hi = lo + np.mod(np.where(ccw, a1 - a0, a0 - a1), _TWO_PI) + 2.0 * _ANGLE_EPS
        seg, beam = self._pairs(lo, hi, angle_increment_rad, beams)
        theta = base + beam * angle_increment_rad
        vk = vert[keep][seg]
        t = np.where(vk, ax[seg], ay[seg]) / np.where(vk, np.cos(theta), np.sin(theta))
        np.minimum.at(ranges, beam, t)
        ranges[ranges > range_max_m] = np.inf
        return ranges

    @staticmethod
    def _pairs(lo: FloatArray, hi: FloatArray, inc: float, beams: int) -> tuple[IntArray, IntArray]:
        """(segment, beam) for every beam whose angle i * inc lies in [lo, hi] modulo 2 pi."""
        if inc <= 0.0:  # a single beam at angle 0
            seg = np.flatnonzero((lo <= 0.0) | (hi >= _TWO_PI))
            return seg, np.zeros(seg.size, dtype=np.int64)
        first = np.ceil(lo / inc).astype(np.int64)
        if abs(beams * inc - _TWO_PI) < 1e-9:  # a full circle: one interval, indices mod beams
            counts = np.maximum(np.floor(hi / inc).astype(np.int64) - first + 1, 0)
            seg, k = _expand(first, counts)
            return seg, k % beams
        # A partial field of view: [lo, min(hi, 2 pi)) and, past 2 pi, [0, hi - 2 pi].
        last = beams - 1
        stop = np.minimum(np.floor(np.minimum(hi, _TWO_PI - _ANGLE_EPS) / inc), last)
        wrap_stop = np.minimum(np.floor((hi - _TWO_PI) / inc), last).astype(np.int64)
        first = np.maximum(first, 0)
        starts = np.concatenate([first, np.zeros_like(first)])
        counts = np.concatenate(
            [np.maximum(stop.astype(np.int64) - first + 1, 0), np.maximum(wrap_stop + 1, 0)]
        )
        seg, k = _expand(starts, counts)
        return seg % lo.size, k


def _expand(starts: IntArray, counts: IntArray) -> tuple[IntArray, IntArray]:
    """(owner, value) of the integer runs starts[j], ..., starts[j] + counts[j] - 1."""
    owner = np.repeat(np.arange(starts.size), counts)
    offset = np.arange(owner.size) - np.repeat(np.cumsum(counts) - counts, counts)
    return owner, starts[owner] + offset


class Lidar:
    """A ``LidarConfig`` on a world: scans in {R} as ``egc_common.scan.Scan``."""

    def __init__(self, world: World, config: LidarConfig) -> None:
        self.config = config
        self.raycaster = Raycaster(world)

    def scan(
        self, pose: tuple[float, float, float], rng: np.random.Generator, stamp_ns: int = 0
    ) -> Scan:
        c = self.config
        ranges = self.raycaster.cast(
            pose[0],
            pose[1],
            pose[2],
            c.angle_min_rad,
            c.angle_increment_rad,
            c.beams,
            c.range_max_m,
        )
        hit = np.isfinite(ranges)
        if c.noise_std_m > 0.0:
            ranges[hit] = np.maximum(
                ranges[hit] + rng.normal(0.0, c.noise_std_m, int(hit.sum())), 0.0
            )
        ranges[~hit] = c.no_return_value
        return Scan.uniform(
            ranges,
            c.angle_min_rad,
            c.angle_increment_rad,
            c.range_min_m,
            c.range_max_m,
            stamp_ns=stamp_ns,
            no_return_is_free=True,
        )
