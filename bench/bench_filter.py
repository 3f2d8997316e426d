"""Issue 2 benchmark: EGC filter time per call, vectorised vs a plain per-point Python loop.

Scans of 360, 720 and 1,440 beams in a room with an obstacle ahead, and a 30,000-point cloud (a
projected RGB-D frame), each with a command that needs modification (the EXPANDED branch, three
nearest-point searches). Both implementations run in the same process on the same inputs;
results are checked to agree before timing. Targets: median <= 50 us at 720 points and <= 2 ms
at 30,000 points.

The filter family (DESIGN 6, issue 10), in the same run on the same scans: ``ek-egc`` (when its
module is importable) with the same radii, target <= 2x EGC's median; ``dwa`` with the
pioneer3dx profile on the same input (points beyond its reach cost nothing), and ``dwa`` with
the jackal profile on the same scan (2.5 m look-ahead: nearly every point is within reach, the
expensive case). DWA's cost is reported as a ratio to EGC's, without a target.

``cbf`` (DESIGN 13, issue 28): on EGC's own input (pioneer3dx at 0.14 m/s: the box 1 m ahead is
beyond anything the command could reach, so it passes after the reach test), then the jackal on
the same scans at 1.2 m/s (the box within reach: the QP is solved) and at 2 m/s (most of the
room within reach, the expensive case), and the disc and the pentagon at speed. Target: every
cbf row <= 2x EGC's median at 720 points. Each family row is timed call for call alternately with
EGC on the same scan, and its ratio is to that EGC median: load on the machine falls on both.

    python bench/bench_filter.py [--repeats N] [--out FILE.json]
"""

from __future__ import annotations

import argparse
import math
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np
from egc_common.profiles import JACKAL, PIONEER3DX, TURTLEBOT4, RobotProfile, load_profile
from egc_experiments.bench_results import write_result
from egc_robot.filters.cbf import CbfParams, cbf_filter
from egc_robot.filters.dwa import DwaParams, dwa_filter
from egc_robot.filters.egc import EgcCase, EgcParams, egc_filter

try:  # written alongside this bench (issue 10); the bench reports it once it lands
    from egc_robot.filters.ek_egc import ek_egc_filter
except ImportError:  # pragma: no cover - depends on the checkout
    ek_egc_filter = None

PARAMS = EgcParams.from_profile(PIONEER3DX.r_min_m, PIONEER3DX.r_max_m, PIONEER3DX.v_max_mps)
COMMAND = (0.14, 0.05)
EK_L_M = PIONEER3DX.v_max_mps / PIONEER3DX.w_max_radps  # L = v_max / w_max (DESIGN 6)
# DWA: the profile and the command at full speed, already driving it (goal: none).
# Beyond the centred rectangle's closed form (DESIGN 14): a disc (two circles) and a polygon
# (orbit x edge crossings, the documented pentagon).
PENTAGON = load_profile(str(Path(__file__).resolve().parents[1] / "docs/profiles/pentagon.toml"))
DWA_CASES: dict[str, tuple[RobotProfile, tuple[float, float]]] = {
    "dwa": (PIONEER3DX, COMMAND),
    "dwa jackal": (JACKAL, (2.0, 0.5)),
    "dwa tb4": (TURTLEBOT4, (0.31, 0.5)),
    "dwa pentagon": (PENTAGON, (0.8, 0.3)),
}
# cbf: the profile and the command, already driving it, on a perfect link (tau 0.25 s).
CBF_CASES: dict[str, tuple[RobotProfile, tuple[float, float]]] = {
    "cbf": (PIONEER3DX, COMMAND),
    "cbf jackal": (JACKAL, (1.2, 0.3)),
    "cbf jackal 2": (JACKAL, (2.0, 0.5)),
    "cbf tb4": (TURTLEBOT4, (0.31, 0.5)),
    "cbf pentagon": (PENTAGON, (0.8, 0.3)),
}


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


def time_interleaved(fn, baseline, repeats: int) -> tuple[list[float], list[float]]:
    """``fn`` and ``baseline`` timed call for call, alternately: whatever else the machine does
    meanwhile falls on both alike, so their ratio holds on a busy machine too."""
    out, base = [], []
    for _ in range(repeats):
        t0 = time.perf_counter_ns()
        baseline()
        t1 = time.perf_counter_ns()
        fn()
        t2 = time.perf_counter_ns()
        base.append((t1 - t0) / 1e3)
        out.append((t2 - t1) / 1e3)
    return out, base


