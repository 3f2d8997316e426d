"""``egc-teleop episode``: headless episodes in the simulator, printed as JSON (pinned CLI).

    egc-teleop episode --map PATH --start X,Y,YAW --goal X,Y
        [--operator goal|forward|sighted|route|careful|FILE]
        [--filter none|egc] [--profile NAME|FILE.toml] [--max-time S] [--goal-tolerance M] [--seed N]
        [--stall-time S] [--record OUT.rrd] [--bag OUT.mcap|DIR] --json
    egc-teleop episode --batch SUITE.jsonl | --random-worlds N  [...] [--jobs J] [--out FILE]

The arguments and their wiring only (DESIGN 2): the episode engine is
``egc_experiments.episode`` (what each option does to an episode, the JSON keys, what counts as
an intervention), the suite files and the worker processes ``egc_experiments.episode_batch``.

- ``--filter egc`` runs the robot's pipeline with the EGC filter and the scripted operators
  select ``shared`` mode; ``--filter none`` turns the filter off and they select ``direct``.
- ``--map`` takes a map.yaml, a .toml or .npy world, or a built-in name (``hallway``,
  ``office02``, ``random:SEED``, ``clutter:SEED``); ``--start``/``--goal``/``--goal-tolerance`` default to the
  world's own where it has them.
- ``--via`` gives the filter its via points (DESIGN 7): ``goal`` (the default), ``route`` or
  ``none``.
- ``--record OUT.rrd`` saves the episode as the operator view shows a live run; open it with
  ``rerun OUT.rrd``.
- ``--bag OUT`` writes the episode as a ROS 2 log: ``/scan``, ``/odom`` and the driver's
  ``/cmd_vel`` (the command *before* the filter), stamped with the simulated clock; ``OUT.mcap``
  is one MCAP file, any other name a ROS 2 bag directory. ``egc-teleop replay OUT`` reads it.
- ``--stall-time S`` ends an episode as ``stalled`` once the robot has stood still for S
  simulated seconds; off by default.

The batch form runs episodes in parallel worker processes (``--jobs``, default: all cores),
shows a progress bar on stderr and writes one JSON object per line to ``--out`` (or stdout), in
input order. ``--random-worlds N`` runs ``random:SEED`` for N seeds from ``--seed`` on.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import sys
import time
from dataclasses import replace

from egc_common.cli_args import PROFILE_HELP, check_writable
from egc_common.errors import UsageError
from egc_common.profiles import get_profile
from egc_experiments.episode import (
    DEFAULT_GOAL_TOLERANCE_M,
    VIA_CHOICES,
    EpisodeSettings,
    parse_goal,
    parse_start,
    run_settings,
)
from egc_experiments.episode_batch import run_batch, suite_settings
from egc_robot.pipeline import FILTERS
from egc_sim.episode_bag import BagError, check_bag_path


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--map",
        help="map.yaml, .toml or .npy world, or a built-in name (hallway, office02, "
        "random:SEED, clutter:SEED)",
    )
    parser.add_argument("--start", help="start pose X,Y,YAW (m, m, rad); default: the map's")
    parser.add_argument("--goal", help="goal X,Y (m); default: the map's")
    parser.add_argument(
        "--operator",
        default="goal",
        help="goal | forward | sighted | route | careful | a joystick CSV file (default goal)",
    )
    parser.add_argument(
        "--filter",
        default="egc",
        help=f"{' | '.join(FILTERS)} (default egc; none is direct mode)",
    )
    parser.add_argument(
        "--via",
        default="goal",
        help="via points for the filter: goal (one, at the goal; default) | route (corners of "
        "a route planned on the map) | none",
    )
    parser.add_argument("--profile", default="pioneer3dx", metavar="NAME|FILE", help=PROFILE_HELP)
    parser.add_argument("--max-time", type=float, default=300.0, help="simulated seconds (300)")
    parser.add_argument(
        "--goal-tolerance",
        type=float,
        help=f"metres (default: the map's or {DEFAULT_GOAL_TOLERANCE_M})",
    )
    parser.add_argument("--seed", type=int, default=0, help="world and noise seed (0)")
    parser.add_argument("--dt", type=float, default=0.05, help="control period in s (0.05, 20 Hz)")
    parser.add_argument(
        "--stall-time", type=float, help="end as 'stalled' after S s standing still (default off)"
    )
    parser.add_argument(
        "--record", metavar="OUT.rrd", help="save the episode's operator view (Rerun .rrd)"
    )
    parser.add_argument(
        "--bag",
        metavar="OUT.mcap|DIR",
        help="write the episode as a ROS 2 log: /scan, /odom and the driver's /cmd_vel (before "
        "the filter); OUT.mcap is one MCAP file, another name a bag directory",
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    batch = parser.add_argument_group("batch")
    batch.add_argument("--batch", metavar="SUITE.jsonl", help="run the episodes of a suite file")
    batch.add_argument(
        "--random-worlds", type=int, metavar="N", help="run N random worlds, seeds --seed..."
    )
    batch.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="worker processes")
    batch.add_argument("--out", help="write JSON lines here (default stdout)")


def _settings_from_args(args: argparse.Namespace) -> EpisodeSettings:
    if args.filter not in FILTERS:
        raise UsageError(f"--filter must be one of {', '.join(FILTERS)}, got {args.filter!r}")
    if args.via not in VIA_CHOICES:
        raise UsageError(f"--via must be one of {', '.join(VIA_CHOICES)}, got {args.via!r}")
    try:
        get_profile(args.profile)  # a built-in name or a FILE.toml (DESIGN 14)
    except ValueError as exc:
        raise UsageError(f"--profile: {exc}") from None
    for name, value in (
        ("--max-time", args.max_time),
        ("--dt", args.dt),
        ("--stall-time", 1.0 if args.stall_time is None else args.stall_time),
    ):
        if not (math.isfinite(value) and value > 0):
            raise UsageError(f"{name} must be a positive number, got {value}")
    if args.goal_tolerance is not None and not (
        math.isfinite(args.goal_tolerance) and args.goal_tolerance > 0
    ):
        raise UsageError(f"--goal-tolerance must be a positive number, got {args.goal_tolerance}")
    return EpisodeSettings(
        map=args.map or "",
        start=parse_start(args.start) if args.start is not None else None,
        goal=parse_goal(args.goal) if args.goal is not None else None,
        operator=args.operator,
        filter=args.filter,
        profile=args.profile,
        max_time_s=args.max_time,
        goal_tolerance_m=args.goal_tolerance,
        seed=args.seed,
        dt_s=args.dt,
        stall_time_s=args.stall_time,
        via=args.via,
    )


def run(args: argparse.Namespace) -> int:
    base = _settings_from_args(args)
    if args.batch or args.random_worlds is not None:
        if args.record:
            raise UsageError("--record saves a single episode; it cannot be used with a batch")
        if args.bag:
            raise UsageError("--bag writes a single episode; it cannot be used with a batch")
        return _run_batch(args, base)
    if args.out is not None:
        raise UsageError(
            "--out writes a batch's JSON lines (--batch or --random-worlds); a single episode "
            "prints to stdout"
        )
    if not base.map:
        raise UsageError("--map is required (a map.yaml, a .toml world or a built-in name)")
    if args.record:
        check_writable(args.record, "--record")
    if args.bag:
        try:
            check_bag_path(args.bag)
        except BagError as exc:
            raise UsageError(f"--bag {exc}") from None
    _, summary = run_settings(base, record_path=args.record, bag_path=args.bag)
    if args.bag:
        summary["bag"] = args.bag
    if args.json:
        print(json.dumps(summary, allow_nan=False))
    else:
        print(
            f"{summary['outcome']} after {summary['time_s']:.1f} s simulated, "
            f"{summary['path_m']:.2f} m, min clearance {summary['min_clearance_m']:.3f} m, "
            f"{summary['interventions']} interventions in {summary['steps']} cycles "
            f"({summary['wall_s']:.2f} s wall)"
        )
    return 0


def _run_batch(args: argparse.Namespace, base: EpisodeSettings) -> int:
    if args.batch and args.random_worlds is not None:
        raise UsageError("give either --batch or --random-worlds, not both")
    if args.jobs < 1:
        raise UsageError(f"--jobs must be at least 1, got {args.jobs}")
    if args.out is not None:  # now, not as a traceback after the suite is read or run
        check_writable(args.out, "--out")
    if args.batch:
        suite = suite_settings(args.batch, base)
    else:
        if args.random_worlds < 1:
            raise UsageError(f"--random-worlds must be at least 1, got {args.random_worlds}")
        if args.map or args.start or args.goal:
            raise UsageError("--random-worlds makes its own maps: drop --map/--start/--goal")
        suite = [
            replace(base, map=f"random:{seed}", seed=seed)
            for seed in range(base.seed, base.seed + args.random_worlds)
        ]
    try:
        out = open(args.out, "w", encoding="utf-8") if args.out else sys.stdout  # noqa: SIM115
    except OSError as exc:  # checked above; the folder may have gone since
        raise UsageError(f"--out {args.out}: {exc.strerror or exc}") from None
    counts = {"reached": 0, "collided": 0, "stalled": 0, "timeout": 0, "error": 0}
    t0 = time.perf_counter()
    done = 0
    try:
        with contextlib.closing(run_batch(suite, args.jobs)) as summaries:
            for summary in summaries:
                counts[summary.get("outcome", "error")] += 1
                out.write(json.dumps(summary, allow_nan=False) + "\n")
                out.flush()
                done += 1
    except (KeyboardInterrupt, SystemExit):
        print(
            f"egc-teleop episode: stopped; {done} of {len(suite)} episodes written, "
            "the workers ended",
            file=sys.stderr,
        )
        raise
    finally:
        if out is not sys.stdout:
            out.close()
    print(
        f"{len(suite)} episodes: {counts['reached']} reached, {counts['collided']} collided, "
        f"{counts['stalled']} stalled, {counts['timeout']} timed out, {counts['error']} failed "
        f"({time.perf_counter() - t0:.1f} s wall, {args.jobs} jobs)",
        file=sys.stderr,
    )
    return 2 if counts["error"] else 0
