"""Expanded Guide Circle filter (Park & Kim 2014, sec. 3, Table 1, eqs. 5-16; DESIGN 5).

``egc_filter`` is a pure function: command (v, w), scan points in {R}, and the radii and horizon,
in; a frozen ``EgcResult`` with every intermediate out. The steps, as pinned in DESIGN 5:

1. P_IGC from the command over the horizon kT (eq. 6); r_RC = |P_IGC| (eq. 7).
2. r_IGC = min(distance from P_IGC to the nearest point m*, r_max) (eqs. 8-9). At or beyond
   r_max the command passes unchanged (Table 1, lines 4-6).
3. Side: s = cross(P_IGC, m*); s < 0 (obstacle right of the reference line) -> expand left,
   s > 0 -> right, s == 0 -> left.
4. P_CL, P_CR: intersections of the reachable circle (origin, r_RC) and the initial GC;
   P_AGC is the one on the chosen side; r_AGC = min(nearest distance, r_max) (eqs. 10-11).
5. P_EGC = (r_IGC P_IGC + r_AGC P_AGC) / (r_IGC + r_AGC) (eq. 12, typo corrected);
   r_EGC = min(nearest distance, r_max) (eq. 13).
6. w_SI from r_EGC (eq. 16, the safety index circle of eq. 5).
7. v' = w_SI sign(x_EGC) |P_EGC| / kT, w' = w_SI (2 / kT) atan(y_EGC / x_EGC) (eqs. 14-15).

Cases the paper leaves undefined (DESIGN 5.9), each never less safe than stopping:

- ``INVALID_INPUT``: v or w is NaN, infinite or beyond 1e6 in magnitude -> stop (0, 0), w_SI 0.
  Scan points that are not finite or beyond 1e6 m are dropped like invalid readings.
- ``NO_POINTS_UNKNOWN``: no valid point at all and the sensor did not declare "no return means
  free" -> nothing was seen, so nothing is known to be free: stop, w_SI 0, region unsafe.
- ``NO_POINTS_FREE``: no valid point and the driver declares no-return as free -> pass, w_SI 1.
- ``NO_TRANSLATION``: r_RC = 0 (zero command or turning in place). There is no reference line
  and no reachable circle; the end point is the robot itself. Translation stays 0 and the
  rotation passes unscaled (scaling it by w_SI would dead-lock a robot next to a wall); the
  command pipeline's footprint check (DESIGN 5.10) decides whether the turn is clear. w_SI is
  reported from r_IGC for the view.
- ``NO_INTERSECTION``: r_IGC > 2 r_RC, the two circles do not meet (a short motion next to a
  close obstacle). No expansion: P_EGC = P_IGC, r_EGC = r_IGC, and eq. 16 scales the command.
- ``ZERO_WEIGHTS``: r_IGC + r_AGC = 0 (a point exactly on both centres) -> stop, w_SI 0.

Eqs. 14-15 invert eq. 6 exactly when P_EGC = P_IGC for |w kT / 2| < pi / 2, which holds for any
command within the profile limits at the default horizon of both pinned profiles.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from egc_common.scan import MAX_ABS_COORD_M, ObstaclePoints, PointIndex, obstacle_points

FloatArray = npt.NDArray[np.float64]
Point = tuple[float, float]

# Commands beyond this magnitude (m/s, rad/s) are treated as invalid: no real robot produces
# them, and squaring them would overflow. Scan points get the same bound (``obstacle_points``).
MAX_ABS_INPUT = MAX_ABS_COORD_M


class Region(enum.Enum):
    """Regions of the safety index circle (eq. 5)."""

    SAFE = "safe"
    CONDITIONAL = "conditional"
    UNSAFE = "unsafe"


class Side(enum.Enum):
    LEFT = "left"
    RIGHT = "right"


class EgcCase(enum.Enum):
    """Which branch of the algorithm produced the result."""

    CLEAR = "clear"  # Table 1, lines 4-6
    EXPANDED = "expanded"  # Table 1, lines 7-21
    NO_TRANSLATION = "no_translation"
    NO_INTERSECTION = "no_intersection"
    ZERO_WEIGHTS = "zero_weights"
    NO_POINTS_UNKNOWN = "no_points_unknown"
    NO_POINTS_FREE = "no_points_free"
    INVALID_INPUT = "invalid_input"


@dataclass(frozen=True, slots=True)
class EgcParams:
    """Radii of the safety index circle and the prediction horizon kT (DESIGN 5.8)."""

    r_min_m: float
    r_max_m: float
    horizon_s: float
    no_return_is_free: bool = False

    def __post_init__(self) -> None:
        values = (self.r_min_m, self.r_max_m, self.horizon_s)
        if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in values):
            raise ValueError("EGC radii and horizon must be finite numbers")
        if not 0.0 <= self.r_min_m < self.r_max_m:
            raise ValueError("EGC needs 0 <= r_min < r_max")
        if self.horizon_s <= 0.0:
            raise ValueError("EGC horizon kT must be positive")

    @staticmethod
    def from_profile(
        r_min_m: float, r_max_m: float, v_max_mps: float, horizon_s: float | None = None
    ) -> EgcParams:
        """Default horizon kT = r_max / v_max: full speed reaches the SIC's outer circle."""
        return EgcParams(r_min_m, r_max_m, r_max_m / v_max_mps if horizon_s is None else horizon_s)


