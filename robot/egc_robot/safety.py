"""Beyond-the-paper safety rules (DESIGN 5.10): footprint sweep, clearance, limits.

The paper's circles judge only the end point of the predicted arc. ``sweep_scale`` checks the
whole footprint (the profile's shape as given, polygon or disc: ``egc_common.footprint``,
DESIGN 14) along the commanded arc over one control period plus the stopping
distance at the profile's deceleration, and scales the command down (same curvature) until the
sweep is clear. "Clear" means the footprint's signed clearance to every point never drops below
``min(margin, clearance now)``: far from obstacles the margin is kept; already closer than the
margin, motion may only keep or increase the clearance. This is what lets a robot next to a
wall turn in place or back away (no dead-lock) while never driving into it.

The sweep assumes the base is at the scaled command within one period. A base brakes no harder
than its deceleration limit, though: when the scaled command asks for more braking than that,
the base would still be faster than the sweep assumed (a robot at 1.7 m/s meeting a new
obstacle on a new arc). ``brake_along`` is the pipeline's answer then: brake as hard as the base
can, on the arc of the previous command, whose stop the previous cycle's sweep checked.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from egc_common.footprint import signed_distance, swept_min_distance
from egc_common.kinematics import arc_displacement, ramp_toward
from egc_common.profiles import RobotProfile
from egc_common.scan import ObstaclePoints, obstacle_points

FloatArray = npt.NDArray[np.float64]

_EPS = 1e-9


# The longest control period the sweep's model holds for (s). It takes the base to be at each
# command from the start of the period, while a base brakes to it at its limits: up to
# a_dec T^2 / 2 further (3.8 mm at 20 Hz, 1.5 cm at 10 Hz for a Jackal), within the 3 cm
# margin. At 5 Hz (6 cm) a Jackal under DWA hit walls in 14 of 20 random worlds.
MAX_CONTROL_PERIOD_S = 0.1


@dataclass(frozen=True, slots=True)
class SweepParams:
    """Footprint check settings: safety margin, cycle latency and sampling resolution."""

    margin_m: float = 0.03
    period_s: float = 0.05
    step_m: float = 0.02
    step_rad: float = 0.05
    iterations: int = 10


def _min_clearance(x_m: FloatArray, y_m: FloatArray, profile: RobotProfile) -> float:
    """Smallest signed clearance of points given in the footprint's frame."""
    return float(signed_distance(profile.footprint, x_m, y_m).min())


def footprint_clearance(points: FloatArray, profile: RobotProfile) -> float:
    """Smallest signed clearance (m) of the footprint at the origin; inf with no points."""
    if len(points) == 0:
        return math.inf
    return _min_clearance(points[:, 0], points[:, 1], profile)


def stopping_time_s(
    v_mps: float, w_radps: float, profile: RobotProfile, params: SweepParams
) -> float:
    """One control period at the command, then a linear ramp down at the profile's limits.

    Returned as the equivalent time at full command: period + t_brake / 2.
    """
    t_brake = max(
        abs(v_mps) / profile.decel_max_mps2, abs(w_radps) / profile.angular_accel_max_radps2
    )
    return params.period_s + 0.5 * t_brake


def sweep_min_clearance(
    v_mps: float,
    w_radps: float,
    t_s: float,
    points: FloatArray,
    profile: RobotProfile,
    params: SweepParams,
) -> float:
    """Smallest signed footprint clearance over the poses swept in (0, t_s]
    (``egc_common.footprint.swept_min_distance``: between samples no point of the footprint
    moves more than 2 ``step_m``, so at most ``step_m`` closer than sampled, within the margin)."""
    return swept_min_distance(
        profile.footprint, points, v_mps, w_radps, t_s, params.step_m, params.step_rad
    )


def horizon_scale(
    v_mps: float,
    w_radps: float,
    obstacles: ObstaclePoints,
    profile: RobotProfile,
    params: SweepParams,
) -> float:
    """Largest s in [0, 1] such that the command (s v, s w) stops within what the sensor sees.

    REP 117 counts a beam with no return as free, but only up to range_max: beyond it nothing
    was seen. The sweep finds no point there, so on a short-range sensor (range_max 0.6 m) a
    Jackal drove at 2 m/s until a wall came into view 0.35 m from its bumper, where it needs
    0.67 m to stop. Here the stopping distance in the direction of travel (one period at the
    command, then the profile's deceleration: |v| T + v^2 / (2 a)) must fit between the
    footprint's edge (its farthest point ahead, or behind when reversing, plus the margin) and
    the sensor's reach.
    """
    if v_mps == 0.0:
        return 1.0
    x_min, x_max, _, _ = profile.footprint.bounds
    if v_mps > 0.0:
        reach, edge = obstacles.seen_ahead_m, max(x_max, 0.0)
    else:
        reach, edge = obstacles.seen_behind_m, max(-x_min, 0.0)
    room = reach - edge - params.margin_m
    speed, a, period = abs(v_mps), profile.decel_max_mps2, params.period_s
    if speed * period + speed * speed / (2.0 * a) <= room:
        return 1.0
    if room <= 0.0:
        return 0.0
    v_cap = a * (math.sqrt(period * period + 2.0 * room / a) - period)
    return min(1.0, v_cap / speed)


