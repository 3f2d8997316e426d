"""Issue 28 benchmark: the cost of assist's local planner per control cycle

Scans (the simulator's 360-beam lidar) from poses drawn in dense-clutter worlds
(``clutter:0-4``, the Jackal), the via point at each world's goal. ``assist_step`` runs with the
planner (the profile's params) and without it (``plan_cell_m`` = 0: the rules alone), call for
call alternately on the same inputs and with the memory of one earlier cycle at the same pose
(so the kept path is there), so load on the machine falls on both. Reports median, p95 and the
largest time per call of each, and the planner's extra cost; the robot runs at 20 Hz (50 ms a
cycle) and the target is a cycle well under 10 ms.

    python bench/bench_assist_plan.py [--poses N] [--repeats N] [--out FILE.json]
"""

from __future__ import annotations

import argparse
import math
import platform
import statistics
import sys
import time
from dataclasses import replace

import numpy as np
from egc_common.profiles import JACKAL
from egc_experiments.bench_results import write_result
from egc_robot.filters.assist import AssistMemory, AssistParams, assist_step
from egc_sim.lidar import Lidar, LidarConfig
from egc_sim.worlds import load_world

SEEDS = range(5)


def cases(poses_per_world: int, seed: int = 0):
    """(obstacles, via point in {R}) at free poses drawn in each clutter world."""
    rng = np.random.default_rng(seed)
    out = []
    for world_seed in SEEDS:
        world = load_world(f"clutter:{world_seed}", footprint=JACKAL.footprint)
        lidar = Lidar(world, LidarConfig())
        assert world.goal is not None
        gx, gy = world.goal
        found = 0
        while found < poses_per_world:
            pose = (rng.uniform(0.5, 7.5), rng.uniform(0.3, 3.7), rng.uniform(-math.pi, math.pi))
            scan = lidar.scan(pose, rng)
            obs = scan.obstacles()
            if len(obs) == 0 or float(np.sqrt(obs.r2.min())) < JACKAL.half_diagonal_m + 0.03:
                continue  # not a pose the robot could be at with the sweep's margin
            c, s = math.cos(pose[2]), math.sin(pose[2])
            dx, dy = gx - pose[0], gy - pose[1]
            out.append((obs, (c * dx + s * dy, -s * dx + c * dy)))
            found += 1
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--poses", type=int, default=20, help="poses per world (5 worlds)")
    ap.add_argument("--repeats", type=int, default=5, help="timed calls per pose and variant")
    ap.add_argument("--out", help="JSON file (default bench/results/assist_plan.json)")
    args = ap.parse_args(argv)
    planned = AssistParams.from_profile(JACKAL)
    rules = replace(planned, plan_cell_m=0.0)
    inputs = cases(args.poses)
    timings: dict[str, list[float]] = {"planned": [], "rules": []}
    phases: dict[str, int] = {}
    for obs, goal in inputs:
        memories = {}
        for name, params in (("planned", planned), ("rules", rules)):
            first = assist_step(AssistMemory.initial(), 1.0, 0.0, obs, goal, 0, params, JACKAL)
            memories[name] = first.memory
        phases[first.rule] = phases.get(first.rule, 0) + 1
        for k in range(args.repeats):
            for name, params in (("planned", planned), ("rules", rules)):
                now = (k + 1) * 50_000_000
                t0 = time.perf_counter()
                assist_step(memories[name], 1.0, 0.0, obs, goal, now, params, JACKAL)
                timings[name].append(time.perf_counter() - t0)

    def stats(xs: list[float]) -> dict[str, float]:
        ms = sorted(1e3 * x for x in xs)
        return {
            "median_ms": statistics.median(ms),
            "p95_ms": ms[int(0.95 * (len(ms) - 1))],
            "max_ms": ms[-1],
        }

    result = {
        "machine": platform.processor() or platform.machine(),
        "poses": len(inputs),
        "repeats": args.repeats,
        "planned": stats(timings["planned"]),
        "rules": stats(timings["rules"]),
    }
    result["ratio_median"] = result["planned"]["median_ms"] / result["rules"]["median_ms"]
    print(f"assist_step on {len(inputs)} clutter poses x {args.repeats} calls (jackal, 360 beams)")
    for name in ("planned", "rules"):
        s = result[name]
        print(
            f"  {name:<8} median {s['median_ms']:6.2f} ms  p95 {s['p95_ms']:6.2f} ms"
            f"  max {s['max_ms']:6.2f} ms"
        )
    print(f"  planned / rules (median): {result['ratio_median']:.1f}x")
    write_result("assist_plan", result, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