@dataclass(frozen=True, slots=True)
class EgcResult:
    """The filtered command (paper equations only, before DESIGN 5.10) and all intermediates."""

    v_mps: float
    w_radps: float
    w_si: float
    region: Region
    side: Side | None
    modified: bool
    case: EgcCase
    r_rc_m: float
    p_igc: Point
    r_igc_m: float
    p_agc: Point | None = None
    r_agc_m: float | None = None
    p_egc: Point | None = None
    r_egc_m: float | None = None
    nearest_m: float = math.inf

    @property
    def igc(self) -> tuple[float, float, float]:
        return (self.p_igc[0], self.p_igc[1], self.r_igc_m)

    @property
    def agc(self) -> tuple[float, float, float] | None:
        if self.p_agc is None or self.r_agc_m is None:
            return None
        return (self.p_agc[0], self.p_agc[1], self.r_agc_m)

    @property
    def egc(self) -> tuple[float, float, float] | None:
        if self.p_egc is None or self.r_egc_m is None:
            return None
        return (self.p_egc[0], self.p_egc[1], self.r_egc_m)


def predicted_position(v_mps: float, w_radps: float, horizon_s: float) -> Point:
    """Eq. 6: the end point of the arc driven by (v, w) for kT, the centre of the initial GC."""
    d = v_mps * horizon_s
    half = 0.5 * w_radps * horizon_s
    return d * math.cos(half), d * math.sin(half)


def safety_index(r_c_m: float, r_min_m: float, r_max_m: float) -> float:
    """Eq. 5 / eq. 16: 1 above r_max, r_c / r_max in (r_min, r_max], 0 at or below r_min."""
    if r_c_m > r_max_m:
        return 1.0
    if r_c_m > r_min_m:
        return r_c_m / r_max_m
    return 0.0


def region_of(r_c_m: float, r_min_m: float, r_max_m: float) -> Region:
    """Eq. 5: safe above r_max, conditionally safe in (r_min, r_max], unsafe at or below r_min."""
    if r_c_m > r_max_m:
        return Region.SAFE
    if r_c_m > r_min_m:
        return Region.CONDITIONAL
    return Region.UNSAFE


def command_from_point(p: Point, w_si: float, horizon_s: float) -> tuple[float, float]:
    """Eqs. 14-15, with x = 0 handled as the limit of atan: w' = w_SI (2/kT)(pi/2) sign(y)."""
    x, y = p
    if x == 0.0:
        return 0.0, w_si * (2.0 / horizon_s) * (math.pi / 2.0) * _sign(y)
    v = w_si * _sign(x) * math.hypot(x, y) / horizon_s
    w = w_si * (2.0 / horizon_s) * math.atan(y / x)
    return v, w


