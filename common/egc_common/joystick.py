"""Joystick deflection to velocity (paper eq. 4, DESIGN 4).

Axes are first calibrated to [-1, 1] (``normalise_axis``), then a deadzone is removed and the
remainder rescaled so the output still spans [-1, 1] (``apply_deadzone``). The robot maps the
normalised deflection (x_o forward, y_o left) to (v, w) with eq. 4, where x_max = y_max = 1:

    v = gamma_v * v_max * x_o,    w = gamma_w * w_max * y_o
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class JoystickMapping:
    """Scale factors of eq. 4 and the deadzone of DESIGN 4."""

    gamma_v: float = 1.0
    gamma_w: float = 1.0
    deadzone: float = 0.05

    def __post_init__(self) -> None:
        for name in ("gamma_v", "gamma_w"):
            value = getattr(self, name)
            if not math.isfinite(value) or not 0.0 <= value <= 1.0:
                raise ValueError(f"{name} must be in [0, 1], got {value}")
        if not math.isfinite(self.deadzone) or not 0.0 <= self.deadzone < 1.0:
            raise ValueError(f"deadzone must be in [0, 1), got {self.deadzone}")


def clamp_unit(value: float) -> float:
    """Clamp to [-1, 1]; NaN becomes 0 (a centred stick is the safe reading)."""
    if not math.isfinite(value):
        return 0.0 if math.isnan(value) else math.copysign(1.0, value)
    return max(-1.0, min(1.0, value))


def normalise_axis(
    raw: float, raw_min: float, raw_max: float, raw_center: float | None = None
) -> float:
    """Calibrate a raw axis reading (e.g. evdev absinfo min/max) to [-1, 1].

    With ``raw_center`` the two halves are scaled separately, so an off-centre rest position
    still reads 0. Readings outside [raw_min, raw_max] are clamped.
    """
    if not raw_max > raw_min:
        raise ValueError("axis calibration needs raw_max > raw_min")
    center = 0.5 * (raw_min + raw_max) if raw_center is None else raw_center
    if not raw_min <= center <= raw_max:
        raise ValueError("axis centre must lie within [raw_min, raw_max]")
    if raw >= center:
        span = raw_max - center
        value = (raw - center) / span if span > 0 else 0.0
    else:
        span = center - raw_min
        value = (raw - center) / span if span > 0 else 0.0
    return clamp_unit(value)


def apply_deadzone(value: float, deadzone: float) -> float:
    """Zero inside the deadzone, rescaled outside so that +-1 still maps to +-1."""
    v = clamp_unit(value)
    magnitude = abs(v)
    if magnitude <= deadzone:
        return 0.0
    return math.copysign((magnitude - deadzone) / (1.0 - deadzone), v)


def deflection_to_velocity(
    x_o: float, y_o: float, v_max_mps: float, w_max_radps: float, mapping: JoystickMapping
) -> tuple[float, float]:
    """Paper eq. 4 with x_max = y_max = 1: normalised deflection to (v [m/s], w [rad/s])."""
    return (
        mapping.gamma_v * v_max_mps * clamp_unit(x_o),
        mapping.gamma_w * w_max_radps * clamp_unit(y_o),
    )
