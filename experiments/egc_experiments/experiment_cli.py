"""``egc-teleop experiment``: run an experiment grid (DESIGN 10, pinned command line).

    egc-teleop experiment --grid GRID.toml --out DIR [--mode simulated|emulated] [--jobs N]

The grid (``egc_experiments.grid``, format in its docstring and in docs/network-delay.md) is a
TOML file of sweeps, each the full product of its axes: worlds (with start and goal),
operators, filters, modes, transport, delay, jitter (ms or a fraction of the delay), loss,
bursts, outages, link-aware on/off, seeds. For example::

    seeds = 5
    [[sweep]]
    name = "delay"
    world = ["hallway", "random"]
    operator = "sighted"
    filter = ["none", "egc"]
    delay_ms = [0, 100, 200, 500]
    jitter_frac = [0, 0.3]
    link_aware = [true, false]

Every distinct run point runs once (``--mode simulated``: ``egc_experiments.simulated``, one
process on a simulated clock; ``--mode emulated``: ``egc_experiments.emulated.run_emulated``,
the real processes over Zenoh through ``egc-teleop link``), ``--jobs`` at a time in worker
processes, with a progress bar on stderr. Outputs in DIR:

- ``runs.jsonl``: one JSON object per run, appended as each run finishes, with at least the
  pinned keys (``run_point.RESULT_KEYS``), ``key`` (the mode and the run point) and
  ``run_mode``. **Resumable**: a rerun skips the runs whose key is already there; a line cut
  short by an interrupted run is dropped (with a note on stderr) and that run is done again.
- ``report.md``: tables of outcome rates, time, hold time, collisions against delay, loss and
  outage, per filter, mode and link-aware setting (``egc_experiments.report``), for the runs of
  this grid found in runs.jsonl.
- ``*.png``: outcome, time and hold time against delay (and loss, outage), per filter and mode.

A run that fails with an unexpected error is not written to runs.jsonl (so a rerun tries it
again); its error goes to ``DIR/errors.log`` and the exit code is 1. Bad input is one line on
stderr and exit code 2 before anything runs: a malformed grid or link SPEC (e.g. loss on TCP),
an unknown world, filter, operator or profile, an unwritable DIR, ``--mode emulated`` without
its module.
"""

from __future__ import annotations

import argparse
import hashlib
import importlib
import json
import multiprocessing
import os
import shlex
import signal
import sys
import tempfile
import time
import traceback
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any, Final

from egc_common.errors import UsageError
from egc_common.profiles import PROFILES, ProfileError, is_profile_path, load_profile
from egc_robot.pipeline import FILTERS
from egc_sim.operators import make_operator
from egc_sim.simulator import Simulator
from egc_sim.worlds import WorldError, load_world

from egc_experiments.grid import Grid, GridError, load_grid
from egc_experiments.report import PLOT_FILES, write_plots, write_report
from egc_experiments.run_point import RunPoint

RUN_MODES: Final = ("simulated", "emulated")
RUNS: Final = "runs.jsonl"
REPORT: Final = "report.md"
ERRORS: Final = "errors.log"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--grid", required=True, metavar="GRID.toml", help="the grid (TOML)")
    parser.add_argument("--out", required=True, metavar="DIR", help="output directory")
    parser.add_argument(
        "--mode",
        choices=RUN_MODES,
        default="simulated",
        help="simulated (one process, simulated clock; default) or emulated (real processes)",
    )
    parser.add_argument("--jobs", type=int, default=1, metavar="N", help="runs in parallel (1)")


def run_key(run_mode: str, point: RunPoint) -> str:
    """The resume key of a run: the experiment mode and the run point."""
    return f"{run_mode}:{point.key()}"


def check_point(point: RunPoint) -> None:
    """Everything a run needs exists: filter, profile, world (start fits, goal inside the
    map), operator."""
    if point.filter not in FILTERS:
        raise GridError(f"unknown filter {point.filter!r} (known: {', '.join(FILTERS)})")
    if point.profile not in PROFILES and not is_profile_path(point.profile):
        known = ", ".join(sorted(PROFILES))
        raise GridError(f"unknown profile {point.profile!r} (known: {known}; or a FILE.toml)")
    try:
        profile = load_profile(point.profile)  # a built-in name or a FILE.toml (DESIGN 14)
    except ProfileError as exc:
        raise GridError(str(exc)) from None
    try:
        world = load_world(
            point.world,
            seed=point.seed,
            reach_m=profile.footprint.reach_m,
            footprint=profile.footprint,
        )
    except WorldError as exc:
        raise GridError(f"world {point.world!r}: {exc}") from None
    start = point.start or world.start_pose
    goal = point.goal or world.goal
    if start is None or goal is None:
        raise GridError(f"world {point.world!r} has no start or goal of its own: give them")
    outside = world.outside_message(goal, "goal", point.world)
    if outside is not None:
        raise GridError(outside)
    try:
        Simulator(world, profile, start)
    except WorldError as exc:
        raise GridError(f"world {point.world!r}: {exc}") from None
    try:
        make_operator(
            point.operator,
            goal,
            point.mode,
            seed=point.seed,
            world=world,
            start=start,
            half_width_m=profile.half_size_m[1],
            profile=profile,
        )
    except ValueError as exc:  # JoystickFileError and RouteError are ValueErrors
        raise GridError(f"operator {point.operator!r}: {exc}") from None