def circle_intersections(p_igc: Point, r_rc_m: float, r_igc_m: float) -> tuple[Point, Point] | None:
    """DESIGN 5.4: (P_CL, P_CR) where the reachable circle meets the initial GC, else None."""
    if r_rc_m <= 0.0 or r_igc_m > 2.0 * r_rc_m:
        return None
    ux, uy = p_igc[0] / r_rc_m, p_igc[1] / r_rc_m
    nx, ny = -uy, ux
    ell = r_rc_m - r_igc_m * r_igc_m / (2.0 * r_rc_m)
    h = math.sqrt(max(r_rc_m * r_rc_m - ell * ell, 0.0))
    left = (ell * ux + h * nx, ell * uy + h * ny)
    right = (ell * ux - h * nx, ell * uy - h * ny)
    return left, right


def _sign(x: float) -> float:
    return 1.0 if x > 0.0 else (-1.0 if x < 0.0 else 0.0)


def _nearest(px: FloatArray, py: FloatArray, c: Point) -> tuple[float, int]:
    """Eqs. 8 / 10: distance to and index of the scan point nearest to ``c``."""
    dx = px - c[0]
    dy = py - c[1]
    d2 = dx * dx
    d2 += dy * dy
    i = int(np.argmin(d2))
    return math.sqrt(float(d2[i])), i


# ``_nearest_indexed`` computes no more than this many distances, then leaves it to numpy.
MAX_INDEXED_VISITS = 96
_BEYOND: tuple[float, int] = (math.inf, -1)  # nothing closer than the limit


def _nearest_indexed(index: PointIndex, c: Point, limit: float) -> tuple[float, int] | None:
    """``_nearest`` from the scan's ``PointIndex``, for a nearest point closer than ``limit``.

    Returns the same (distance, position) as ``_nearest`` when the nearest point is closer than
    ``limit``, ``_BEYOND`` when no point is, and None when more than ``MAX_INDEXED_VISITS``
    distances would be needed (the caller then asks ``_nearest``).

    Only blocks whose bounding box is within ``limit`` of ``c`` are looked at, nearest box
    first, and none farther than the best point so far. A box's squared distance is computed
    with the same floating-point steps as a point's, from coordinate differences that are each
    at most as large, so it is never more than any of its points': a point left out is
    strictly farther than the best. Ties go to the first position, as ``argmin``'s do.
    """
    cx, cy = c
    bx0, bx1, by0, by1 = index.block_x0, index.block_x1, index.block_y0, index.block_y1
    gx0, gx1, gy0, gy1 = index.group_x0, index.group_x1, index.group_y0, index.group_y1
    n_blocks, per_group = len(bx0), index.GROUP
    reach = limit * (1.0 + 1e-9)
    bound = reach * reach  # boxes farther than this (squared) hold nothing of interest
    near: list[tuple[float, int]] = []  # (squared box distance, block)
    for g in range(len(gx0)):
        dx = gx0[g] - cx
        if dx < 0.0:
            dx = cx - gx1[g]
            if dx < 0.0:
                dx = 0.0
        dy = gy0[g] - cy
        if dy < 0.0:
            dy = cy - gy1[g]
            if dy < 0.0:
                dy = 0.0
        if dx * dx + dy * dy > bound:
            continue
        first_block = g * per_group
        for b in range(first_block, min(first_block + per_group, n_blocks)):
            dx = bx0[b] - cx
            if dx < 0.0:
                dx = cx - bx1[b]
                if dx < 0.0:
                    dx = 0.0
            dy = by0[b] - cy
            if dy < 0.0:
                dy = cy - by1[b]
                if dy < 0.0:
                    dy = 0.0
            box2 = dx * dx + dy * dy
            if box2 <= bound:
                near.append((box2, b))
    best = math.inf
    best_at = -1
    if near:
        near.sort()
        xs, ys = index.x, index.y
        n, per_block = len(xs), index.BLOCK
        visits = MAX_INDEXED_VISITS
        for box2, b in near:
            if box2 > bound:
                break  # this box and every later one are farther than the best point
            first = b * per_block
            last = min(first + per_block, n)
            visits -= last - first
            if visits < 0:
                return None
            for j in range(first, last):
                dx = xs[j] - cx
                dy = ys[j] - cy
                d2 = dx * dx + dy * dy
                if d2 < best or (d2 == best and j < best_at):
                    best, best_at = d2, j
                    if d2 < bound:
                        bound = d2
    d = math.sqrt(best)
    return (d, best_at) if d < limit else _BEYOND


