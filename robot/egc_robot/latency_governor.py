"""The latency governor (DESIGN 9, pinned): the robot may not outrun the operator's ability to
correct it.

With tau the loop delay (how long the operator needs to see a situation and have the correction
arrive), the speed is capped so that the distance covered during tau plus the braking distance at
``a_dec`` stays within D = v_max x ``blind_time``:

    v tau + v^2 / (2 a_dec) <= D   =>   v_lim = a_dec (sqrt(tau^2 + 2 D / a_dec) - tau)

As tau -> 0 the cap tends to sqrt(2 a_dec D) (the braking distance alone), which for the
pinned profiles lies above v_max, so nothing changes on a good link. The command is scaled as a
whole (v and w by the same factor): same curvature, so the path keeps its shape.

The turn rate obeys the same rule (our addition to DESIGN 9, ``latency_turn_cap``, on by
default): the heading turned during tau plus the angle needed to stop turning at the profile's
angular acceleration stays within Theta = w_max x ``blind_time``, so w_lim is the formula above
with (w_max, alpha) for (v_max, a_dec). The reason is the same: a robot turning at 2 rad/s on a
0.8 s loop has turned 90 degrees before the operator can see it turning, and a sighted operator
correcting that overshoots again (a speed cap alone does not touch a turn in place; measured in
docs/network-delay.md). The command is still scaled as a whole, by the tighter of the two caps.
A cap lies at or above its maximum exactly when ``blind_time >= tau + max / (2 decel)``
(for the Pioneer 3-DX, filtered, both caps are off at tau 0.75 s, as DESIGN 9 states).
"""

from __future__ import annotations

import math

# govern: the command scaled as a whole by the tighter cap, shared with the view's prediction.
from egc_common.kinematics import scale_as_whole as govern

__all__ = ["govern", "latency_speed_limit", "latency_turn_limit"]


def _latency_limit(
    tau_s: float, rate_max: float, decel: float, blind_time_s: float, names: tuple[str, str]
) -> float:
    for name, value in (
        ("tau_s", tau_s),
        (names[0], rate_max),
        (names[1], decel),
        ("blind_time_s", blind_time_s),
    ):
        if not math.isfinite(value) or value < 0:
            raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
    if decel == 0:
        raise ValueError(f"{names[1]} must be > 0")
    budget = rate_max * blind_time_s
    return decel * (math.sqrt(tau_s * tau_s + 2.0 * budget / decel) - tau_s)


def latency_speed_limit(
    tau_s: float, v_max_mps: float, a_dec_mps2: float, blind_time_s: float
) -> float:
    """v_lim (m/s) for loop delay ``tau_s``; raises ValueError on non-physical arguments."""
    return _latency_limit(tau_s, v_max_mps, a_dec_mps2, blind_time_s, ("v_max_mps", "a_dec_mps2"))


def latency_turn_limit(
    tau_s: float, w_max_radps: float, alpha_dec_radps2: float, blind_time_s: float
) -> float:
    """w_lim (rad/s) for loop delay ``tau_s``: ``latency_speed_limit`` for the turn rate."""
    return _latency_limit(
        tau_s, w_max_radps, alpha_dec_radps2, blind_time_s, ("w_max_radps", "alpha_dec_radps2")
    )
