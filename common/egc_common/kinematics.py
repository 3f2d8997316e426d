"""Differential-drive kinematics (paper eqs. 1-3) and footprint geometry, all in SI units.

Poses are (x, y, theta) tuples in metres and radians. Arc integration is exact for constant
(v, w) over a step, not Euler.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

_SMALL_ANGLE = 1e-9


def wrap_angle(angle_rad: float) -> float:
    """Wrap to (-pi, pi]."""
    a = math.fmod(angle_rad + math.pi, 2.0 * math.pi)
    if a <= 0.0:
        a += 2.0 * math.pi
    return a - math.pi


def arc_displacement(v_mps: float, w_radps: float, dt_s: float) -> tuple[float, float, float]:
    """Displacement (dx, dy, dtheta) in the start frame after moving on a constant arc for dt.

    Uses the chord form of eq. 6: the end point lies at distance |2 R sin(w dt / 2)| along the
    direction w dt / 2, which tends to v dt as w -> 0 without a division by w.
    """
    dtheta = w_radps * dt_s
    half = 0.5 * dtheta
    if abs(half) < _SMALL_ANGLE:
        chord = v_mps * dt_s
    else:
        chord = v_mps * dt_s * math.sin(half) / half
    return chord * math.cos(half), chord * math.sin(half), dtheta


def integrate_arc(
    pose: tuple[float, float, float], v_mps: float, w_radps: float, dt_s: float
) -> tuple[float, float, float]:
    """Exact pose after driving (v, w) for dt from ``pose`` (world frame)."""
    x, y, th = pose
    dx, dy, dth = arc_displacement(v_mps, w_radps, dt_s)
    c, s = math.cos(th), math.sin(th)
    return x + c * dx - s * dy, y + s * dx + c * dy, wrap_angle(th + dth)


def ramp_toward(target: float, current: float, up: float, down: float) -> float:
    """Move from ``current`` toward ``target`` by at most ``up`` when speeding up (same sign,
    larger magnitude) and at most ``down`` otherwise (slowing down or reversing)."""
    speeding_up = abs(target) > abs(current) and target * current >= 0.0
    step = up if speeding_up else down
    return current + max(-step, min(step, target - current))


def scale_as_whole(
    v_mps: float, w_radps: float, v_lim_mps: float, w_lim_radps: float = math.inf
) -> tuple[float, float, bool]:
    """(v, w) scaled by one factor so that |v| <= v_lim and |w| <= w_lim (the tighter cap
    wins): the curvature w / v stays, so the path keeps its shape. The flag says whether it
    scaled. The latency governor (DESIGN 9) on the robot and its prediction in the view share
    it, so that the view predicts what the robot does."""
    scale = 1.0
    speed, turn = abs(v_mps), abs(w_radps)
    if speed > v_lim_mps:
        scale = max(v_lim_mps, 0.0) / speed
    if turn > w_lim_radps:
        scale = min(scale, max(w_lim_radps, 0.0) / turn)
    if scale >= 1.0:
        return v_mps, w_radps, False
    return v_mps * scale, w_radps * scale, True


def wheel_speeds(v_mps: float, w_radps: float, wheel_base_m: float) -> tuple[float, float]:
    """(left, right) wheel rim speeds for a body twist (inverse of eq. 2)."""
    half = 0.5 * wheel_base_m * w_radps
    return v_mps - half, v_mps + half


def body_twist(left_mps: float, right_mps: float, wheel_base_m: float) -> tuple[float, float]:
    """Body twist (v, w) from wheel rim speeds (eq. 2 with r folded into the rim speeds)."""
    return 0.5 * (left_mps + right_mps), (right_mps - left_mps) / wheel_base_m


def signed_distance_to_rectangle(
    x_m: npt.ArrayLike, y_m: npt.ArrayLike, half_length_m: float, half_width_m: float
) -> FloatArray:
    """Signed distance (m) from points (x, y) to the rectangle centred on the origin, axes along
    x and y: positive outside, minus the penetration depth inside.

    The footprint check of the robot's safety rules and the simulator's collision check both
    measure with this, in the footprint's own frame.
    """
    qx = np.abs(np.asarray(x_m, dtype=np.float64)) - half_length_m
    qy = np.abs(np.asarray(y_m, dtype=np.float64)) - half_width_m
    outside = np.hypot(np.maximum(qx, 0.0), np.maximum(qy, 0.0))
    result: FloatArray = outside + np.minimum(np.maximum(qx, qy), 0.0)
    return result