def _nearest_to(
    px: FloatArray,
    py: FloatArray,
    index: PointIndex | None,
    c: Point,
    limit: float,
    exact: bool = False,
) -> tuple[float, int]:
    """``_nearest``, from the scan's index when it has one and the nearest point is closer than
    ``limit``. Else ``_BEYOND`` where the result is only clamped to ``limit`` (eqs. 11, 13),
    ``_nearest`` itself with ``exact`` (eq. 8: the result reports the distance)."""
    if index is not None:
        found = _nearest_indexed(index, c, limit)
        if found is not None and not (exact and found is _BEYOND):
            return found
    return _nearest(px, py, c)


def _clamp(d: float, r_max_m: float) -> float:
    """Eqs. 9, 11, 13: the circle grows to the nearest point, but not beyond r_max."""
    return d if d < r_max_m else r_max_m


def _stop(case: EgcCase, r_rc: float, p_igc: Point, r_igc: float, region: Region) -> EgcResult:
    return EgcResult(0.0, 0.0, 0.0, region, None, True, case, r_rc, p_igc, r_igc)


def egc_filter(
    v_mps: float, w_radps: float, points: npt.ArrayLike | ObstaclePoints, params: EgcParams
) -> EgcResult:
    """Filter one command against scan points (N, 2) in {R}; see the module docstring."""
    if not (abs(v_mps) <= MAX_ABS_INPUT and abs(w_radps) <= MAX_ABS_INPUT):  # also NaN
        return _stop(EgcCase.INVALID_INPUT, 0.0, (0.0, 0.0), 0.0, Region.UNSAFE)

    obstacles = obstacle_points(points)
    p_igc = predicted_position(v_mps, w_radps, params.horizon_s)  # eq. 6
    if obstacles.count == 0:
        return no_points(v_mps, w_radps, p_igc, params)
    return guide_circles(
        v_mps,
        w_radps,
        p_igc,
        obstacles.x,
        obstacles.y,
        params,
        command_from_point,
        obstacles.prepared_index,
    )


def no_points(v_mps: float, w_radps: float, p_igc: Point, params: EgcParams) -> EgcResult:
    """DESIGN 5.9: no valid point at all; a stop unless the driver declares no return as free."""
    r_rc = math.hypot(*p_igc)
    if params.no_return_is_free:
        return EgcResult(
            v_mps,
            w_radps,
            1.0,
            Region.SAFE,
            None,
            False,
            EgcCase.NO_POINTS_FREE,
            r_rc,
            p_igc,
            params.r_max_m,
        )
    return _stop(EgcCase.NO_POINTS_UNKNOWN, r_rc, p_igc, 0.0, Region.UNSAFE)


