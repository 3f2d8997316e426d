"""An independent, deliberately plain reference of DESIGN 5.1-5.8 for cross-checking.

Written from the text of DESIGN 5 with scalar loops and no code shared with egc_robot, so that
a mistake in the vectorised filter shows up as a disagreement.
"""

from __future__ import annotations

import math


def reference_egc(v, w, points, r_min, r_max, kT):
    """Returns dict(v, w, w_si, region, side, rc, igc, agc, egc) or None for undefined cases."""
    x_igc = v * kT * math.cos(w * kT / 2)
    y_igc = v * kT * math.sin(w * kT / 2)

    def to_command(x_egc, y_egc, w_si):  # step 7, eqs. 14-15
        if x_egc == 0:
            sign = 1 if y_egc > 0 else -1 if y_egc < 0 else 0
            return 0.0, w_si * (2 / kT) * (math.pi / 2) * sign
        v_out = w_si * math.copysign(1, x_egc) * math.sqrt(x_egc**2 + y_egc**2) / kT
        return v_out, w_si * (2 / kT) * math.atan(y_egc / x_egc)

    return reference_circles(v, w, x_igc, y_igc, points, r_min, r_max, to_command)


def reference_circles(v, w, x_igc, y_igc, points, r_min, r_max, to_command):
    """DESIGN 5 steps 2-6 around a given P_IGC, then ``to_command(x_egc, y_egc, w_si)`` back to
    (v', w'); shared by the EGC and EK-EGC references (EK-EGC runs the same steps on EK points).
    Returns the result dict, or None for the undefined cases."""
    r_rc = math.sqrt(x_igc**2 + y_igc**2)

    def nearest(cx, cy):
        best, best_p = math.inf, None
        for px, py in points:
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
    v_out, w_out = to_command(x_egc, y_egc, w_si)
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
