"""Issue 2 benchmark: EGC filter time per call, vectorised vs a plain per-point Python loop.

Scans of 360, 720 and 1,440 beams in a room with an obstacle ahead, and a 30,000-point cloud (a
projected RGB-D frame), each with a command that needs modification (the EXPANDED branch, three
nearest-point searches). Both implementations run in the same process on the same inputs;
results are checked to agree before timing. Targets: median <= 50 us at 720 points and <= 2 ms
at 30,000 points.

    python bench/bench_filter.py [--repeats N] [--out FILE.json]
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np
from egc_common.profiles import PIONEER3DX
from egc_robot.filters.egc import EgcCase, EgcParams, egc_filter

PARAMS = EgcParams.from_profile(PIONEER3DX.r_min_m, PIONEER3DX.r_max_m, PIONEER3DX.v_max_mps)
COMMAND = (0.14, 0.05)


def room_scan(beams: int) -> np.ndarray:
    """A 6 x 4 m room seen from its middle, with a box 1 m ahead slightly right of the path."""
    a = np.linspace(-math.pi, math.pi, beams, endpoint=False)
    c, s = np.cos(a), np.sin(a)
    with np.errstate(divide="ignore"):
        r = np.minimum(
            np.where(c != 0, 3.0 / np.abs(c), np.inf), np.where(s != 0, 2.0 / np.abs(s), np.inf)
        )
    box = np.abs(a + 0.05) < 0.12
    r[box] = 1.0 / np.maximum(c[box], 1e-3)
    return np.column_stack((r * c, r * s))


def rgbd_cloud(n: int = 30_000, seed: int = 0) -> np.ndarray:
    """A projected depth frame: a 58-degree wedge of floor-level returns with an obstacle ahead."""
    rng = np.random.default_rng(seed)
    ang = rng.uniform(-0.506, 0.506, n)
    depth = rng.uniform(1.5, 4.0, n)
    near = np.abs(ang + 0.05) < 0.12
    depth[near] = rng.uniform(0.95, 1.1, int(near.sum()))
    return np.column_stack((depth * np.cos(ang), depth * np.sin(ang)))


def python_loop_egc(
    v: float, w: float, pts: list[tuple[float, float]], r_min: float, r_max: float, kT: float
):
    """The same algorithm with a per-point Python loop for the nearest-point searches."""

    def nearest(cx: float, cy: float) -> tuple[float, float, float]:
        best, bx, by = math.inf, 0.0, 0.0
        for px, py in pts:
            d = math.hypot(px - cx, py - cy)
            if d < best:
                best, bx, by = d, px, py
        return best, bx, by

    xi, yi = v * kT * math.cos(w * kT / 2), v * kT * math.sin(w * kT / 2)
    rc = math.hypot(xi, yi)
    d, mx, my = nearest(xi, yi)
    if d >= r_max:
        return v, w
    ux, uy = xi / rc, yi / rc
    ell = rc - d * d / (2 * rc)
    h = math.sqrt(max(rc * rc - ell * ell, 0.0))
    sgn = 1.0 if xi * my - yi * mx <= 0 else -1.0
    xa, ya = ell * ux - sgn * h * uy, ell * uy + sgn * h * ux
    ra = min(nearest(xa, ya)[0], r_max)
    xe, ye = (d * xi + ra * xa) / (d + ra), (d * yi + ra * ya) / (d + ra)
    re = min(nearest(xe, ye)[0], r_max)
    wsi = 1.0 if re > r_max else (re / r_max if re > r_min else 0.0)
    return wsi * math.copysign(1, xe) * math.hypot(xe, ye) / kT, wsi * 2 / kT * math.atan(ye / xe)


def time_calls(fn, repeats: int) -> list[float]:
    out = []
    for _ in range(repeats):
        t0 = time.perf_counter_ns()
        fn()
        out.append((time.perf_counter_ns() - t0) / 1e3)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=2000)
    ap.add_argument("--out", default="bench/results/bench_filter.json")
    args = ap.parse_args(argv)

    cases = {f"scan {n}": room_scan(n) for n in (360, 720, 1440)}
    cases["rgbd 30000"] = rgbd_cloud()
    rows = []
    print(
        f"EGC filter, command (v, w) = {COMMAND}, {platform.processor() or platform.machine()}, "
        f"Python {platform.python_version()}"
    )
    print(
        f"{'input':<12}{'points':>8}{'median us':>12}{'p95 us':>10}{'loop median us':>16}{'speed-up':>10}"
    )
    for name, pts in cases.items():
        res = egc_filter(*COMMAND, pts, PARAMS)
        assert res.case is EgcCase.EXPANDED, f"{name}: command not modified ({res.case})"
        as_list = [tuple(p) for p in pts.tolist()]
        ref = python_loop_egc(*COMMAND, as_list, PARAMS.r_min_m, PARAMS.r_max_m, PARAMS.horizon_s)
        assert np.allclose((res.v_mps, res.w_radps), ref, atol=1e-12), (name, res, ref)
        for _ in range(50):
            egc_filter(*COMMAND, pts, PARAMS)
        vec = time_calls(lambda pts=pts: egc_filter(*COMMAND, pts, PARAMS), args.repeats)
        loop_reps = max(5, min(200, args.repeats // max(1, len(pts) // 100)))
        loop = time_calls(
            lambda lst=as_list: python_loop_egc(
                *COMMAND, lst, PARAMS.r_min_m, PARAMS.r_max_m, PARAMS.horizon_s
            ),
            loop_reps,
        )
        med, p95 = statistics.median(vec), float(np.percentile(vec, 95))
        lmed = statistics.median(loop)
        rows.append(
            {
                "input": name,
                "points": len(pts),
                "median_us": med,
                "p95_us": p95,
                "loop_median_us": lmed,
                "speedup": lmed / med,
                "repeats": args.repeats,
                "loop_repeats": loop_reps,
            }
        )
        print(f"{name:<12}{len(pts):>8}{med:>12.1f}{p95:>10.1f}{lmed:>16.1f}{lmed / med:>9.1f}x")

    by = {r["points"]: r for r in rows}
    targets = {
        "720 points <= 50 us": by[720]["median_us"] <= 50.0,
        "30000 points <= 2000 us": by[30000]["median_us"] <= 2000.0,
    }
    for k, ok in targets.items():
        print(f"target {k}: {'met' if ok else 'MISSED'}")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"rows": rows, "targets": targets, "python": sys.version}, indent=2))
    print(f"wrote {out}")
    return 0 if all(targets.values()) else 1


if __name__ == "__main__":
    raise SystemExit(main())
