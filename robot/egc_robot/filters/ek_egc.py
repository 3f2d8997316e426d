"""EGC in the ego-kinematic space, ``ek-egc`` (DESIGN 6, pinned reconstruction).

The EK-EGC paper (``egc-ego-kinematic-ko.txt``, sec. 3) runs EGC on scan points mapped by the
ego-kinematic transform (EKT) of Minguez & Montano, so that a differential-drive robot's
admissible arcs become straight rays and EGC's circles respect the non-holonomic constraint.
Its formulas were lost in extraction; DESIGN 6 pins our reconstruction, which this module
follows step by step. With L = v_max / w_max of the profile (m):

1. EK transform of a point (x, y) in {R} (``ek_transform``): if y = 0, d = x and theta = 0 for
   x > 0, and the point is dropped (unreachable going forward) for x <= 0. Otherwise
   R = (x^2 + y^2) / (2y) (signed, > 0 on the left), g = atan2(x, |R| - |y|) wrapped to
   [0, 2 pi), d = |R| g, theta = sign(R) (pi/2 - atan(|R| / L)). The EK point is the embedding
   (d cos theta, d sin theta); distances are Euclidean distances of embeddings.
2. The command's EK point: P_IGC = (v kT cos theta_c, v kT sin theta_c), theta_c = atan(L w / v)
   for v > 0. For v < 0, mirror: points x -> -x, run with (-v, -w), negate (v', w').
3. DESIGN 5 steps 2-6 unchanged on EK points (``egc.guide_circles``, shared with ``egc``).
4. Back to a command (``ek_command_from_point``): d_E = |P_EGC|, theta_E = atan2(y_EGC, x_EGC);
   x_EGC > 0: v' = w_SI d_E / kT, w' = v' tan(theta_E) / L; x_EGC <= 0: v' = 0,
   w' = w_SI (2 / kT) (pi / 2) sign(y_EGC) (the rule of DESIGN 5.7).

The undefined cases of DESIGN 5.9 keep EGC's rules (``EgcCase``): INVALID_INPUT (NaN, infinite
or > 1e6 command) stops; no valid scan point at all is NO_POINTS_UNKNOWN (stop) unless the
driver declares no return as free (NO_POINTS_FREE); v = 0 is NO_TRANSLATION (P_IGC = origin,
rotation passes, translation 0) unless nothing lies within r_max of the origin in EK space
(CLEAR); NO_INTERSECTION scales (v, w) by w_SI; ZERO_WEIGHTS stops.

Choices this module makes where DESIGN 6 is silent, none less safe than EGC:

- Points the transform drops (y = 0, x <= 0) were still seen: if every valid point is dropped,
  nothing is reachable going forward and the command is CLEAR, as EGC answers for a scan with
  only a point straight behind. The empty-scan rule applies to the scan before the transform.
- |y| so small that R overflows is the limit y -> 0 (the y = 0 rule); a point whose arc length
  overflows (far behind, tiny |y|) is dropped as infinitely far.
- In reverse, every circle (p_igc, p_agc, p_egc) is reported in the mirrored EK space, the one
  the circles were computed in; only (v', w') is negated back.

Identity: a point on the command's own arc (radius v / w) maps onto the ray at theta_c, at the
arc length driven; with P_EGC = P_IGC and w_SI = 1 step 4 gives back (v, w), so a command
with nothing within r_max of P_IGC passes unchanged. |v'| <= w_SI |v| since |P_EGC| <= r_RC.
"""

from __future__ import annotations

import math
from decimal import Decimal

import numpy as np
import numpy.typing as npt
from egc_common.scan import ObstaclePoints, obstacle_points

from egc_robot.filters.egc import (
    MAX_ABS_INPUT,
    EgcCase,
    EgcParams,
    EgcResult,
    FloatArray,
    Point,
    Region,
    guide_circles,
    no_points,
)

_TWO_PI = 2.0 * math.pi
BoolArray = npt.NDArray[np.bool_]


def _check_l(l_m: float) -> None:
    if not (isinstance(l_m, (int, float)) and math.isfinite(l_m) and l_m > 0.0):
        raise ValueError("ek-egc needs L = v_max / w_max, a positive finite length in metres")


