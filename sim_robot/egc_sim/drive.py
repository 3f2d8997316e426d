"""Differential-drive base: what the wheels can do with a velocity command (paper eqs. 2-3).

A real base does not jump to the commanded twist. Per integration step of length dt the
simulated base

1. clamps the command to the profile's |v| <= v_max and |w| <= w_max. This is also the wheel
   limit: the profile's largest wheel rim speed is ``v_max + w_max * wheel_base / 2``
   (``RobotProfile.wheel_speed_max_mps``), so no clamped twist asks a wheel for more;
2. moves its twist toward it by at most ``accel_max * dt`` when speeding up, ``decel_max * dt``
   when slowing down or reversing (linear), and ``angular_accel_max * dt`` (angular).

The pose then follows the exact arc for the resulting constant (v, w)
(``egc_common.kinematics.integrate_arc``). Odometry integrates the same arc with the distance and
the angle of each integration step scaled by ``1 + N(0, std)`` (``OdometryNoise``): errors grow
with the motion, as wheel slip and a mis-calibrated wheel radius make them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from egc_common.kinematics import ramp_toward
from egc_common.profiles import RobotProfile


@dataclass(frozen=True, slots=True)
class OdometryNoise:
    """Relative standard deviations of the distance and the angle odometry measures per step."""

    linear_rel_std: float = 0.0
    angular_rel_std: float = 0.0

    def __post_init__(self) -> None:
        for name in ("linear_rel_std", "angular_rel_std"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"odometry noise {name} must be >= 0, got {value}")

    @property
    def enabled(self) -> bool:
        return self.linear_rel_std > 0.0 or self.angular_rel_std > 0.0


def achievable_twist(
    v_cmd_mps: float,
    w_cmd_radps: float,
    current: tuple[float, float],
    dt_s: float,
    profile: RobotProfile,
) -> tuple[float, float]:
    """The twist the base reaches after dt from ``current`` toward the command (docstring)."""
    v_max, w_max = profile.v_max_mps, profile.w_max_radps
    v = ramp_toward(
        max(-v_max, min(v_max, v_cmd_mps)),
        current[0],
        profile.accel_max_mps2 * dt_s,
        profile.decel_max_mps2 * dt_s,
    )
    dw = profile.angular_accel_max_radps2 * dt_s
    w = ramp_toward(max(-w_max, min(w_max, w_cmd_radps)), current[1], dw, dw)
    return max(-v_max, min(v_max, v)), max(-w_max, min(w_max, w))