def family_rows(cases: dict, repeats: int) -> list[dict]:
    """ek-egc, dwa and cbf per call on the scans, each timed alternately with EGC on the same
    scan (``time_interleaved``); the ratio is to that EGC median."""
    fns = {}
    if ek_egc_filter is not None:
        fns["ek-egc"] = lambda pts: ek_egc_filter(*COMMAND, pts, PARAMS, EK_L_M)
    for name, (profile, cmd) in DWA_CASES.items():
        params = DwaParams.from_profile(profile)
        fns[name] = lambda pts, p=profile, c=cmd, d=params: dwa_filter(*c, pts, *c, None, p, d)
    for name, (profile, cmd) in CBF_CASES.items():
        cbf = CbfParams.from_profile(profile)
        fns[name] = lambda pts, p=profile, c=cmd, d=cbf: cbf_filter(*c, pts, *c, None, p, d)
    rows = []
    print()
    print("Filter family per call, same scans, each timed alternately with EGC (egc us)")
    print(
        f"{'filter':<12}{'points':>8}{'median us':>12}{'p95 us':>10}{'egc us':>10}{'ratio':>8}  note"
    )
    for name, fn in fns.items():
        for case, pts in cases.items():
            if not case.startswith("scan"):
                continue
            res = fn(pts)
            note = ""
            if name.startswith("dwa"):
                profile = DWA_CASES[name][0]
                reach = profile.half_diagonal_m + DwaParams.from_profile(profile).margin_m
                reach += DwaParams.from_profile(profile).lookahead_m
                within = int((np.hypot(pts[:, 0], pts[:, 1]) <= reach).sum())
                note = (
                    f"{profile.name}, {within} points in reach, {res.candidates} candidates, "
                    f"{res.admissible} admissible, {'modified' if res.modified else 'passed'}"
                )
            elif name.startswith("cbf"):
                note = (
                    f"{CBF_CASES[name][0].name}, {res.case.value}, {res.considered} points "
                    f"considered, {res.rounds} rounds"
                )
            else:
                note = str(res.case.value)
            for _ in range(20):
                fn(pts)
            reps = max(50, repeats // 10) if name.startswith("dwa") else repeats
            times, egc_times = time_interleaved(
                lambda f=fn, p=pts: f(p), lambda p=pts: egc_filter(*COMMAND, p, PARAMS), reps
            )
            med, p95 = statistics.median(times), float(np.percentile(times, 95))
            egc = statistics.median(egc_times)
            rows.append(
                {
                    "filter": name,
                    "points": len(pts),
                    "median_us": med,
                    "p95_us": p95,
                    "egc_median_us": egc,
                    "ratio_to_egc": med / egc,
                    "repeats": reps,
                    "note": note,
                }
            )
            print(
                f"{name:<12}{len(pts):>8}{med:>12.1f}{p95:>10.1f}{egc:>10.1f}{med / egc:>7.1f}x  {note}"
            )
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=2000)
    ap.add_argument("--out", help="JSON file (default bench/results/filter.json)")
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
    family = family_rows(cases, args.repeats)
    if ek_egc_filter is None:
        print("ek-egc: egc_robot.filters.ek_egc is not importable in this checkout; not timed")
    else:
        for n in (360, 720, 1440):
            ratio = next(
                r["ratio_to_egc"] for r in family if r["filter"] == "ek-egc" and r["points"] == n
            )
            targets[f"ek-egc <= 2x egc at {n} points"] = ratio <= 2.0
    for name in CBF_CASES:
        ratio = next(
            r["ratio_to_egc"] for r in family if r["filter"] == name and r["points"] == 720
        )
        targets[f"{name} <= 2x egc at 720 points"] = ratio <= 2.0
    for k, ok in targets.items():
        print(f"target {k}: {'met' if ok else 'MISSED'}")
    result = {"rows": rows, "family": family, "targets": targets, "python": sys.version}
    out = write_result("filter", result, args.out)
    print(f"wrote {out}")
    return 0 if all(targets.values()) else 1


if __name__ == "__main__":
    raise SystemExit(main())
