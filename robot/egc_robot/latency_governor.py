"""The latency governor (DESIGN 9, pinned): the robot may not outrun the operator's ability to
correct it.

With tau the loop delay (how long the operator needs to see a situation and have the correction
arrive), the speed is capped so that the distance covered during tau plus the braking distance at
``a_dec`` stays within D = v_max x ``blind_time``:

    v tau + v^2 / (2 a_dec) <= D   =>   v_lim = a_dec (sqrt(tau^2 + 2 D / a_dec) - tau)

As tau -> 0 the cap tends to sqrt(2 a_dec D) (the braking distance alone), which for the
pinned profiles lies above v_max, so nothing changes on a good link. The command is scaled as a
whole (v and w by the same factor): same curvature, so the path keeps its shape.
"""

from __future__ import annotations

import math


def latency_speed_limit(
    tau_s: float, v_max_mps: float, a_dec_mps2: float, blind_time_s: float
) -> float:
    """v_lim (m/s) for loop delay ``tau_s``; raises ValueError on non-physical arguments."""
    for name, value in (
        ("tau_s", tau_s),
        ("v_max_mps", v_max_mps),
        ("a_dec_mps2", a_dec_mps2),
        ("blind_time_s", blind_time_s),
    ):
        if not math.isfinite(value) or value < 0:
            raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
    if a_dec_mps2 == 0:
        raise ValueError("a_dec_mps2 must be > 0")
    d_m = v_max_mps * blind_time_s
    return a_dec_mps2 * (math.sqrt(tau_s * tau_s + 2.0 * d_m / a_dec_mps2) - tau_s)


def govern(v_mps: float, w_radps: float, v_lim_mps: float) -> tuple[float, float, bool]:
    """(v, w) scaled as a whole so that |v| <= v_lim; the flag says whether it acted."""
    speed = abs(v_mps)
    if speed <= v_lim_mps:
        return v_mps, w_radps, False
    scale = max(v_lim_mps, 0.0) / speed
    return v_mps * scale, w_radps * scale, True
