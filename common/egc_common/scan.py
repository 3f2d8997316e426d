"""Laser scans and their conversion to points in the robot frame {R} (DESIGN 3, 5).

A reading is *valid* when it is finite and within [range_min, range_max]. NaN, inf, readings
below range_min (the sensor's blind zone) and above range_max (the usual "no return" encoding,
e.g. range_max + 1) are dropped. Whether "no valid reading at all" means *free* or *unknown* is
the driver's declaration (``no_return_is_free``); the filter treats unknown as a reason to stop.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from egc_common.footprint import (
    Footprint,
    closest_boundary_points,
    ray_exit_m,
    signed_distance,
)

FloatArray = npt.NDArray[np.float64]

# Coordinates beyond this magnitude (m) are treated as invalid readings: no real sensor produces
# them, and squaring them would overflow.
MAX_ABS_COORD_M = 1e6


@dataclass(frozen=True, slots=True, eq=False)
class Scan:
    """One planar range scan: beam angles in {R} (rad, CCW from +x) and ranges (m)."""

    angles_rad: FloatArray
    ranges_m: FloatArray
    range_min_m: float
    range_max_m: float
    stamp_ns: int = 0
    no_return_is_free: bool = False
    mount_x_m: float = 0.0
    mount_y_m: float = 0.0
    # Obstacle points in {R} that no beam's range holds: REP 117's -inf readings placed where
    # the object may be nearest (``too_close_points``). (K, 2) or None.
    extra_xy_m: FloatArray | None = None
    _obstacles: ObstaclePoints | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        angles = np.asarray(self.angles_rad, dtype=np.float64)
        ranges = np.asarray(self.ranges_m, dtype=np.float64)
        if angles.ndim != 1 or angles.shape != ranges.shape:
            raise ValueError("scan angles and ranges must be 1-D arrays of the same length")
        if not (math.isfinite(self.range_min_m) and math.isfinite(self.range_max_m)):
            raise ValueError("scan range_min/range_max must be finite")
        if not 0.0 <= self.range_min_m < self.range_max_m:
            raise ValueError("scan needs 0 <= range_min < range_max")
        if not np.all(np.isfinite(angles)):
            raise ValueError("scan angles must be finite")
        object.__setattr__(self, "angles_rad", angles)
        object.__setattr__(self, "ranges_m", ranges)

    @staticmethod
    def uniform(
        ranges_m: npt.ArrayLike,
        angle_min_rad: float,
        angle_increment_rad: float,
        range_min_m: float,
        range_max_m: float,
        **kwargs: object,
    ) -> Scan:
        """A scan in the ROS LaserScan layout (first angle and increment)."""
        r = np.asarray(ranges_m, dtype=np.float64)
        angles = angle_min_rad + angle_increment_rad * np.arange(r.size, dtype=np.float64)
        return Scan(angles, r, range_min_m, range_max_m, **kwargs)  # type: ignore[arg-type]

    @property
    def valid_mask(self) -> npt.NDArray[np.bool_]:
        r = self.ranges_m
        with np.errstate(invalid="ignore"):
            return np.isfinite(r) & (r >= self.range_min_m) & (r <= self.range_max_m)

    def points(self) -> FloatArray:
        """Valid readings as a read-only (N, 2) array of (x, y) in {R}, metres."""
        return self.obstacles().xy

    def obstacles(self) -> ObstaclePoints:
        """Valid readings as prepared points in {R}, computed once per scan and cached.

        A driver can call this in its receiving thread, so the command path finds it done.
        """
        cached = self._obstacles
        if cached is None:
            xy = ranges_to_points(
                self.ranges_m,
                self.angles_rad,
                self.range_min_m,
                self.range_max_m,
                self.mount_x_m,
                self.mount_y_m,
            )
            if self.extra_xy_m is not None and len(self.extra_xy_m):
                xy = np.concatenate((xy, np.asarray(self.extra_xy_m, np.float64).reshape(-1, 2)))
            ahead_m, behind_m = seen_along_axis_of_scan(
                self.angles_rad,
                self.ranges_m,
                self.range_min_m,
                self.range_max_m,
                self.mount_x_m,
                self.mount_y_m,
            )
            cached = obstacle_points(xy, seen_ahead_m=ahead_m, seen_behind_m=behind_m)
            for array in (cached.xy, cached.x, cached.y, cached.r2):
                array.flags.writeable = False
            object.__setattr__(self, "_obstacles", cached)
        return cached


@dataclass(frozen=True, slots=True, eq=False)
class ObstaclePoints:
    """Scan points in {R}, checked once (``obstacle_points``): finite, every coordinate within
    ``MAX_ABS_COORD_M``, an (N, 2) C-contiguous array plus contiguous x and y columns.

    A scan arrives at sensor rate but is filtered against every command until the next one;
    checking and laying out the points once, when the scan arrives, keeps that work off the
    command path. So does ``index``, which a driver builds in its receiving thread.
    """

    xy: FloatArray
    x: FloatArray
    y: FloatArray
    r2: FloatArray  # squared distance of each point from the origin of {R}
    # How far ahead of and behind {R}'s origin the sensor sees along {R}'s x axis (its
    # range_max from where it sits, or less where the axis runs into a direction no beam looks
    # at: ``seen_along_axis_m``): what lies beyond was not seen, free or not. inf when unknown
    # (points only).
    seen_ahead_m: float = math.inf
    seen_behind_m: float = math.inf
    count: int = field(init=False)  # len(xy), without asking numpy on the command path
    _index: PointIndex | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "count", len(self.xy))

    def __len__(self) -> int:
        return self.count

    def index(self) -> PointIndex:
        """The points' ``PointIndex``, built once and cached."""
        index = self._index
        if index is None:
            index = PointIndex.build(self.x, self.y, self.r2)
            object.__setattr__(self, "_index", index)
        return index

    @property
    def prepared_index(self) -> PointIndex | None:
        """``index()`` if it was built already, else None (then numpy does the work)."""
        return self._index