def sweep_scale(
    v_mps: float,
    w_radps: float,
    points: FloatArray | ObstaclePoints,
    profile: RobotProfile,
    params: SweepParams,
) -> float:
    """Largest s in [0, 1] such that the command (s v, s w) sweeps the footprint clear."""
    if len(points) == 0 or (v_mps == 0.0 and w_radps == 0.0):
        return 1.0
    obstacles = obstacle_points(points)
    # Only points the footprint can reach within the full command's stopping sweep matter.
    t_full = stopping_time_s(v_mps, w_radps, profile, params)
    reach = profile.half_diagonal_m + abs(v_mps) * t_full + params.margin_m
    index = obstacles.prepared_index
    if index is not None and index.r2_sorted[0] > reach * reach:
        return 1.0  # nothing within reach (the scan's nearest point says so, without numpy)
    near = obstacles.xy[obstacles.r2 <= reach * reach]
    if len(near) == 0:
        return 1.0
    # A point beyond ``reach`` is more than the margin clear now, so it cannot lower
    # min(margin, clearance now): the near points alone give the same requirement.
    required = min(params.margin_m, footprint_clearance(near, profile)) - _EPS

    def clear(scale: float) -> bool:
        v, w = scale * v_mps, scale * w_radps
        t = stopping_time_s(v, w, profile, params)
        return sweep_min_clearance(v, w, t, near, profile, params) >= required

    if clear(1.0):
        return 1.0
    lo, hi = 0.0, 1.0
    for _ in range(params.iterations):
        mid = 0.5 * (lo + hi)
        if clear(mid):
            lo = mid
        else:
            hi = mid
    return lo


def increases_clearance(
    v_mps: float,
    w_radps: float,
    horizon_s: float,
    points: FloatArray,
    profile: RobotProfile,
) -> bool:
    """True if driving (v, w) for the horizon ends with more footprint clearance than now."""
    if len(points) == 0 or (v_mps == 0.0 and w_radps == 0.0):
        return False
    dx, dy, dth = arc_displacement(v_mps, w_radps, horizon_s)
    c, s = math.cos(dth), math.sin(dth)
    px, py = points[:, 0] - dx, points[:, 1] - dy
    after = _min_clearance(c * px + s * py, -s * px + c * py, profile)
    return after > footprint_clearance(points, profile) + 1e-6


def limit_velocity(v_mps: float, w_radps: float, profile: RobotProfile) -> tuple[float, float]:
    """Clamp to the profile's |v| <= v_max and |w| <= w_max."""
    return (
        max(-profile.v_max_mps, min(profile.v_max_mps, v_mps)),
        max(-profile.w_max_radps, min(profile.w_max_radps, w_radps)),
    )


def limit_acceleration(
    v_mps: float,
    w_radps: float,
    previous: tuple[float, float],
    dt_s: float,
    profile: RobotProfile,
) -> tuple[float, float]:
    """Acceleration limits of the profile; braking uses the (larger) deceleration limit."""
    dv_up = profile.accel_max_mps2 * dt_s
    dv_down = profile.decel_max_mps2 * dt_s
    dw = profile.angular_accel_max_radps2 * dt_s
    return (
        ramp_toward(v_mps, previous[0], dv_up, dv_down),
        ramp_toward(w_radps, previous[1], dw, dw),
    )


def reachable(
    v_mps: float,
    w_radps: float,
    previous: tuple[float, float],
    dt_s: float,
    profile: RobotProfile,
) -> bool:
    """Whether the base can be at (v, w) one period after ``previous`` (acceleration limits)."""
    lv, lw = limit_acceleration(v_mps, w_radps, previous, dt_s, profile)
    return abs(lv - v_mps) <= _EPS and abs(lw - w_radps) <= _EPS


def brake_along(
    previous: tuple[float, float], dt_s: float, profile: RobotProfile
) -> tuple[float, float]:
    """The hardest braking the base can do on the previous command's arc (same curvature).

    The previous cycle's sweep checked this stop (one period at the previous command, then the
    ramp down on its arc), so it stays clear where a sharper command could not be reached in
    time. On a straight line or a turn in place a zero command keeps the arc (and lets a base
    that brakes harder than the profile stop sooner); on a curve only the pair braking at the
    limits together keeps it.
    """
    v_prev, w_prev = previous
    if v_prev == 0.0 or w_prev == 0.0:
        return 0.0, 0.0
    return decelerate(previous, dt_s, profile)


def decelerate(
    previous: tuple[float, float], dt_s: float, profile: RobotProfile
) -> tuple[float, float]:
    """One step of a controlled stop at the profile's limits, on the previous command's arc
    (HOLD, IDLE, and ``brake_along`` on a curve).

    v and w shrink by one common factor, as fast as the tighter of the two limits allows, and
    reach zero together after max(|v| / a_dec, |w| / alpha): the stop ``stopping_time_s`` and
    the sweep assume. Ramping each at its own limit left the arc: on a Jackal w reached zero in
    0.33 s while v needed 0.67 s, and the robot, released from a full-speed curve, went straight
    on out of the swept arc into a wall.
    """
    v_prev, w_prev = previous
    step = 1.0
    if v_prev != 0.0:
        step = min(step, profile.decel_max_mps2 * dt_s / abs(v_prev))
    if w_prev != 0.0:
        step = min(step, profile.angular_accel_max_radps2 * dt_s / abs(w_prev))
    keep = max(0.0, 1.0 - step)
    return v_prev * keep, w_prev * keep
