"""Dynamic Window Approach, ``dwa`` (Fox, Burgard & Thrun 1997; DESIGN 6).

The baseline the EK-EGC paper compares against. ``dwa_filter`` is a pure function: the operator's
command (after eq. 4), scan points in {R}, the current velocity, the via point (or None), the
profile and ``DwaParams`` in; a frozen ``DwaResult`` out. One call:

1. **Dynamic window.** The velocities reachable within one period ``period_s`` from the current
   (v, w) under the profile's acceleration limits (speeding up at ``accel_max``, slowing down or
   reversing at ``decel_max``, the rule of ``safety.limit_acceleration``; ``angular_accel_max``
   for w), intersected with |v| <= v_max, |w| <= w_max, sampled on a ``v_samples`` x
   ``w_samples`` grid. The operator's command clipped into the window is a candidate too (first,
   so it wins ties), so a reachable command can pass exactly.
   Forward only, as in the paper, unless the operator commands reverse (v_ref < 0): then only
   v <= 0. When the window does not reach the allowed sign (moving forward fast while reverse is
   asked for) it keeps the hardest braking it reaches.
2. **Admissible velocities.** (v, w) is admissible when the robot can stop before the first
   contact of its footprint along the arc: the paper's
   v <= sqrt(2 dist a_dec), here with the stopping model of the pipeline's footprint sweep
   (``safety.stopping_time_s``): the command held for ``latency_s``, then v and w ramped down
   together (same curvature) at the profile's limits, so the stop covers |v| T of arc and |w| T
   of turn with T = latency + max(|v| / a_dec, |w| / alpha_max) / 2. With latency 0 and linear
   braking dominant this is exactly v^2 / (2 a_dec) <= dist. Reverse arcs are checked backwards
   (points mirrored x -> -x), turns in place by the angle before a corner touches.
   Contact is exact, not sampled: in the moving frame every point orbits the instantaneous
   centre of rotation, and the first contact angle is the first crossing of that circle with the
   footprint's boundary (vectorised over candidates x points): the profile's shape as given
   (DESIGN 14), in closed form on a centred rectangle's four edges (``contact_angles``), as two
   circles for a disc (``disc_contact_angles``), and as circle-segment crossings on every edge
   of any other polygon (``polygon_contact_angles``; reverse and right turns mirror the polygon
   with the points, as it need not be symmetric).
   Margin, the rule of the pipeline's sweep (DESIGN 5.10): "contact" is with the footprint grown
   by g = min(``margin_m``, the footprint's clearance now) (a disc by g; the centred rectangle
   by g on each side; another polygon by its mitred outline, whose sharp corners reach at most
   g beyond it, so its edges move out by g / ``mitre_factor``), so far from obstacles the margin
   is kept (along such a polygon's edges g / ``mitre_factor`` of it; the pipeline's sweep, which
   has the last word, keeps all of it), and closer than the margin motion may keep the clearance
   (drive along a wall, back away) but not lower it. A point inside the footprint (contact now) leaves nothing but
   stopping.
3. **Score** of each admissible candidate, every term normalised to [0, 1]:
   ``alpha * heading + beta * clearance + gamma * speed``.
   - heading, with a via point: 1 - |angle of the goal seen from the pose predicted after the
     same T| / pi (the paper's 180 deg - theta, at the position reached after the next interval
     and braking); without one: closeness to the operator's own command,
     1 - |((v - v_ref) / v_max, (w - w_ref) / w_max)| / (2 sqrt 2) (DESIGN 6: the closest
     admissible velocity).
   - clearance: free arc length before contact (turning in place: the corner's arc), capped at
     ``lookahead_m``, divided by it.
   - speed: |v| / v_max; without a via point, min(|v|, |v_ref|) / v_max (an assistant does not
     drive faster than the operator asked).
   The best admissible candidate is the output. If nothing but stopping is admissible, the
   output is a stop (0, 0) with ``stopped`` set; the pipeline ramps down to it.

Cases, each never less safe than stopping (as EGC's DESIGN 5.9 rules):

- ``INVALID_INPUT``: a non-finite or > 1e6 command, current velocity or goal -> stop.
- ``NO_POINTS_UNKNOWN``: no valid scan point and no-return not declared free -> stop
  (``egc.EgcCase.NO_POINTS_UNKNOWN``'s rule). ``NO_POINTS_FREE``: declared free -> every
  candidate is admissible with full clearance.
- A candidate whose arc deviates from a straight line by less than 0.5 um within the reach
  (radius >= 2 reach^2 / 1 um, thousands of km) is driven as straight, the footprint grown by
  that deviation; points closer than 1 um to the footprint count as touching it.

Cost: candidates x points in reach (within half-diagonal + margin + look-ahead of the origin);
``bench filter`` reports it next to EGC's.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace

import numpy as np
import numpy.typing as npt
from egc_common.footprint import Footprint, mitre_factor, mitred_outline, signed_distance
from egc_common.kinematics import ramp_toward
from egc_common.profiles import RobotProfile
from egc_common.scan import MAX_ABS_COORD_M, ObstaclePoints, obstacle_points

from egc_robot.safety import SweepParams

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

_TWO_PI = 2.0 * math.pi
_SAME = 1e-9
# Points within this distance of the footprint count as touching it (m); grown rectangles stay
# this far inside a point's present clearance, so no contact angle rounds across zero.
_TOUCH_M = 1e-6
_MAX_SAMPLES = 201
_BLOCK = 8192  # candidate x point pairs per vectorised block


class DwaCase(enum.Enum):
    """Which branch produced the result."""

    CHOSEN = "chosen"  # the best admissible candidate
    NO_ADMISSIBLE = "no_admissible"  # nothing but stopping is admissible -> stop
    NO_POINTS_UNKNOWN = "no_points_unknown"
    NO_POINTS_FREE = "no_points_free"
    INVALID_INPUT = "invalid_input"


@dataclass(frozen=True, slots=True)
class DwaParams:
    """DWA settings; every one has a default and a unit (DESIGN 3).

    ``DwaParams.from_profile`` sizes the look-ahead from the profile; ``from_mapping`` reads the
    robot TOML's table (keys = field names) on top of that.
    """

    period_s: float = 0.25  # s, the dynamic window: velocities reachable in one period
    v_samples: int = 9  # grid points across the window in v
    w_samples: int = 17  # grid points across the window in w
    alpha: float = 2.0  # weight of heading (1)
    beta: float = 0.2  # weight of clearance (1)
    gamma: float = 0.2  # weight of speed (1)
    lookahead_m: float = 1.0  # m, clearance counted up to this free arc length
    margin_m: float = SweepParams().margin_m  # m, kept from obstacles farther than this
    latency_s: float = SweepParams().period_s  # s, command held before braking (one cycle)
    no_return_is_free: bool = False  # the driver's declaration (DESIGN 5.9)

    def __post_init__(self) -> None:
        for name in ("period_s", "lookahead_m"):
            value = getattr(self, name)
            if not _is_number(value) or not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"dwa {name} must be a positive number, got {value!r}")
        for name in ("alpha", "beta", "gamma", "margin_m", "latency_s"):
            value = getattr(self, name)
            if not _is_number(value) or not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"dwa {name} must be a number >= 0, got {value!r}")
        if self.alpha + self.beta + self.gamma <= 0.0:
            raise ValueError("dwa needs at least one positive weight (alpha, beta, gamma)")
        for name in ("v_samples", "w_samples"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int):
                raise ValueError(f"dwa {name} must be an integer, got {value!r}")
            if not 2 <= value <= _MAX_SAMPLES:
                raise ValueError(f"dwa {name} must be within [2, {_MAX_SAMPLES}], got {value}")
        if not isinstance(self.no_return_is_free, bool):
            raise ValueError("dwa no_return_is_free must be true or false")

    @staticmethod
    def from_profile(profile: RobotProfile, **overrides: object) -> DwaParams:
        """Defaults for a profile: look-ahead = r_max, the radius EGC looks within (same radii)."""
        return replace(DwaParams(lookahead_m=profile.r_max_m), **overrides)  # type: ignore[arg-type]

    @staticmethod
    def keys() -> tuple[str, ...]:
        """The keys a ``[dwa]`` config table may hold."""
        return tuple(f.name for f in fields(DwaParams))

    @staticmethod
    def from_mapping(table: Mapping[str, object], profile: RobotProfile | None = None) -> DwaParams:
        """Parameters from a config table (e.g. the robot TOML's ``[dwa]``), over the defaults of
        ``profile`` (or the plain defaults). Unknown keys and bad values raise ValueError."""
        known = DwaParams.keys()
        unknown = sorted(set(table) - set(known))
        if unknown:
            raise ValueError(
                f"[dwa] has unknown keys: {', '.join(unknown)} (known: {', '.join(known)})"
            )
        values: dict[str, object] = {}
        for key, value in table.items():
            if key in ("v_samples", "w_samples"):
                if isinstance(value, float) and value.is_integer():
                    value = int(value)
            elif key == "no_return_is_free":
                pass
            elif isinstance(value, int) and not isinstance(value, bool):
                value = float(value)
            elif not isinstance(value, float):
                raise ValueError(f"dwa {key} must be a number, got {value!r}")
            values[key] = value
        base = DwaParams.from_profile(profile) if profile is not None else DwaParams()
        params: DwaParams = replace(base, **values)  # type: ignore[arg-type]
        # Below the sweep's own margin or latency DWA keeps choosing commands the sweep then
        # refuses, and the robot stalls (measured: 4 of 4 runs with margin_m 0 or 0.02).
        sweep = SweepParams()
        for name, least, unit in (
            ("margin_m", sweep.margin_m, "m"),
            ("latency_s", sweep.period_s, "s"),
        ):
            value = getattr(params, name)
            if value < least:
                raise ValueError(
                    f"dwa {name} must be at least the footprint sweep's {least} {unit}, got "
                    f"{value!r} (below it DWA picks commands the sweep refuses and the robot stalls)"
                )
        return params


@dataclass(frozen=True, slots=True)
class DwaResult:
    """The chosen command and why: window, admissible count and the winner's score terms."""

    v_mps: float
    w_radps: float
    modified: bool
    stopped: bool  # nothing but stopping was admissible (or a rule stopped)
    case: DwaCase
    admissible: int = 0  # admissible candidates (stop included when in the window)
    candidates: int = 0
    heading: float = 0.0  # the winner's normalised terms, each in [0, 1]
    clearance: float = 0.0
    speed: float = 0.0
    score: float = 0.0
    free_m: float = 0.0  # the winner's free arc length before contact, capped at look-ahead
    window: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)  # v_lo, v_hi, w_lo, w_hi
    goal_mode: bool = False