# Points with 0 < |y| < _Y_ZERO (m), or within sqrt(_R2_TINY) = 1e-145 m of the origin, would
# overflow or underflow the vectorised formulas (R, tan theta, the arc length); they are rare
# (real scans have y == 0 exactly, which is the y = 0 rule, vectorised) and go through
# ``_ek_point_careful``, the same formulas in decimal arithmetic.
_Y_ZERO = 1e-250
_R2_TINY = 1e-290
_TINY_RATIO = Decimal("1e-200")


def _ek_point_careful(x: float, y: float, l_m: float) -> tuple[float, float] | None:
    """Step 1 for one point with y != 0 at any magnitude, in decimal arithmetic where floats
    would overflow or underflow; None if the arc length is beyond the float range."""
    ax, ay = Decimal(x), Decimal(abs(y))
    r2 = ax * ax + ay * ay  # exact, in decimal
    if x > 0.0:
        ratio = ay / ax
        if ratio < _TINY_RATIO:  # atan(r) = r (1 - r^2 / 3): u / |y| = 1 / x to double precision
            d = r2 / ax
        else:
            d = r2 * Decimal(math.atan(float(ratio))) / ay
    else:  # u in [pi/2, pi]: a float atan2 is accurate
        d = r2 * Decimal(math.atan2(float(ay), x) if ay.adjusted() > -300 else math.pi) / ay
    t = float(Decimal(2.0 * l_m) * Decimal(y) / r2)  # tan theta = L / R; may be +-inf
    if math.isinf(t):
        c, s = 0.0, math.copysign(1.0, t)
    else:
        c = 1.0 / math.hypot(1.0, t)
        s = t * c
    ex, ey = float(d * Decimal(c)), float(d * Decimal(s))
    if not (math.isfinite(ex) and math.isfinite(ey)):
        return None
    return ex, ey


def _ek_xy(
    x: FloatArray, y: FloatArray, r2: FloatArray, l_m: float
) -> tuple[FloatArray, FloatArray, BoolArray | None]:
    """Step 1 on columns (r2 = x^2 + y^2): embeddings of the kept points, and the kept mask
    (None when every point is kept).

    Computed with two identities of the pinned formulas (the tests check them against the
    literal ones): the turned angle g = atan2(x, |R| - |y|) wrapped to [0, 2 pi) equals
    2 atan2(|y|, x) (the tangent-chord angle is half the arc's), so d = |R| g = r2 u / |y| with
    u = atan2(|y|, x); and theta = sign(R) (pi/2 - atan(|R| / L)) = atan(L / R), so with
    t = L / R = 2 L y / r2, cos theta = 1 / sqrt(1 + t^2) and sin theta = t cos theta.
    """
    ay = np.abs(y)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        ex = np.arctan2(ay, x)  # u = g / 2, in [0, pi]
        ex *= r2
        ex /= ay  # d = |R| g
        t = y * (2.0 * l_m)
        t /= r2  # tan theta = L / R
        c = t * t
        c += 1.0
        ex /= np.sqrt(c, out=c)  # d cos theta
        ey = ex * t  # d sin theta
    special = ay < _Y_ZERO
    special |= r2 < _R2_TINY
    if not special.any():
        return ex, ey, None
    kept = np.ones(x.shape, dtype=np.bool_)
    for i in np.flatnonzero(special).tolist():
        xi, yi = float(x[i]), float(y[i])
        if yi == 0.0:  # d = x, theta = 0 ahead; dropped at x <= 0 (unreachable going forward)
            p: tuple[float, float] | None = (xi, 0.0) if xi > 0.0 else None
        else:
            p = _ek_point_careful(xi, yi, l_m)
        if p is None:
            kept[i] = False
        else:
            ex[i], ey[i] = p
    if kept.all():
        return ex, ey, None
    return ex[kept], ey[kept], kept


def ek_transform(xy: npt.ArrayLike, l_m: float) -> tuple[FloatArray, BoolArray]:
    """DESIGN 6 step 1: (N, 2) points in {R} -> ((K, 2) EK embeddings, (N,) kept mask).

    The embeddings are (d cos theta, d sin theta) of the kept points, in their order; a point is
    dropped when y = 0 and x <= 0 (not reachable going forward) or when its arc length
    overflows. Rows must be finite (``obstacle_points`` drops the others before the filter).
    """
    _check_l(l_m)
    p = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    x = np.ascontiguousarray(p[:, 0])
    y = np.ascontiguousarray(p[:, 1])
    ex, ey, kept = _ek_xy(x, y, x * x + y * y, float(l_m))
    return np.column_stack((ex, ey)), np.ones(x.shape, np.bool_) if kept is None else kept