@dataclass(frozen=True, slots=True, eq=False)
class PointIndex:
    """The points of an ``ObstaclePoints`` for plain-Python queries near a place (issue 9).

    A control cycle looks at the few points near a place instead of running numpy over the
    whole scan for every command. Built once per scan (a driver builds it in its receiving
    thread), from the very values of the arrays:

    - ``x``, ``y``: the coordinates, in the arrays' order;
    - bounding boxes of every ``BLOCK`` consecutive points (``block_*``: min x, max x, min y,
      max y) and of every ``GROUP`` consecutive blocks (``group_*``); a scan's consecutive
      points are mostly neighbours, so the boxes are small;
    - ``r2_sorted``: the squared distances from the origin of {R}, ascending.
    """

    BLOCK = 8
    GROUP = 8

    x: list[float]
    y: list[float]
    block_x0: list[float]
    block_x1: list[float]
    block_y0: list[float]
    block_y1: list[float]
    group_x0: list[float]
    group_x1: list[float]
    group_y0: list[float]
    group_y1: list[float]
    r2_sorted: list[float]

    @staticmethod
    def build(x: FloatArray, y: FloatArray, r2: FloatArray) -> PointIndex:
        if x.size == 0:
            return PointIndex([], [], [], [], [], [], [], [], [], [], [])
        starts = np.arange(0, x.size, PointIndex.BLOCK)
        x0, x1 = np.minimum.reduceat(x, starts), np.maximum.reduceat(x, starts)
        y0, y1 = np.minimum.reduceat(y, starts), np.maximum.reduceat(y, starts)
        groups = np.arange(0, starts.size, PointIndex.GROUP)
        return PointIndex(
            x.tolist(),
            y.tolist(),
            x0.tolist(),
            x1.tolist(),
            y0.tolist(),
            y1.tolist(),
            np.minimum.reduceat(x0, groups).tolist(),
            np.maximum.reduceat(x1, groups).tolist(),
            np.minimum.reduceat(y0, groups).tolist(),
            np.maximum.reduceat(y1, groups).tolist(),
            np.sort(r2).tolist(),
        )


