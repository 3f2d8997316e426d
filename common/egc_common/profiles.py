"""Robot profiles (DESIGN 3): footprint, kinematic limits and the EGC radii.

The radii follow the paper's sec. 3.1 / 4.1: ``r_min = d_robot`` and ``r_max = d_robot + d_safe``.
For the Pioneer 3-DX of the paper this gives r_min = 0.455 m and r_max = 0.595 m.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import Any


@dataclass(frozen=True, slots=True)
class RobotProfile:
    """Everything the filter, the limits and the simulator need to know about one robot."""

    name: str
    length_m: float
    width_m: float
    wheel_base_m: float
    v_max_mps: float
    w_max_radps: float
    accel_max_mps2: float
    decel_max_mps2: float
    angular_accel_max_radps2: float
    d_robot_m: float
    d_safe_m: float

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name == "name":
                if not isinstance(value, str) or not value:
                    raise ValueError("profile name must be a non-empty string")
                continue
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
                raise ValueError(
                    f"profile {self.name!r}: {f.name} must be a positive finite number"
                )

    @property
    def r_min_m(self) -> float:
        """Radius of the unsafe region (paper eq. 5)."""
        return self.d_robot_m

    @property
    def r_max_m(self) -> float:
        """Radius of the safety index circle's outer boundary (paper eq. 5)."""
        return self.d_robot_m + self.d_safe_m

    @property
    def horizon_s(self) -> float:
        """Default prediction horizon kT = r_max / v_max (DESIGN 5.8)."""
        return self.r_max_m / self.v_max_mps

    @property
    def half_size_m(self) -> tuple[float, float]:
        """Half length and half width of the footprint rectangle, centred on {R}'s origin."""
        return 0.5 * self.length_m, 0.5 * self.width_m

    @property
    def half_diagonal_m(self) -> float:
        """Radius of the circle swept by the footprint when turning in place."""
        return 0.5 * math.hypot(self.length_m, self.width_m)

    @property
    def wheel_speed_max_mps(self) -> float:
        """Largest wheel rim speed the profile's (v_max, w_max) can ask for."""
        return self.v_max_mps + 0.5 * self.wheel_base_m * self.w_max_radps

    def with_overrides(self, **overrides: Any) -> RobotProfile:
        """A copy with some fields replaced (validated again)."""
        return replace(self, **overrides)


PIONEER3DX = RobotProfile(
    name="pioneer3dx",
    length_m=0.455,
    width_m=0.381,
    wheel_base_m=0.33,
    v_max_mps=0.14,
    w_max_radps=0.5,
    accel_max_mps2=0.3,
    decel_max_mps2=0.5,
    angular_accel_max_radps2=1.5,
    d_robot_m=0.455,
    d_safe_m=0.14,
)

JACKAL = RobotProfile(
    name="jackal",
    length_m=0.508,
    width_m=0.430,
    wheel_base_m=0.37,
    v_max_mps=2.0,
    w_max_radps=2.0,
    accel_max_mps2=2.0,
    decel_max_mps2=3.0,
    angular_accel_max_radps2=6.0,
    d_robot_m=0.508,
    d_safe_m=2.0 * 1.0,  # d_safe = v_max * 1 s (DESIGN 3)
)

PROFILES: dict[str, RobotProfile] = {p.name: p for p in (PIONEER3DX, JACKAL)}


def get_profile(name: str) -> RobotProfile:
    """Look a profile up by its pinned name; a clear error names the known ones."""
    try:
        return PROFILES[name]
    except KeyError:
        known = ", ".join(sorted(PROFILES))
        raise ValueError(f"unknown robot profile {name!r} (known: {known})") from None