def _runner(run_mode: str) -> Callable[[RunPoint, Path], dict[str, Any]]:
    if run_mode == "simulated":
        from egc_experiments.simulated import run_simulated

        return lambda point, _workdir: run_simulated(point)
    try:
        module = importlib.import_module("egc_experiments.emulated")
    except ModuleNotFoundError as exc:
        if exc.name != "egc_experiments.emulated":
            raise
        raise UsageError(
            "--mode emulated needs egc_experiments/emulated.py (run_emulated), which this "
            "installation does not have; use --mode simulated"
        ) from None
    runner = getattr(module, "run_emulated", None)
    if not callable(runner):
        raise UsageError("egc_experiments.emulated has no run_emulated(point, workdir)")
    return runner  # type: ignore[no-any-return]


def _check_out_dir(out: Path) -> None:
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {out} exists and is not a directory")
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=out, prefix=".write-test-"):
            pass
    except OSError as exc:
        raise UsageError(f"cannot write to --out {out}: {exc.strerror or exc}") from None
    outputs = (RUNS, REPORT, ERRORS, *PLOT_FILES)
    temporaries = (REPORT + ".tmp", *(Path(n).stem + ".tmp.png" for n in PLOT_FILES))
    for name in outputs + temporaries:
        path = out / name
        if path.is_dir():
            raise UsageError(f"cannot write {path}: it is a directory")
        if name in outputs and path.exists() and not os.access(path, os.W_OK):
            raise UsageError(f"cannot write to {path}: permission denied")


def parse_runs(text: str) -> tuple[dict[str, dict[str, Any]], list[str], int]:
    """runs.jsonl's text: the result lines by key, the lines kept, and how many were unreadable
    (cut short by an interrupted run, or not a result)."""
    done: dict[str, dict[str, Any]] = {}
    kept: list[str] = []
    bad = 0
    for line in text.splitlines():
        if not line.strip():
            continue
        try:
            row = json.loads(line)
        except json.JSONDecodeError:
            bad += 1
            continue
        if not isinstance(row, dict) or not isinstance(row.get("key"), str):
            bad += 1
            continue
        done[row["key"]] = row
        kept.append(line)
    return done, kept, bad


def load_runs(path: Path) -> dict[str, dict[str, Any]]:
    """The complete result lines of runs.jsonl by key; lines cut short are removed from it."""
    if not path.exists():
        return {}
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise UsageError(f"cannot read {path}: {exc}") from None
    done, kept, bad = parse_runs(text)
    if bad or (text and not text.endswith("\n")):
        if bad:
            print(
                f"egc-teleop experiment: dropped {bad} unreadable line(s) of {path} "
                "(an interrupted run?); those runs will run again",
                file=sys.stderr,
            )
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text("".join(line + "\n" for line in kept), encoding="utf-8")
        tmp.replace(path)
    return done


def _work(item: tuple[str, RunPoint, str]) -> tuple[str, dict[str, Any] | None, str | None]:
    """Worker: one run; (key, result line or None, error text or None)."""
    run_mode, point, out = item
    key = run_key(run_mode, point)
    try:
        runner = _runner(run_mode)
        workdir = Path(out) / "work" / hashlib.sha256(key.encode()).hexdigest()[:16]
        result = runner(point, workdir)
    except Exception as exc:
        detail = "".join(traceback.format_exception_only(type(exc), exc)).strip()
        return key, None, f"{detail}\n{traceback.format_exc()}"
    return key, {**result, "run_mode": run_mode, "key": key}, None


