"""Issue 3 benchmark: one simulation step on MRPB office02, egc_sim against IR-SIM.

One step is what a headless episode does per control cycle, minus the operator: a 360-beam lidar
scan from the current pose, the scan turned into points, the EGC filter
(``egc_robot.filters.egc.egc_filter``) applied to the operator's command, and the filtered
command driven for 0.05 s (profile limits, exact arcs, footprint collision check). The operator
pushes full forward and, whenever the filter has stopped the robot, turns in place to the left
for a cycle (which EGC lets through), so that the robot keeps moving and every step pays for
its collision check. The robot (pioneer3dx, the paper's) starts from each start pose of MRPB's
office02 tests in turn for ``--steps-per-start`` steps.

IR-SIM (``pip install ir-sim``; imported lazily, skipped when absent, not a dependency of the
project) runs the same loop on the same PGM file, the same robot rectangle and a 360-beam lidar:
``env.get_lidar_scan()``, the same ``egc_filter`` call, ``env.step``. The process is pinned to
one core and steps per second are counted in that process's CPU time, so that other load on the
machine does not count (wall-clock rates are reported too). Targets: >= 2,000 steps/s for
egc_sim, and >= 20x IR-SIM's steps/s.

    python bench/bench_sim.py [--steps-per-start N] [--irsim-steps N] [--out FILE.json]
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import re
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from egc_common.profiles import PIONEER3DX
from egc_common.scan import ranges_to_points
from egc_experiments.bench_results import write_result
from egc_robot.filters.egc import EgcParams, egc_filter
from egc_sim.lidar import LidarConfig, Raycaster
from egc_sim.simulator import Simulator
from egc_sim.worlds import WORLDS_DIR, load_world

MAP_DIR = WORLDS_DIR / "office02"
DT_S = 0.05
LIDAR = LidarConfig(beams=360, range_min_m=0.05, range_max_m=10.0)
PROFILE = PIONEER3DX
PARAMS = EgcParams.from_profile(PROFILE.r_min_m, PROFILE.r_max_m, PROFILE.v_max_mps)
FORWARD = (PROFILE.v_max_mps, 0.0)
TURN = (0.0, PROFILE.w_max_radps)


def start_poses() -> list[tuple[float, float, float]]:
    """The initial poses of MRPB's office02 tests (tests.txt)."""
    text = (MAP_DIR / "tests.txt").read_text()
    values = {}
    poses = []
    for key, value in re.findall(r'name="initial_pose_([xya])" default="([-0-9.]+)"', text):
        values[key] = float(value)
        if key == "a":
            poses.append((values["x"], values["y"], values["a"]))
    return poses


def bench_egc_sim(steps_per_start: int) -> dict[str, float]:
    world = load_world("office02")
    sims = [Simulator(world, PROFILE, pose, lidar=LIDAR) for pose in start_poses()]
    for sim in sims:  # warm-up: first calls allocate
        egc_filter(*FORWARD, sim.scan().points(), PARAMS)
    steps = moving = 0
    t0, c0 = time.perf_counter(), time.process_time()
    for sim in sims:
        command = FORWARD
        for _ in range(steps_per_start):
            result = egc_filter(*command, sim.scan().points(), PARAMS)
            sim.step(result.v_mps, result.w_radps, DT_S)
            command = TURN if result.w_si == 0.0 else FORWARD
            steps += 1
            moving += sim.twist != (0.0, 0.0)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    assert not any(sim.collided for sim in sims), "the filter let the robot touch a wall"
    return {
        "steps": steps,
        "wall_s": wall,
        "cpu_s": cpu,
        "steps_per_s": steps / cpu,
        "us_per_step": 1e6 * cpu / steps,
        "wall_steps_per_s": steps / wall,
        "moving_fraction": moving / steps,
        "path_m": sum(sim.path_m for sim in sims),
    }


def _irsim_world(folder: Path, pose: tuple[float, float, float]) -> Path:
    world = load_world("office02")
    path = folder / "office02.yaml"
    path.write_text(
        "world:\n"
        f"  height: {world.height_m}\n  width: {world.width_m}\n"
        f"  step_time: {DT_S}\n  sample_time: {DT_S}\n"
        f"  offset: [{world.origin_x_m}, {world.origin_y_m}]\n"
        "  collision_mode: 'stop'\n  control_mode: 'auto'\n"
        f"  obstacle_map: '{(MAP_DIR / 'map.pgm').resolve()}'\n"
        "robot:\n"
        "  - kinematics: {name: 'diff'}\n"
        f"    shape: {{name: 'rectangle', length: {PROFILE.length_m}, width: {PROFILE.width_m}}}\n"
        f"    state: [{pose[0]}, {pose[1]}, {pose[2]}]\n"
        f"    vel_max: [{PROFILE.v_max_mps}, {PROFILE.w_max_radps}]\n"
        "    sensors:\n"
        "      - name: 'lidar2d'\n"
        f"        range_min: {LIDAR.range_min_m}\n        range_max: {LIDAR.range_max_m}\n"
        f"        angle_range: {2 * math.pi}\n        number: {LIDAR.beams}\n"
        "        noise: False\n"
    )
    return path


