"""An independent, deliberately plain reference of DESIGN 6 (`ek-egc`) for cross-checking.

Written from the text of DESIGN 6 (and 5.2-5.6) with scalar loops, the literal formulas of the
design (R, the wrapped atan2, theta = sign(R) (pi/2 - atan(|R| / L)), cos and sin of it) and no
code shared with egc_robot, so that a mistake in the vectorised filter, or in the identities it
uses to avoid trigonometry, shows up as a disagreement.
"""

from __future__ import annotations

import math


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
    r_rc = math.sqrt(x_igc**2 + y_igc**2)

    def nearest(cx, cy):
        best, best_p = math.inf, None
        for px, py in ek:
            d = math.sqrt((px - cx) ** 2 + (py - cy) ** 2)
            if d < best:
                best, best_p = d, (px, py)
        return best, best_p

    d, m = nearest(x_igc, y_igc)
    if d >= r_max:
        return {
            "v": v,
            "w": w,
            "w_si": 1.0,
            "region": "safe",
            "side": None,
            "rc": r_rc,
            "igc": [x_igc, y_igc, r_max],
            "agc": None,
            "egc": None,
        }
    r_igc = d
    if r_rc == 0 or r_igc > 2 * r_rc:
        return None
    s = x_igc * m[1] - y_igc * m[0]
    side = "right" if s > 0 else "left"
    ux, uy = x_igc / r_rc, y_igc / r_rc
    nx, ny = -uy, ux
    ell = r_rc - r_igc**2 / (2 * r_rc)
    h = math.sqrt(max(r_rc**2 - ell**2, 0.0))
    sgn = 1 if side == "left" else -1
    x_agc, y_agc = ell * ux + sgn * h * nx, ell * uy + sgn * h * ny
    r_agc = min(nearest(x_agc, y_agc)[0], r_max)
    if r_igc + r_agc == 0:
        return None
    x_egc = (r_igc * x_igc + r_agc * x_agc) / (r_igc + r_agc)
    y_egc = (r_igc * y_igc + r_agc * y_agc) / (r_igc + r_agc)
    r_egc = min(nearest(x_egc, y_egc)[0], r_max)
    if r_egc > r_max:
        w_si, region = 1.0, "safe"
    elif r_egc > r_min:
        w_si, region = r_egc / r_max, "conditional"
    else:
        w_si, region = 0.0, "unsafe"
    # step 4
    d_e = math.sqrt(x_egc**2 + y_egc**2)
    theta_e = math.atan2(y_egc, x_egc)
    if x_egc > 0:
        v_out = w_si * d_e / kT
        w_out = v_out * math.tan(theta_e) / L
    else:
        v_out = 0.0
        w_out = w_si * (2 / kT) * (math.pi / 2) * (1 if y_egc > 0 else -1 if y_egc < 0 else 0)
    return {
        "v": v_out,
        "w": w_out,
        "w_si": w_si,
        "region": region,
        "side": side,
        "rc": r_rc,
        "igc": [x_igc, y_igc, r_igc],
        "agc": [x_agc, y_agc, r_agc],
        "egc": [x_egc, y_egc, r_egc],
    }