def ranges_to_points(
    ranges_m: FloatArray,
    angles_rad: FloatArray,
    range_min_m: float,
    range_max_m: float,
    mount_x_m: float = 0.0,
    mount_y_m: float = 0.0,
) -> FloatArray:
    """Valid (finite, range_min <= r <= range_max) readings to (N, 2) points in {R}."""
    r = np.asarray(ranges_m, dtype=np.float64)
    a = np.asarray(angles_rad, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        keep = np.isfinite(r) & (r >= range_min_m) & (r <= range_max_m)
    r = r[keep]
    a = a[keep]
    out = np.empty((r.size, 2), dtype=np.float64)
    out[:, 0] = r * np.cos(a) + mount_x_m
    out[:, 1] = r * np.sin(a) + mount_y_m
    return out


def footprint_exit_m(
    angles_rad: FloatArray, mount_x_m: float, mount_y_m: float, half_l_m: float, half_w_m: float
) -> FloatArray:
    """How far each beam (angles in {R}) runs from the sensor before it leaves the footprint
    rectangle |x| <= half_l, |y| <= half_w; 0 for a sensor outside it."""
    a = np.asarray(angles_rad, dtype=np.float64)
    if abs(mount_x_m) > half_l_m or abs(mount_y_m) > half_w_m:
        return np.zeros_like(a)
    c, s = np.cos(a), np.sin(a)
    with np.errstate(divide="ignore", invalid="ignore"):
        tx = np.where(c != 0.0, (np.copysign(half_l_m, c) - mount_x_m) / c, np.inf)
        ty = np.where(s != 0.0, (np.copysign(half_w_m, s) - mount_y_m) / s, np.inf)
    out: FloatArray = np.minimum(tx, ty)
    return out


def carries_information(ranges_m: FloatArray, range_min_m: float, range_max_m: float) -> bool:
    """Whether a scan says anything (REP 117): a valid reading, or a +-inf beam (nothing within
    range_max, an object nearer than range_min). All NaN, all out of range, or no beams: no."""
    with np.errstate(invalid="ignore"):
        valid = (ranges_m >= range_min_m) & (ranges_m <= range_max_m)
    return bool((valid | (np.abs(ranges_m) == np.inf)).any())


def too_close_readings(
    ranges_m: FloatArray,
    angles_rad: FloatArray,
    range_min_m: float,
    mount_x_m: float,
    mount_y_m: float,
    footprint_half_m: Footprint | tuple[float, float] | None,
) -> tuple[FloatArray, FloatArray | None]:
    """REP 117's ``-inf`` readings (an object nearer than range_min), as every scan source of
    the robot reads them: the ranges with each ``-inf`` at range_min (DESIGN 11), and, given
    the footprint (the profile's shape, or a centred rectangle's half length and width), the
    points of ``too_close_points`` (else None).
    ``ranges_m`` (float64) is changed in place and returned; ``angles_rad`` are in {R}."""
    too_close = ranges_m == -np.inf
    if not too_close.any():
        return ranges_m, None
    ranges_m[too_close] = range_min_m
    if footprint_half_m is None:
        return ranges_m, None
    extra = too_close_points(
        angles_rad[too_close], range_min_m, mount_x_m, mount_y_m, footprint_half_m
    )
    return ranges_m, extra


_MAX_TOO_CLOSE_PLACES = 64  # per -inf beam (see too_close_points)


def too_close_points(
    angles_rad: FloatArray,
    range_min_m: float,
    mount_x_m: float,
    mount_y_m: float,
    footprint_half_m: Footprint | tuple[float, float],
    gap_m: float = 0.001,
    step_m: float = 0.02,
) -> FloatArray:
    """Where REP 117's ``-inf`` readings (an object closer than range_min, distance unknown)
    may touch the robot first: (K, 2) points in {R} just outside the footprint.

    The reading stays ``-inf`` while the robot closes in, so a point at range_min alone (DESIGN
    11) would let it drive on into the object, and so would any point that keeps its distance
    from the laser. The object lies somewhere on the beam between the laser (or, for a laser
    inside the footprint, where the beam leaves it) and range_min: each place on that stretch,
    sampled every ``step_m``, is taken to the nearest point of the footprint's edge and moved
    ``gap_m`` out of it. That stops motion towards every place the object may be, also for a
    laser mounted beyond the footprint's edge, whose beams never cross the footprint. Places
    inside the footprint (the laser seeing the robot itself) add nothing.

    The footprint is the profile's shape (DESIGN 14: a polygon of any shape or a disc; an
    obstacle in an L's notch is outside the robot) or, as before, a centred rectangle's half
    length and width (which a centred-rectangle ``Footprint`` also takes, so its points are
    unchanged).
    """
    a = np.asarray(angles_rad, dtype=np.float64)
    if isinstance(footprint_half_m, Footprint):
        box = footprint_half_m.centred_box
        if box is None:
            return _too_close_points_of_shape(
                a, range_min_m, mount_x_m, mount_y_m, footprint_half_m, gap_m, step_m
            )
        footprint_half_m = box
    half_l, half_w = footprint_half_m
    t0 = footprint_exit_m(a, mount_x_m, mount_y_m, half_l, half_w) + gap_m
    span = np.clip(range_min_m - t0, 0.0, None)
    n = int(np.ceil(span.max() / step_m)) + 1 if span.size else 0
    # Every step_m up to a lidar's usual range_min (~1 m); a range_min of kilometres (a broken
    # message) would ask for millions of places per beam, and gigabytes: spread them instead.
    n = min(n, _MAX_TOO_CLOSE_PLACES)
    if n == 0:
        return np.empty((0, 2), dtype=np.float64)
    frac = np.linspace(0.0, 1.0, n) if n > 1 else np.zeros(1)
    t = t0[:, None] + span[:, None] * frac[None, :]  # (K, n) along each beam
    ok = np.broadcast_to(span[:, None] > 0.0, t.shape)
    qx = (mount_x_m + t * np.cos(a)[:, None])[ok]
    qy = (mount_y_m + t * np.sin(a)[:, None])[ok]
    cx, cy = np.clip(qx, -half_l, half_l), np.clip(qy, -half_w, half_w)
    dx, dy = qx - cx, qy - cy
    d = np.hypot(dx, dy)
    outside = d > 0.0
    dx, dy, d, cx, cy = dx[outside], dy[outside], d[outside], cx[outside], cy[outside]
    out = np.empty((d.size, 2), dtype=np.float64)
    out[:, 0] = cx + gap_m * dx / d
    out[:, 1] = cy + gap_m * dy / d
    if out.shape[0] > 1:  # many places map onto the same bit of edge: one point per 5 mm
        _, first = np.unique(np.round(out / 0.005), axis=0, return_index=True)
        out = out[np.sort(first)]
    return out


def _too_close_points_of_shape(
    a: FloatArray,
    range_min_m: float,
    mount_x_m: float,
    mount_y_m: float,
    fp: Footprint,
    gap_m: float,
    step_m: float,
) -> FloatArray:
    """``too_close_points`` for a footprint that is not a centred rectangle: the same places
    along each beam, each taken to the nearest point of the real edge and ``gap_m`` out."""
    t0 = ray_exit_m(fp, mount_x_m, mount_y_m, a) + gap_m
    span = np.clip(range_min_m - t0, 0.0, None)
    n = int(np.ceil(span.max() / step_m)) + 1 if span.size else 0
    n = min(n, _MAX_TOO_CLOSE_PLACES)
    if n == 0:
        return np.empty((0, 2), dtype=np.float64)
    frac = np.linspace(0.0, 1.0, n) if n > 1 else np.zeros(1)
    t = t0[:, None] + span[:, None] * frac[None, :]
    ok = np.broadcast_to(span[:, None] > 0.0, t.shape)
    qx = (mount_x_m + t * np.cos(a)[:, None])[ok]
    qy = (mount_y_m + t * np.sin(a)[:, None])[ok]
    outside = signed_distance(fp, qx, qy) > 0.0
    qx, qy = qx[outside], qy[outside]
    cx, cy = closest_boundary_points(fp, qx, qy)
    dx, dy = qx - cx, qy - cy
    d = np.hypot(dx, dy)
    out = np.empty((d.size, 2), dtype=np.float64)
    out[:, 0] = cx + gap_m * dx / d
    out[:, 1] = cy + gap_m * dy / d
    if out.shape[0] > 1:  # one point per 5 mm of edge
        _, first = np.unique(np.round(out / 0.005), axis=0, return_index=True)
        out = out[np.sort(first)]
    return out


# A gap between neighbouring beams wider than this many median beam spacings is a blind
# sector: no beam looks there (a 270-degree laser behind itself, a 180-degree one's back half).
BLIND_GAP_SPACINGS = 3.0
_FULL_TURN = 2.0 * math.pi


def blind_sectors(angles_rad: npt.ArrayLike) -> tuple[tuple[float, float], ...]:
    """The directions no beam of a scan looks at: (start, width) in rad, start in [0, 2 pi),
    counter-clockwise, as seen from the laser (beam angles in {R}).

    Between two neighbouring beams whose directions are more than ``BLIND_GAP_SPACINGS``
    median spacings apart, what lies more than half a spacing from either beam is blind. Any
    beam order and sweep direction; a scan of fewer than two beams looks only along its beam.
    """
    a = np.asarray(angles_rad, dtype=np.float64).reshape(-1)
    if a.size >= 2:
        d = np.diff(a)
        lo, hi = float(d.min()), float(d.max())
        small, large = min(abs(lo), abs(hi)), max(abs(lo), abs(hi))
        # The usual scan: one sweep in one direction, evenly spaced, all the way round.
        one_sweep = (lo > 0.0 or hi < 0.0) and large <= BLIND_GAP_SPACINGS * small
        if one_sweep and abs(float(a[-1] - a[0])) + large >= _FULL_TURN:
            return ()
    if a.size < 2:
        half = math.radians(0.5)
        start = (float(a[0]) if a.size else 0.0) + half
        return ((start % _FULL_TURN, _FULL_TURN - 2.0 * half),)
    b = np.sort(np.mod(a, _FULL_TURN))
    gaps = np.diff(np.concatenate((b, [b[0] + _FULL_TURN])))
    spacing = float(np.median(gaps))
    wide = np.flatnonzero(gaps > BLIND_GAP_SPACINGS * spacing)
    return tuple(
        ((float(b[i]) + 0.5 * spacing) % _FULL_TURN, float(gaps[i]) - spacing) for i in wide
    )


def seen_along_axis_m(
    angles_rad: npt.ArrayLike,
    range_max_m: float,
    mount_x_m: float = 0.0,
    mount_y_m: float = 0.0,
    step_m: float = 0.01,
) -> tuple[float, float]:
    """How far ahead of and behind {R}'s origin a laser sees along {R}'s x axis (m).

    Its range_max from where it sits (``range_max +- mount_x``), but only up to the first
    place on the axis that lies in one of its ``blind_sectors`` as seen from the laser: what
    the laser does not look at is not known to be free. A 270-degree laser facing forward sees
    nothing straight behind (0 m behind), one mounted backwards nothing straight ahead. The
    axis is sampled every ``step_m`` (at most 2,000 samples a side) from the origin, or from
    the laser's own x where that lies farther out (the stretch between them is the robot's).
    """
    ahead_m, behind_m = range_max_m + mount_x_m, range_max_m - mount_x_m
    sectors = blind_sectors(angles_rad)
    if not sectors:
        return ahead_m, behind_m
    seen = []
    for sign, reach in ((1.0, ahead_m), (-1.0, behind_m)):
        x0 = max(0.0, sign * mount_x_m)
        if reach <= x0:
            seen.append(max(reach, 0.0))
            continue
        n = min(2000, max(1, math.ceil((reach - x0) / step_m)))
        x = np.linspace(x0, reach, n + 1)
        bearing = np.mod(np.arctan2(-mount_y_m, sign * x - mount_x_m), _FULL_TURN)
        blind = np.zeros(x.size, dtype=bool)
        for start, width in sectors:
            blind |= np.mod(bearing - start, _FULL_TURN) < width
        first = np.flatnonzero(blind)
        seen.append(reach if first.size == 0 else float(x[max(int(first[0]) - 1, 0)]))
    return seen[0], seen[1]


@functools.lru_cache(maxsize=32)
def seen_along_axis_cached(
    angles: bytes, range_max_m: float, mount_x_m: float, mount_y_m: float
) -> tuple[float, float]:
    """``seen_along_axis_m`` once per laser geometry (the beam angles' float64 bytes): a
    sensor's scans all share theirs, a live one's and a log's alike."""
    a = np.frombuffer(angles, dtype=np.float64)
    return seen_along_axis_m(a, range_max_m, mount_x_m, mount_y_m)


def seen_along_axis_of_scan(
    angles_rad: FloatArray,
    ranges_m: npt.ArrayLike,
    range_min_m: float,
    range_max_m: float,
    mount_x_m: float = 0.0,
    mount_y_m: float = 0.0,
) -> tuple[float, float]:
    """``seen_along_axis_m`` of the beams that told something in this scan.

    A beam that read NaN or below range_min (REP 117: an error, no information) did not see
    its direction: a run of them wider than ``BLIND_GAP_SPACINGS`` beam spacings is a blind
    sector like the one behind a 270-degree laser (an obstacle whose beams all fail, a black
    or glass wall, must not read as free space ahead). ``+inf``, ``-inf`` and readings past
    range_max did tell (no return, too close). A scan whose beams all told shares its
    laser's cached geometry.
    """
    angles = np.asarray(angles_rad, dtype=np.float64)
    r = np.asarray(ranges_m, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        failed = np.isnan(r) | (r < range_min_m) & np.isfinite(r)
    if failed.any():
        angles = angles[~failed]
    return seen_along_axis_cached(angles.tobytes(), range_max_m, mount_x_m, mount_y_m)


def obstacle_points(
    points: npt.ArrayLike | ObstaclePoints,
    *,
    seen_ahead_m: float = math.inf,
    seen_behind_m: float = math.inf,
) -> ObstaclePoints:
    """Check points once: drop rows that are not finite or beyond ``MAX_ABS_COORD_M``.

    Raises ValueError unless ``points`` is empty or an (N, 2) array; already prepared points are
    returned as they are. ``seen_ahead_m``/``seen_behind_m``: the sensor's reach (``Scan``).
    """
    if isinstance(points, ObstaclePoints):
        return points
    p = np.asarray(points, dtype=np.float64)
    if p.size == 0:
        p = np.empty((0, 2), dtype=np.float64)
    elif p.ndim != 2 or p.shape[1] != 2:
        raise ValueError("points must be an (N, 2) array of x, y in metres")
    elif not np.abs(p).max() <= MAX_ABS_COORD_M:  # NaN compares False
        with np.errstate(invalid="ignore"):
            p = p[np.all(np.abs(p) <= MAX_ABS_COORD_M, axis=1)]
    p = np.ascontiguousarray(p)
    x, y = p[:, 0].copy(), p[:, 1].copy()
    return ObstaclePoints(p, x, y, x * x + y * y, seen_ahead_m, seen_behind_m)