def dynamic_window(
    v_now_mps: float,
    w_now_radps: float,
    v_ref_mps: float,
    profile: RobotProfile,
    params: DwaParams,
) -> tuple[float, float, float, float]:
    """(v_lo, v_hi, w_lo, w_hi): reachable in one period, within the limits and allowed sign."""
    dt = params.period_s
    v_up, v_down = profile.accel_max_mps2 * dt, profile.decel_max_mps2 * dt
    dw = profile.angular_accel_max_radps2 * dt
    v_max, w_max = profile.v_max_mps, profile.w_max_radps
    v_lo = _clip(ramp_toward(-v_max, v_now_mps, v_up, v_down), -v_max, v_max)
    v_hi = _clip(ramp_toward(v_max, v_now_mps, v_up, v_down), -v_max, v_max)
    w_lo = _clip(w_now_radps - dw, -w_max, w_max)
    w_hi = _clip(w_now_radps + dw, -w_max, w_max)
    sign_lo, sign_hi = (-v_max, 0.0) if v_ref_mps < 0.0 else (0.0, v_max)
    if v_hi < sign_lo:  # cannot reach the allowed sign this period: brake as hard as possible
        v_lo = v_hi
    elif v_lo > sign_hi:
        v_hi = v_lo
    else:
        v_lo, v_hi = max(v_lo, sign_lo), min(v_hi, sign_hi)
    return v_lo, v_hi, w_lo, w_hi