def guide_circles(
    v_mps: float,
    w_radps: float,
    p_igc: Point,
    px: FloatArray,
    py: FloatArray,
    params: EgcParams,
    to_command: Callable[[Point, float, float], tuple[float, float]],
    index: PointIndex | None = None,
) -> EgcResult:
    """DESIGN 5.2-5.6 and the rules of 5.9 on given points and a given P_IGC.

    Shared by ``egc`` (points and P_IGC in {R}) and ``ek-egc`` (both in the ego-kinematic
    space). ``to_command(P_EGC, w_SI, kT)`` turns the expanded centre back into (v', w') (eqs.
    14-15 for EGC, DESIGN 6 step 4 for EK-EGC); every other branch is the same rule for both:
    CLEAR passes (v, w), NO_TRANSLATION keeps (0, w), NO_INTERSECTION scales (v, w) by w_SI,
    ZERO_WEIGHTS stops. No point at all (possible after the EK transform drops points) is
    nothing within r_max: CLEAR. Callers decide the empty-scan rule (``no_points``) before.
    ``index``, the points' ``PointIndex`` when it was built, answers the nearest-point
    queries near the robot without numpy (same results).
    """
    r_min, r_max = params.r_min_m, params.r_max_m
    r_rc = math.hypot(*p_igc)  # eq. 7

    some = index.x if index is not None else px.size  # any point at all (the index: no numpy)
    d_igc, i_igc = (  # eq. 8
        _nearest_to(px, py, index, p_igc, r_max, exact=True) if some else (math.inf, -1)
    )
    r_igc = _clamp(d_igc, r_max)  # eq. 9
    if d_igc >= r_max:  # Table 1, lines 4-6
        return EgcResult(
            v_mps,
            w_radps,
            1.0,
            Region.SAFE,
            None,
            False,
            EgcCase.CLEAR,
            r_rc,
            p_igc,
            r_igc,
            nearest_m=d_igc,
        )

    if r_rc == 0.0:  # DESIGN 5.9: turning in place or standing still
        w_si = safety_index(r_igc, r_min, r_max)
        return EgcResult(
            0.0,
            w_radps,
            w_si,
            region_of(r_igc, r_min, r_max),
            None,
            v_mps != 0.0,
            EgcCase.NO_TRANSLATION,
            r_rc,
            p_igc,
            r_igc,
            nearest_m=d_igc,
        )

    mx, my = float(px[i_igc]), float(py[i_igc])
    s = p_igc[0] * my - p_igc[1] * mx  # cross(P_IGC, m*)
    side = Side.RIGHT if s > 0.0 else Side.LEFT

    meets = circle_intersections(p_igc, r_rc, r_igc)
    if meets is None:  # DESIGN 5.9: the circles do not intersect; regulate without expanding
        w_si = safety_index(r_igc, r_min, r_max)
        v_out, w_out = w_si * v_mps, w_si * w_radps
        return EgcResult(
            v_out,
            w_out,
            w_si,
            region_of(r_igc, r_min, r_max),
            side,
            True,
            EgcCase.NO_INTERSECTION,
            r_rc,
            p_igc,
            r_igc,
            p_egc=p_igc,
            r_egc_m=r_igc,
            nearest_m=d_igc,
        )

    p_agc = meets[0] if side is Side.LEFT else meets[1]
    r_agc = _clamp(_nearest_to(px, py, index, p_agc, r_max)[0], r_max)  # eqs. 10-11

    weight = r_igc + r_agc
    if weight <= 0.0:  # DESIGN 5.9: both circles collapsed onto a point
        return EgcResult(
            0.0,
            0.0,
            0.0,
            Region.UNSAFE,
            side,
            True,
            EgcCase.ZERO_WEIGHTS,
            r_rc,
            p_igc,
            r_igc,
            p_agc,
            r_agc,
            p_igc,
            0.0,
            d_igc,
        )

    p_egc = (  # eq. 12 (typo corrected, DESIGN 5.5)
        (r_igc * p_igc[0] + r_agc * p_agc[0]) / weight,
        (r_igc * p_igc[1] + r_agc * p_agc[1]) / weight,
    )
    r_egc = _clamp(_nearest_to(px, py, index, p_egc, r_max)[0], r_max)  # eq. 13
    w_si = safety_index(r_egc, r_min, r_max)  # eq. 16
    v_out, w_out = to_command(p_egc, w_si, params.horizon_s)  # eqs. 14-15 / DESIGN 6.4
    return EgcResult(
        v_out,
        w_out,
        w_si,
        region_of(r_egc, r_min, r_max),
        side,
        True,
        EgcCase.EXPANDED,
        r_rc,
        p_igc,
        r_igc,
        p_agc,
        r_agc,
        p_egc,
        r_egc,
        d_igc,
    )