def bench_irsim(steps: int) -> dict[str, float] | None:
    os.environ.setdefault("MPLBACKEND", "Agg")  # IR-SIM imports matplotlib; no window wanted
    try:
        import irsim
    except ImportError:
        return None
    pose = start_poses()[0]
    with tempfile.TemporaryDirectory() as tmp:
        env = irsim.make(
            str(_irsim_world(Path(tmp), pose)),
            display=False,
            disable_all_plot=True,
            log_level="WARNING",
        )
    scan = env.get_lidar_scan()
    # Same map, same pose: the two lidars must agree (IR-SIM spreads its beams over
    # [-pi, pi] inclusive; cast ours along its angles).
    ours = Raycaster(load_world("office02")).cast(
        *pose, scan["angle_min"], scan["angle_increment"], LIDAR.beams, LIDAR.range_max_m
    )
    theirs = np.asarray(scan["ranges"], dtype=float)
    both = np.isfinite(ours) & np.asarray(scan["valid"], dtype=bool)
    agreement = float(np.median(np.abs(ours[both] - theirs[both])))

    command = FORWARD

    def step() -> None:
        nonlocal command
        s = env.get_lidar_scan()
        ranges = np.asarray(s["ranges"], dtype=float)
        angles = s["angle_min"] + s["angle_increment"] * np.arange(ranges.size)
        points = ranges_to_points(ranges, angles, s["range_min"], s["range_max"])
        result = egc_filter(*command, points, PARAMS)
        env.step(np.array([[result.v_mps], [result.w_radps]]))
        command = TURN if result.w_si == 0.0 else FORWARD

    step()  # warm-up
    t0, c0 = time.perf_counter(), time.process_time()
    for _ in range(steps):
        step()
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return {
        "steps": steps,
        "wall_s": wall,
        "cpu_s": cpu,
        "steps_per_s": steps / cpu,
        "us_per_step": 1e6 * cpu / steps,
        "wall_steps_per_s": steps / wall,
        "median_range_difference_m": agreement,
        "version": str(getattr(irsim, "__version__", "?")),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps-per-start", type=int, default=1500)
    ap.add_argument("--irsim-steps", type=int, default=60)
    ap.add_argument("--out", help="JSON file (default bench/results/sim.json)")
    args = ap.parse_args(argv)
    cores = os.sched_getaffinity(0) if hasattr(os, "sched_setaffinity") else None
    if cores is not None:
        os.sched_setaffinity(0, {min(cores)})
    try:
        return _run(args)
    finally:
        if cores is not None:  # `egc-teleop bench all` runs the next benchmark in this process
            os.sched_setaffinity(0, cores)


def _run(args: argparse.Namespace) -> int:

    print(
        f"One simulation step on MRPB office02 ({LIDAR.beams}-beam lidar, EGC, kinematics, "
        f"collision), {PROFILE.name}, {platform.processor() or platform.machine()}, "
        f"Python {platform.python_version()}, one core"
    )
    ours = bench_egc_sim(args.steps_per_start)
    theirs = bench_irsim(args.irsim_steps)
    print(f"{'simulator':<10}{'steps':>8}{'steps/s':>12}{'us/step':>12}{'wall steps/s':>14}")
    print(
        f"{'egc_sim':<10}{ours['steps']:>8}{ours['steps_per_s']:>12.0f}{ours['us_per_step']:>12.1f}"
        f"{ours['wall_steps_per_s']:>14.0f}"
    )
    print(
        f"  moving in {100 * ours['moving_fraction']:.0f}% of the steps, "
        f"{ours['path_m']:.1f} m driven"
    )
    targets = {"egc_sim >= 2000 steps/s": ours["steps_per_s"] >= 2000.0}
    ratio = None
    if theirs is None:
        print("IR-SIM not installed (pip install ir-sim): comparison skipped")
    else:
        ratio = ours["steps_per_s"] / theirs["steps_per_s"]
        print(
            f"{'IR-SIM':<10}{theirs['steps']:>8}{theirs['steps_per_s']:>12.1f}"
            f"{theirs['us_per_step']:>12.1f}{theirs['wall_steps_per_s']:>14.1f}"
            f"   (ir-sim {theirs['version']})"
        )
        print(
            "  same map check: median |range difference| "
            f"{theirs['median_range_difference_m']:.3f} m"
        )
        print(f"egc_sim is {ratio:.0f}x faster per step")
        targets[">= 20x IR-SIM"] = ratio >= 20.0
    for name, ok in targets.items():
        print(f"target {name}: {'met' if ok else 'MISSED'}")
    result = {
        "egc_sim": ours,
        "irsim": theirs,
        "ratio": ratio,
        "targets": targets,
        "python": sys.version,
    }
    out = write_result("sim", result, args.out)
    print(f"wrote {out}")
    return 0 if all(targets.values()) else 1


if __name__ == "__main__":
    raise SystemExit(main())