def stopping_times(
    v_mps: FloatArray, w_radps: FloatArray, profile: RobotProfile, latency_s: float
) -> FloatArray:
    """``safety.stopping_time_s`` for arrays: latency + t_brake / 2 (equivalent full-command time)."""
    t_brake = np.maximum(
        np.abs(v_mps) / profile.decel_max_mps2, np.abs(w_radps) / profile.angular_accel_max_radps2
    )
    out: FloatArray = latency_s + 0.5 * t_brake
    return out


def contact_angles(
    radius_m: FloatArray,
    x_m: FloatArray,
    y_m: FloatArray,
    half_l: float | FloatArray,
    half_w: float | FloatArray,
) -> FloatArray:
    """First contact angle (rad, in (0, 2 pi], inf for none) of each candidate turning left.

    Canonical form: forward, left turn of radius R >= 0 (R = 0: in place), points (x, y) in {R}
    strictly outside the rectangle |x| <= half_l, |y| <= half_w (scalars or per point). Seen from the
    robot, a point orbits the centre (0, R) clockwise; the answer is the smallest clockwise
    angle to a crossing of that orbit with a rectangle edge. Shapes: radius (K, 1); the rest
    (1, N) or (K, N). Returns (K,).
    """
    r = radius_m
    dy0 = y_m - r
    phi0 = np.arctan2(dy0, x_m)
    best = np.full(np.broadcast_shapes(r.shape, x_m.shape), np.inf)

    def take(psi: FloatArray, ok: BoolArray) -> None:
        angle = np.mod(phi0 - psi, _TWO_PI)
        np.minimum(best, np.where(ok, angle, np.inf), out=best)

    # Only entering crossings can come first (the point starts outside). The orbit's velocity is
    # (y - R, -x): it enters the front edge below R, the back edge above R, the left side ahead
    # of the axle and the right side behind it; one crossing per edge.
    q2 = (x_m - half_l) * (x_m + half_l) + dy0 * dy0
    q = np.sqrt(np.maximum(q2, 0.0))
    beta = np.arctan2(q, half_l)
    take(-beta, (q2 >= 0.0) & (np.abs(r - q) <= half_w))  # front x = half_l, y = R - q
    take(math.pi - beta, (q2 >= 0.0) & (r + q <= half_w))  # back x = -half_l, y = R + q
    for left, h in ((True, half_w), (False, -half_w)):
        # Side y = h, at x = +p (left) or x = -p (right), p^2 = rho^2 - (h - R)^2.
        p2 = x_m * x_m + (y_m - h) * (y_m + h - 2.0 * r)
        p = np.sqrt(np.maximum(p2, 0.0))
        g = np.arctan2(h - r, p)
        take(g if left else math.pi - g, (p2 >= 0.0) & (p <= half_l))
    if best.size == 0:
        return np.full(len(r), np.inf)
    result: FloatArray = best.min(axis=1)
    return result