def ek_command_point(v_mps: float, w_radps: float, horizon_s: float, l_m: float) -> Point:
    """DESIGN 6 step 2 for v >= 0: P_IGC = v kT (cos theta_c, sin theta_c).

    theta_c = atan(L w / v), computed as atan2(L w, v) (equal for v > 0, no overflow for tiny
    v); v = 0 gives the origin (NO_TRANSLATION).
    """
    if v_mps == 0.0:
        return (0.0, 0.0)
    theta_c = math.atan2(l_m * w_radps, v_mps)
    d = v_mps * horizon_s
    return d * math.cos(theta_c), d * math.sin(theta_c)


def ek_command_from_point(
    p: Point, w_si: float, horizon_s: float, l_m: float
) -> tuple[float, float]:
    """DESIGN 6 step 4: the expanded centre in EK space back to (v', w')."""
    x, y = p
    if x > 0.0:
        v = w_si * math.hypot(x, y) / horizon_s
        return v, v * math.tan(math.atan2(y, x)) / l_m
    sign = 1.0 if y > 0.0 else (-1.0 if y < 0.0 else 0.0)
    return 0.0, w_si * (2.0 / horizon_s) * (math.pi / 2.0) * sign


def _negate(x: float) -> float:
    return 0.0 - x  # -x, but 0.0 stays 0.0 (no -0.0 on the wire)


def ek_egc_filter(
    v_mps: float,
    w_radps: float,
    points: npt.ArrayLike | ObstaclePoints,
    params: EgcParams,
    l_m: float,
) -> EgcResult:
    """Filter one command against scan points (N, 2) in {R} in the EK space (DESIGN 6).

    Returns EGC's ``EgcResult``, with p_igc/p_agc/p_egc and the radii in EK coordinates (the
    mirrored EK space when v < 0); see the module docstring for the steps and the rules.
    """
    _check_l(l_m)
    if not (abs(v_mps) <= MAX_ABS_INPUT and abs(w_radps) <= MAX_ABS_INPUT):  # also NaN
        return EgcResult(
            0.0, 0.0, 0.0, Region.UNSAFE, None, True, EgcCase.INVALID_INPUT, 0.0, (0.0, 0.0), 0.0
        )

    obstacles = obstacle_points(points)
    reverse = v_mps < 0.0
    v, w = (-v_mps, _negate(w_radps)) if reverse else (v_mps, w_radps)  # step 2: mirror
    kT = params.horizon_s
    p_igc = ek_command_point(v, w, kT, l_m)
    if obstacles.x.size == 0:
        res = no_points(v, w, p_igc, params)
    else:
        x, y, r2 = obstacles.x, obstacles.y, obstacles.r2
        # Only points within r_RC + r_max of the robot can matter: an arc is never shorter than
        # its chord, so a farther point is farther than that from the EK origin too, hence more
        # than r_max from every circle centre (all lie within r_RC of it) and beyond every
        # clamp. Skipping them changes no result but ``nearest_m`` when it is >= r_max.
        bound = v * kT + params.r_max_m
        near = r2 <= bound * bound * (1.0 + 1e-9)
        if not near.all():
            x, y, r2 = x[near], y[near], r2[near]
        ex, ey, _ = _ek_xy(-x if reverse else x, y, r2, l_m)
        if ex.size and ex.max() > bound:  # far along the EK space (d >= x_EK): same argument
            near = ex <= bound  # (and no overflow in the distances; |y_EK| <= 2 pi L always)
            ex, ey = ex[near], ey[near]

        def to_command(p: Point, w_si: float, horizon_s: float) -> tuple[float, float]:
            return ek_command_from_point(p, w_si, horizon_s, l_m)

        res = guide_circles(v, w, p_igc, ex, ey, params, to_command)
    if not reverse:
        return res
    return EgcResult(
        _negate(res.v_mps),
        _negate(res.w_radps),
        res.w_si,
        res.region,
        res.side,
        res.modified,
        res.case,
        res.r_rc_m,
        res.p_igc,
        res.r_igc_m,
        res.p_agc,
        res.r_agc_m,
        res.p_egc,
        res.r_egc_m,
        res.nearest_m,
    )