def run_grid(
    grid: Grid, out: Path, run_mode: str, jobs: int, progress: bool = True
) -> tuple[list[dict[str, Any]], int, list[str]]:
    """Run what runs.jsonl lacks; returns (the grid's rows in grid order, runs done now, errors)."""
    runs_path = out / RUNS
    done = load_runs(runs_path)
    todo = [p for p in grid.points if run_key(run_mode, p) not in done]
    errors: list[str] = []
    new = 0
    from tqdm import tqdm

    bar = tqdm(
        total=len(grid.points),
        initial=len(grid.points) - len(todo),
        unit="run",
        file=sys.stderr,
        disable=not progress,
        dynamic_ncols=True,
    )
    # Absolute: an emulated run starts its processes in its own work directory.
    items = [(run_mode, p, str(out.absolute())) for p in todo]
    try:
        with runs_path.open("a", encoding="utf-8") as f:
            for key, row, error in _results(items, jobs):
                if row is None:
                    errors.append(f"{key}: {error}")
                    with (out / ERRORS).open("a", encoding="utf-8") as ef:
                        ef.write(f"{time.strftime('%Y-%m-%d %H:%M:%S')} {key}\n{error}\n\n")
                else:
                    f.write(json.dumps(row, allow_nan=False) + "\n")
                    f.flush()
                    done[key] = row
                    new += 1
                bar.update(1)
    finally:
        bar.close()
    rows = [done[k] for k in (run_key(run_mode, p) for p in grid.points) if k in done]
    return rows, new, errors


def _results(
    items: Sequence[tuple[str, RunPoint, str]], jobs: int
) -> Iterator[tuple[str, dict[str, Any] | None, str | None]]:
    if jobs <= 1 or len(items) <= 1:
        for item in items:
            yield _work(item)
        return
    context = multiprocessing.get_context("fork")
    with context.Pool(min(jobs, len(items)), initializer=_stop_on_signals) as pool:
        yield from pool.imap_unordered(_work, items, chunksize=1)


def _stop(signum: int, frame: object) -> None:
    """The first SIGINT or SIGTERM unwinds the run, so that every ``finally`` stops its
    processes and removes its namespaces; later ones (Pool.terminate's SIGTERM after a Ctrl-C,
    a second Ctrl-C) are ignored so that they cannot cut that cleanup short."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    raise SystemExit(128 + signum)


def _stop_on_signals() -> None:
    signal.signal(signal.SIGINT, _stop)
    signal.signal(signal.SIGTERM, _stop)


def _saved(grid: Grid, out: Path, run_mode: str, what: str = "") -> str:
    """How many of the grid's runs are in runs.jsonl, and how to go on."""
    try:  # read only: load_runs would rewrite a file with a cut line
        done = parse_runs((out / RUNS).read_text(encoding="utf-8"))[0]
    except (OSError, UnicodeDecodeError):
        done = {}
    n = sum(run_key(run_mode, p) in done for p in grid.points)
    head = f"{what}: " if what else ""
    return (
        f"{head}{n} of {len(grid.points)} runs saved in {out / RUNS}; the same command again "
        "runs the rest"
    )


def run(args: argparse.Namespace) -> int:
    if args.jobs < 1:
        raise UsageError(f"--jobs must be at least 1, got {args.jobs}")
    _runner(args.mode)  # --mode emulated without its module: exit 2 before anything else
    try:
        grid = load_grid(args.grid, check_point=check_point)
    except GridError as exc:
        raise UsageError(str(exc)) from None
    if not args.out.strip():  # Path("") would be the current directory
        raise UsageError("--out needs a directory name, got an empty one")
    out = Path(args.out)
    _check_out_dir(out)
    t0 = time.perf_counter()
    _stop_on_signals()  # a SIGTERM (timeout, systemd) cleans up like Ctrl-C
    try:
        rows, new, errors = run_grid(grid, out, args.mode, args.jobs)
    except SystemExit:
        print(_saved(grid, out, args.mode, "stopped"), file=sys.stderr)
        raise
    except OSError as exc:  # a full disk, a directory removed under us
        raise UsageError(
            f"cannot write the results: {exc.strerror or exc}; " + _saved(grid, out, args.mode)
        ) from None
    command = "egc-teleop experiment " + " ".join(
        shlex.quote(a)
        for a in ("--grid", str(args.grid), "--out", str(args.out), "--mode", args.mode)
    )
    if args.jobs > 1:
        command += f" --jobs {args.jobs}"
    try:
        plots = write_plots(rows, out)
        write_report(
            rows,
            out / REPORT,
            f"Network-delay experiment: {Path(args.grid).name} ({args.mode})",
            grid.description,
            command,
            plots,
        )
    except OSError as exc:
        raise UsageError(
            f"cannot write the report: {exc.strerror or exc}; " + _saved(grid, out, args.mode)
        ) from None
    wall = time.perf_counter() - t0
    print(
        f"{len(rows)} of {len(grid.points)} runs in {out / RUNS} ({new} new, "
        f"{len(rows) - new} already there) in {wall:.1f} s; report {out / REPORT}"
        + (f"; {len(errors)} failed, see {out / ERRORS}" if errors else ""),
        file=sys.stderr,
    )
    return 1 if errors else 0