def disc_contact_angles(
    radius_m: FloatArray, x_m: FloatArray, y_m: FloatArray, disc_m: float
) -> FloatArray:
    """``contact_angles`` for a disc of radius ``disc_m`` about the origin (a round robot):
    the first clockwise crossing of each point's orbit (centre (0, R), R >= 0) with the circle.
    Turning in place (R = 0) the orbit is concentric with the disc: never a contact."""
    r = radius_m
    dy0 = y_m - r
    phi0 = np.arctan2(dy0, x_m)
    rho2 = x_m * x_m + dy0 * dy0
    # Crossings P: |P| = disc, |P - (0, R)| = rho, so P_y = (disc^2 - rho^2 + R^2) / (2 R).
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        py = (disc_m * disc_m - rho2 + r * r) / (2.0 * r)
        px2 = disc_m * disc_m - py * py
    ok = (r > 0.0) & (px2 >= 0.0)
    px = np.sqrt(np.maximum(px2, 0.0))
    best = np.full(np.broadcast_shapes(r.shape, x_m.shape), np.inf)
    for sign in (1.0, -1.0):
        psi = np.arctan2(py - r, sign * px)
        np.minimum(best, np.where(ok, np.mod(phi0 - psi, _TWO_PI), np.inf), out=best)
    if best.size == 0:
        return np.full(len(r), np.inf)
    result: FloatArray = best.min(axis=1)
    return result


def polygon_contact_angles(
    radius_m: FloatArray, x_m: FloatArray, y_m: FloatArray, outline: FloatArray
) -> FloatArray:
    """``contact_angles`` for any simple polygon ``outline`` ((E, 2) vertices, in the canonical
    frame): the first clockwise crossing of each point's orbit (centre (0, R), radius rho) with
    an edge. Starting outside, the first crossing of the boundary is the first contact, so the
    smallest crossing angle over all edges is exact. Shapes: radius (K, 1), points (1, N);
    returns (K,)."""
    r = radius_m[:, :, None]  # (K, 1, 1)
    x, y = x_m[:, :, None], y_m[:, :, None]  # (1, N, 1)
    dy0 = y - r
    phi0 = np.arctan2(dy0, x)
    rho2 = x * x + dy0 * dy0
    p0 = outline
    e = np.roll(outline, -1, axis=0) - outline
    ex, ey = e[:, 0], e[:, 1]  # (E,)
    fx, fy = p0[:, 0], p0[:, 1] - r  # (E,), (K, 1, E)
    a = ex * ex + ey * ey
    b = 2.0 * (fx * ex + fy * ey)
    c = fx * fx + fy * fy - rho2  # (K, N, E)
    disc = b * b - 4.0 * a * c
    root = np.sqrt(np.maximum(disc, 0.0))
    best = np.full(c.shape, np.inf)
    for sign in (1.0, -1.0):
        t = (-b + sign * root) / (2.0 * a)
        ok = (disc >= 0.0) & (t >= 0.0) & (t <= 1.0)
        psi = np.arctan2(p0[:, 1] + t * ey - r, p0[:, 0] + t * ex)
        np.minimum(best, np.where(ok, np.mod(phi0 - psi, _TWO_PI), np.inf), out=best)
    if best.size == 0:
        return np.full(len(radius_m), np.inf)
    result: FloatArray = best.min(axis=(1, 2))
    return result


