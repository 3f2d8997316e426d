"""An independent, deliberately plain reference of DESIGN 6 (`ek-egc`) for cross-checking.

Written from the text of DESIGN 6 (and 5.2-5.6) with scalar loops, the literal formulas of the
design (R, the wrapped atan2, theta = sign(R) (pi/2 - atan(|R| / L)), cos and sin of it) and no
code shared with egc_robot, so that a mistake in the vectorised filter, or in the identities it
uses to avoid trigonometry, shows up as a disagreement.
"""

from __future__ import annotations

import math

from tests.filters.reference_egc import reference_circles


def reference_ek_point(x, y, L):
    """DESIGN 6 step 1 for one point: (ex, ey), or None when the point is dropped."""
    if y == 0:
        if x > 0:
            return (x, 0.0)
        return None
    R = (x * x + y * y) / (2 * y)
    g = math.atan2(x, abs(R) - abs(y))
    if g < 0:
        g += 2 * math.pi
    d = abs(R) * g
    theta = math.copysign(1.0, R) * (math.pi / 2 - math.atan(abs(R) / L))
    return (d * math.cos(theta), d * math.sin(theta))


def reference_ek_egc(v, w, points, r_min, r_max, kT, L):
    """dict(v, w, w_si, region, side, rc, igc, agc, egc), or None for the undefined cases of
    DESIGN 5.9 (no points, v = 0 with a point within r_max, circles that do not meet, zero
    weights)."""
    if not points:
        return None
    if v < 0:  # step 2: mirror x -> -x, run with (-v, -w), negate (v', w')
        out = reference_ek_egc(-v, -w, [(-x, y) for x, y in points], r_min, r_max, kT, L)
        if out is not None:
            out["v"], out["w"] = -out["v"], -out["w"]
        return out

    ek = []
    for x, y in points:
        p = reference_ek_point(x, y, L)
        if p is not None:
            ek.append(p)

    theta_c = math.atan(L * w / v) if v != 0 else 0.0  # v = 0: P_IGC is the origin
    x_igc, y_igc = v * kT * math.cos(theta_c), v * kT * math.sin(theta_c)

    def to_command(x_egc, y_egc, w_si):  # step 4
        if x_egc > 0:
            v_out = w_si * math.sqrt(x_egc**2 + y_egc**2) / kT
            return v_out, v_out * math.tan(math.atan2(y_egc, x_egc)) / L
        sign = 1 if y_egc > 0 else -1 if y_egc < 0 else 0
        return 0.0, w_si * (2 / kT) * (math.pi / 2) * sign

    return reference_circles(v, w, x_igc, y_igc, ek, r_min, r_max, to_command)