def polygon_straight_free(x_m: FloatArray, y_m: FloatArray, outline: FloatArray) -> float:
    """Free distance driving straight ahead (+x) before the polygon ``outline`` touches any
    point (canonical frame; inf for none): for each point, the nearest edge crossing of the
    horizontal line through it at or behind it."""
    x0, y0 = outline[:, 0], outline[:, 1]
    x1, y1 = np.roll(x0, -1), np.roll(y0, -1)
    px, py = x_m[:, None], y_m[:, None]
    span = (np.minimum(y0, y1) <= py) & (py <= np.maximum(y0, y1)) & (y0 != y1)
    with np.errstate(divide="ignore", invalid="ignore"):
        cx = x0 + (py - y0) * (x1 - x0) / (y1 - y0)
    gap = np.where(span & (cx <= px), px - cx, np.inf)
    return float(gap.min()) if gap.size else math.inf


def _shape_free(
    fp: Footprint,
    grow_m: float,
    x: FloatArray,
    y: FloatArray,
    sx: FloatArray,
    sy: FloatArray,
    radius: FloatArray,
    straight: BoolArray,
    turning: BoolArray,
) -> tuple[FloatArray, FloatArray]:
    """(free distance of the straight candidates, contact angle of the turning ones) for a
    footprint that is not a centred rectangle: a disc (exact circles) or any polygon (its
    mitred outline grown so that it stays inside every point's clearance)."""
    dev = 0.5 * _TOUCH_M
    s_free = np.full(int(straight.sum()), np.inf)
    theta = np.full(int(turning.sum()), np.inf)
    if fp.is_disc:
        rd = fp.radius_m + grow_m
        if s_free.size:
            xs = sx[straight, None] * x[None, :]
            hits = (np.abs(y) <= rd + dev)[None, :] & (xs > 0.0)
            front = np.sqrt(np.maximum((rd + dev) ** 2 - y * y, 0.0))[None, :]
            s_free = np.maximum(np.where(hits, xs - front, np.inf).min(axis=1), 0.0)
        if theta.size:
            xt = sx[turning, None] * x[None, :]
            yt = sy[turning, None] * y[None, :]
            rows = max(1, _BLOCK // x.size)
            theta = np.concatenate(
                [
                    disc_contact_angles(
                        radius[i : i + rows], xt[i : i + rows], yt[i : i + rows], rd
                    )
                    for i in range(0, len(radius), rows)
                ]
            )
        return s_free, theta
    # The sharp corners reach mitre_factor * g beyond the footprint: g keeps them within the
    # clearance every point has now, and the straight test's deviation within that too.
    g = grow_m / mitre_factor(fp) - dev
    vertices = fp.vertices
    for mx in (1.0, -1.0):  # straight: mirror x for reverse (the polygon with the points)
        pick = straight & (sx == mx)
        if pick.any():
            outline = mitred_outline(fp, g + dev) * np.array([mx, 1.0])
            s_free[(sx[straight] == mx)] = max(polygon_straight_free(mx * x, y, outline), 0.0)
    if theta.size:
        idx = np.flatnonzero(turning)
        outline0 = mitred_outline(fp, g)
        rows = max(1, _BLOCK // (x.size * len(vertices)))
        for mx in (1.0, -1.0):
            for my in (1.0, -1.0):
                group = (sx[idx] == mx) & (sy[idx] == my)
                if not group.any():
                    continue
                outline = outline0 * np.array([mx, my])
                rg = radius[group]
                xt, yt = (mx * x)[None, :], (my * y)[None, :]
                theta[group] = np.concatenate(
                    [
                        polygon_contact_angles(rg[i : i + rows], xt, yt, outline)
                        for i in range(0, len(rg), rows)
                    ]
                )
    return s_free, theta


def dwa_filter(
    v_ref_mps: float,
    w_ref_radps: float,
    obstacles: npt.ArrayLike | ObstaclePoints,
    v_now_mps: float,
    w_now_radps: float,
    goal_xy_m: tuple[float, float] | None,
    profile: RobotProfile,
    params: DwaParams,
) -> DwaResult:
    """Choose the command for one cycle; see the module docstring."""
    numbers = [v_ref_mps, w_ref_radps, v_now_mps, w_now_radps]
    if goal_xy_m is not None:
        numbers.extend(goal_xy_m)
    if not all(abs(x) <= MAX_ABS_COORD_M for x in numbers):  # also NaN
        return _stop(DwaCase.INVALID_INPUT, v_ref_mps, w_ref_radps, goal_xy_m is not None)

    window = dynamic_window(v_now_mps, w_now_radps, v_ref_mps, profile, params)
    goal_mode = goal_xy_m is not None
    pts = obstacle_points(obstacles)
    if len(pts) == 0 and not params.no_return_is_free:
        return _stop(DwaCase.NO_POINTS_UNKNOWN, v_ref_mps, w_ref_radps, goal_mode, window)

    v, w = _candidates(v_ref_mps, w_ref_radps, window, params)
    t_stop = stopping_times(v, w, profile, params.latency_s)
    stop_len = np.abs(v) * t_stop
    lookahead = max(params.lookahead_m, float(stop_len.max()))
    free_m, admissible = _free_and_admissible(v, w, t_stop, pts, lookahead, profile, params)

    clearance = np.minimum(free_m, lookahead) / lookahead
    v_max, w_max = profile.v_max_mps, profile.w_max_radps
    if goal_xy_m is not None:
        heading = _goal_heading(v, w, t_stop, goal_xy_m)
        speed = np.abs(v) / v_max
    else:
        dv = (v - v_ref_mps) / v_max
        dw = (w - w_ref_radps) / w_max
        heading = np.maximum(0.0, 1.0 - np.sqrt(dv * dv + dw * dw) / (2.0 * math.sqrt(2.0)))
        speed = np.minimum(np.abs(v), abs(v_ref_mps)) / v_max
    score = params.alpha * heading + params.beta * clearance + params.gamma * speed

    count = int(admissible.sum())
    moving = admissible & ((v != 0.0) | (w != 0.0))
    if not moving.any():
        return DwaResult(
            0.0,
            0.0,
            _changed(0.0, 0.0, v_ref_mps, w_ref_radps),
            True,
            DwaCase.NO_ADMISSIBLE,
            count,
            len(v),
            window=window,
            goal_mode=goal_mode,
        )
    i = int(np.argmax(np.where(admissible, score, -np.inf)))
    v_out, w_out = float(v[i]), float(w[i])
    return DwaResult(
        v_out,
        w_out,
        _changed(v_out, w_out, v_ref_mps, w_ref_radps),
        False,
        DwaCase.NO_POINTS_FREE if len(pts) == 0 else DwaCase.CHOSEN,
        count,
        len(v),
        float(heading[i]),
        float(clearance[i]),
        float(speed[i]),
        float(score[i]),
        float(min(free_m[i], lookahead)),
        window,
        goal_mode,
    )


def _candidates(
    v_ref: float, w_ref: float, window: tuple[float, float, float, float], params: DwaParams
) -> tuple[FloatArray, FloatArray]:
    """The command clipped into the window first, then the grid."""
    v_lo, v_hi, w_lo, w_hi = window
    gv, gw = np.meshgrid(
        np.linspace(v_lo, v_hi, params.v_samples), np.linspace(w_lo, w_hi, params.w_samples)
    )
    v = np.concatenate(([_clip(v_ref, v_lo, v_hi)], gv.ravel()))
    w = np.concatenate(([_clip(w_ref, w_lo, w_hi)], gw.ravel()))
    return v, w


def _free_and_admissible(
    v: FloatArray,
    w: FloatArray,
    t_stop: FloatArray,
    pts: ObstaclePoints,
    lookahead: float,
    profile: RobotProfile,
    params: DwaParams,
) -> tuple[FloatArray, BoolArray]:
    """Free arc length before contact (inf: none within reach) and admissibility per candidate."""
    k = len(v)
    free = np.full(k, np.inf)
    standing = (v == 0.0) & (w == 0.0)
    admissible = standing.copy()
    fp = profile.footprint
    box = fp.centred_box
    reach = fp.reach_m + params.margin_m + lookahead
    near = pts.r2 <= reach * reach
    x, y = pts.x[near], pts.y[near]
    if x.size == 0:  # nothing within reach: every candidate is free up to the look-ahead
        admissible[:] = True
        return free, admissible
    now = signed_distance(fp, x, y)
    if bool((now <= 2.0 * _TOUCH_M).any()):  # in contact now: only stopping
        free[~standing] = 0.0
        return free, admissible
    grow = min(float(now.min()), params.margin_m) - _TOUCH_M

    # Canonical form: forward (mirror x for reverse), then left turns (mirror y for right).
    sx = np.where(v < 0.0, -1.0, 1.0)
    sy = np.where(sx * w < 0.0, -1.0, 1.0)
    speed, turn = np.abs(v), np.abs(w)
    # Curvature below TOUCH / reach^2 deviates from a straight line by at most TOUCH / 2 within
    # the reach: driven as straight, with the footprint grown by that deviation.
    dev = 0.5 * _TOUCH_M
    straight = ~standing & (turn * reach * reach <= _TOUCH_M * speed)
    turning = ~standing & ~straight
    radius = (speed[turning] / turn[turning])[:, None]  # turning: |w| > 0

    if box is None:  # a disc or any other polygon
        s_free, theta = _shape_free(fp, grow, x, y, sx, sy, radius, straight, turning)
        free[straight] = s_free
        admissible[straight] = speed[straight] * t_stop[straight] <= s_free
    else:  # the centred rectangle: closed forms on its four edges
        a, b = box[0] + grow, box[1] + grow
        if straight.any():
            xs = sx[straight, None] * x[None, :]
            hits = (np.abs(y) <= b + dev)[None, :] & (xs > 0.0)
            gap = np.where(hits, xs - (a + dev), np.inf)
            s_free = np.maximum(gap.min(axis=1), 0.0)
            free[straight] = s_free
            admissible[straight] = speed[straight] * t_stop[straight] <= s_free
        theta = np.full(len(radius), np.inf)
        if turning.any():
            xt = sx[turning, None] * x[None, :]
            yt = sy[turning, None] * y[None, :]
            rows = max(1, _BLOCK // x.size)  # blocks of candidates that stay in cache
            theta = np.concatenate(
                [
                    contact_angles(radius[i : i + rows], xt[i : i + rows], yt[i : i + rows], a, b)
                    for i in range(0, len(radius), rows)
                ]
            )
    if turning.any():
        arm = np.where(radius[:, 0] > 0.0, radius[:, 0], fp.reach_m)
        free[turning] = theta * arm
        admissible[turning] = turn[turning] * t_stop[turning] <= theta
    return free, admissible


def _goal_heading(
    v: FloatArray, w: FloatArray, t: FloatArray, goal_xy_m: tuple[float, float]
) -> FloatArray:
    """1 - |bearing of the goal from the pose after t on the arc| / pi (chord form of eq. 6)."""
    theta = w * t
    half = 0.5 * theta
    chord = v * t * np.sinc(half / math.pi)
    px, py = chord * np.cos(half), chord * np.sin(half)
    gx, gy = goal_xy_m
    if math.hypot(gx, gy) < _SAME:  # at the goal: no direction to prefer
        return np.ones_like(v)
    bearing = np.arctan2(gy - py, gx - px) - theta
    bearing = np.mod(bearing + math.pi, _TWO_PI) - math.pi
    out: FloatArray = 1.0 - np.abs(bearing) / math.pi
    return out


def _stop(
    case: DwaCase,
    v_ref: float,
    w_ref: float,
    goal_mode: bool,
    window: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0),
) -> DwaResult:
    modified = not (v_ref == 0.0 and w_ref == 0.0)
    return DwaResult(0.0, 0.0, modified, True, case, window=window, goal_mode=goal_mode)


def _changed(v: float, w: float, v_ref: float, w_ref: float) -> bool:
    return abs(v - v_ref) > _SAME or abs(w - w_ref) > _SAME


def _clip(x: float, lo: float, hi: float) -> float:
    return lo if x < lo else (hi if x > hi else x)


def _is_number(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)
