"""Careful-drive logs of the project's own worlds, and how much each filter would change them.

    python -m egc_experiments.careful_logs --out DIR [--random N] [--seed S] [--mrpb DIR|none]
        [--profile jackal] [--filters none,egc,ek-egc,assist,dwa,cbf] [--jobs J] [--resume]

Issue 28 measures a filter's intervention on careful drives: a driver who keeps the footprint
0.2 m from everything, up to 0.8 m/s on the Jackal, recorded as ROS 2 MCAP logs. This makes such
logs in worlds of our own, the way a user can, and replays them through the filters:

1. **Drive**: the ``careful`` operator model (``egc_sim.careful``) in direct mode (``filter
   none``: nothing helps it) on ``random:S`` .. ``random:S+N-1`` (fresh seeds: 5000 on by
   default, never used to tune anything) and on every MRPB test (``../shared/worlds/mrpb``,
   ``tests.txt`` beside each map) where it finds a path that keeps its clearance; each episode
   written with ``episode --bag`` (``egc_sim.episode_bag``) to ``DIR/logs/NAME.mcap``. A log is
   kept only for a careful drive: it arrived and its footprint never came within the model's
   ``clearance_m`` of anything (the simulator's exact clearance). ``DIR/drives.jsonl`` has one
   line per episode: the episode's JSON, ``log`` (the file, or null) and ``why_not`` when it
   was not kept (the planner's refusal: no path with room to spare; or the outcome).
2. **Replay**: every kept log through each filter of ``--filters`` exactly as ``egc-teleop
   replay LOG --filter F --profile P`` does (``egc_experiments.log_replay``): ``DIR/replay.jsonl``
   has one line per (log, filter) with the replay summary's pinned keys (``scans``,
   ``commands``, ``changed``, ``changed_share``, ``mean_cut``, ``hold_s``, ``closest_m``, ...).
3. **Table**: ``DIR/summary.md``, per filter: logs, commands, commands changed and their share
   over all logs, the median and largest share of one log, the mean cut, the time it would
   have held.

``--resume`` goes on with a run that was stopped: the drives of ``DIR/drives.jsonl`` are kept
and only the replays missing from ``DIR/replay.jsonl`` are made.

The logs are data (a few hundred kB each): keep them out of git; this command makes them again,
the same bytes for the same seeds (the simulator and the model are deterministic).
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing
import signal
import sys
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, TypeVar

from egc_common.errors import UsageError
from egc_common.profiles import get_profile
from egc_robot.pipeline import FILTERS
from egc_robot.replay_core import Replayer
from egc_sim.careful import CarefulParams
from egc_sim.mrpb_tests import TESTS_FILE, parse_tests

from egc_experiments.episode import EpisodeSettings, run_settings
from egc_experiments.log_replay import replay

T = TypeVar("T")
R = TypeVar("R")

MRPB_DIR = Path(__file__).resolve().parents[2].parent / "shared" / "worlds" / "mrpb"
DEFAULT_FILTERS = tuple(
    f for f in ("none", "egc", "ek-egc", "assist", "dwa", "cbf") if f in FILTERS
)
REPLAY_KEYS = (
    "scans",
    "commands",
    "changed",
    "changed_share",
    "mean_cut",
    "max_cut_mps",
    "hold_s",
    "closest_m",
    "duration_s",
)


@dataclass(frozen=True, slots=True)
class Drive:
    """One careful drive to make: its name (the log's file name) and its episode."""

    name: str
    settings: EpisodeSettings


def drives(
    random_worlds: int,
    seed: int,
    profile: str,
    mrpb_dir: Path | None,
    max_time_s: float = 60.0,
    mrpb_max_time_s: float = 300.0,
) -> list[Drive]:
    """The episodes of step 1 (module docstring), random worlds first."""
    out = [
        Drive(
            f"random-{s}",
            EpisodeSettings(
                map=f"random:{s}",
                seed=s,
                operator="careful",
                filter="none",
                profile=profile,
                max_time_s=max_time_s,
            ),
        )
        for s in range(seed, seed + random_worlds)
    ]
    if mrpb_dir is not None:
        for tests in sorted(mrpb_dir.glob(f"*/{TESTS_FILE}")):
            text = tests.read_text(encoding="utf-8", errors="replace")
            for number, test in enumerate(parse_tests(text), start=1):
                out.append(
                    Drive(
                        f"mrpb-{tests.parent.name}-{number}",
                        EpisodeSettings(
                            map=str(tests.parent / "map.yaml"),
                            start=test.start_pose,
                            goal=test.goal_xy_m,
                            operator="careful",
                            filter="none",
                            profile=profile,
                            max_time_s=mrpb_max_time_s,
                        ),
                    )
                )
    return out


def drive(job: tuple[Drive, str, float]) -> dict[str, Any]:
    """Worker: one drive written to ``log``; the log is removed unless it is a careful drive
    (arrived, the footprint never nearer than ``clearance_m``)."""
    d, log, clearance_m = job
    record: dict[str, Any] = {"name": d.name, **_plain(asdict(d.settings))}
    try:
        _, summary = run_settings(d.settings, bag_path=log)
    except UsageError as exc:
        Path(log).unlink(missing_ok=True)
        return {**record, "log": None, "why_not": str(exc)}
    record.update(summary)
    careful = summary["outcome"] == "reached" and summary["min_clearance_m"] >= clearance_m
    if careful:
        return {**record, "log": log, "why_not": None}
    Path(log).unlink(missing_ok=True)
    why = (
        f"min clearance {summary['min_clearance_m']:.3f} m"
        if summary["outcome"] == "reached"
        else summary["outcome"]
    )
    return {**record, "log": None, "why_not": why}


def replay_one(job: tuple[str, str, str]) -> dict[str, Any]:
    """Worker: one log through one filter, as ``egc-teleop replay`` does."""
    log, filter_name, profile_name = job
    replayer = Replayer.for_filter(filter_name, get_profile(profile_name))
    summary = replay(Path(log), replayer, progress=False)
    return {"log": log, "filter": filter_name, **{k: summary.get(k) for k in REPLAY_KEYS}}


def summary_table(rows: Iterable[dict[str, Any]], filters: Sequence[str]) -> str:
    """The Markdown table of step 3 (module docstring)."""
    by_filter: dict[str, list[dict[str, Any]]] = {f: [] for f in filters}
    for row in rows:
        by_filter.setdefault(row["filter"], []).append(row)
    lines = [
        "| filter | logs | commands | changed | changed share | median per log | "
        "largest per log | mean cut | hold (s) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name, items in by_filter.items():
        if not items:
            continue
        commands = sum(r["commands"] for r in items)
        changed = sum(r["changed"] for r in items)
        shares = sorted(r["changed"] / r["commands"] for r in items if r["commands"])
        cuts = [r["mean_cut"] for r in items if r.get("mean_cut") is not None]
        weights = [r["commands"] for r in items if r.get("mean_cut") is not None]
        mean_cut = (
            sum(c * w for c, w in zip(cuts, weights, strict=True)) / sum(weights)
            if weights and sum(weights)
            else math.nan
        )
        median = shares[len(shares) // 2] if shares else math.nan
        lines.append(
            f"| {name} | {len(items)} | {commands} | {changed} | "
            f"{_pct(changed / commands if commands else math.nan)} | {_pct(median)} | "
            f"{_pct(max(shares, default=math.nan))} | {mean_cut:.4f} | "
            f"{sum(r['hold_s'] for r in items):.2f} |"
        )
    return "\n".join(lines) + "\n"


def _drive_all(todo: Sequence[Drive], logs: Path, drives_file: Path, jobs: int) -> list[str]:
    """Step 1 (module docstring): the kept logs, in the order of ``todo``."""
    clearance_m = CarefulParams().clearance_m  # what the drives are kept to
    t0 = time.perf_counter()
    kept: list[str] = []
    work = [(d, str(logs / f"{d.name}.mcap"), clearance_m) for d in todo]
    with drives_file.open("w", encoding="utf-8") as f:
        for record in _map(drive, work, jobs):
            f.write(json.dumps(record, allow_nan=False) + "\n")
            f.flush()
            if record["log"] is not None:
                kept.append(record["log"])
            print(
                f"{record['name']}: "
                + (f"kept ({record['time_s']:.1f} s)" if record["log"] else record["why_not"]),
                file=sys.stderr,
            )
    print(
        f"careful_logs: {len(kept)} careful logs of {len(todo)} drives in {logs} "
        f"({time.perf_counter() - t0:.0f} s)",
        file=sys.stderr,
    )
    return kept


def _kept_logs(drives_file: Path) -> list[str]:
    records = [json.loads(line) for line in drives_file.read_text().splitlines() if line]
    return [r["log"] for r in records if r.get("log") and Path(r["log"]).exists()]


def _done_replays(replay_file: Path) -> list[dict[str, Any]]:
    if not replay_file.exists():
        return []
    rows = []
    for line in replay_file.read_text().splitlines():
        try:
            rows.append(json.loads(line))
        except json.JSONDecodeError:  # a line cut short when the run was stopped
            continue
    return rows


def _pct(share: float) -> str:
    return "-" if math.isnan(share) else f"{100 * share:.1f}%"


def _plain(d: dict[str, Any]) -> dict[str, Any]:
    return {k: list(v) if isinstance(v, tuple) else v for k, v in d.items() if v is not None}


def _worker_init() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to answer


def _pool(jobs: int) -> ProcessPoolExecutor:
    ctx = multiprocessing.get_context("forkserver" if sys.platform == "linux" else "spawn")
    return ProcessPoolExecutor(jobs, mp_context=ctx, initializer=_worker_init)


def _map(fn: Callable[[T], R], items: Sequence[T], jobs: int) -> Iterator[R]:
    """``fn`` over ``items``, results in order: in this process at ``--jobs 1`` or for a single
    item (a worker would only add its start-up: a fresh interpreter importing numpy, scipy and
    the filters), else in ``jobs`` worker processes."""
    if jobs <= 1 or len(items) <= 1:
        yield from map(fn, items)
        return
    with _pool(min(jobs, len(items))) as pool:
        yield from pool.map(fn, items)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m egc_experiments.careful_logs",
        description="Careful-drive ROS 2 logs of our own worlds and the filters' intervention "
        "on them (issue 28).",
    )
    p.add_argument("--out", required=True, help="folder for logs/, drives.jsonl, replay.jsonl")
    p.add_argument("--random", type=int, default=50, help="random worlds (50)")
    p.add_argument("--seed", type=int, default=5000, help="first random world's seed (5000)")
    p.add_argument(
        "--mrpb", default=str(MRPB_DIR), help="MRPB folder (maps with tests.txt), or none"
    )
    p.add_argument("--profile", default="jackal", help="robot profile (jackal)")
    p.add_argument(
        "--filters",
        default=",".join(DEFAULT_FILTERS),
        help=f"filters to replay the logs through ({','.join(DEFAULT_FILTERS)})",
    )
    p.add_argument("--jobs", type=int, default=2, help="worker processes (2)")
    p.add_argument(
        "--resume",
        action="store_true",
        help="go on with an interrupted run in --out: keep its drives, replay what is missing",
    )
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    filters = [f.strip() for f in args.filters.split(",") if f.strip()]
    unknown = [f for f in filters if f not in FILTERS]
    if unknown or args.random < 0 or args.jobs < 1:
        print(
            f"careful_logs: filters must be among {', '.join(FILTERS)}; --random >= 0 and "
            "--jobs >= 1",
            file=sys.stderr,
        )
        return 2
    try:
        get_profile(args.profile)
    except ValueError as exc:
        print(f"careful_logs: --profile: {exc}", file=sys.stderr)
        return 2
    out = Path(args.out)
    logs = out / "logs"
    logs.mkdir(parents=True, exist_ok=True)
    mrpb = None if args.mrpb == "none" else Path(args.mrpb)
    if mrpb is not None and not mrpb.is_dir():
        print(f"careful_logs: --mrpb {mrpb}: no such folder (or give none)", file=sys.stderr)
        return 2
    todo = drives(args.random, args.seed, args.profile, mrpb)
    drives_file = out / "drives.jsonl"
    if args.resume and drives_file.exists():
        kept = _kept_logs(drives_file)
        print(f"careful_logs: resuming with the {len(kept)} logs of {drives_file}", file=sys.stderr)
    else:
        taken = [d.name for d in todo if (logs / f"{d.name}.mcap").exists()]
        if taken:
            print(
                f"careful_logs: {logs} already holds {len(taken)} of these logs (e.g. "
                f"{taken[0]}.mcap): give another --out, --resume, or remove them",
                file=sys.stderr,
            )
            return 2
        kept = _drive_all(todo, logs, drives_file, args.jobs)
    replay_file = out / "replay.jsonl"
    rows = _done_replays(replay_file) if args.resume else []
    done = {(r["log"], r["filter"]) for r in rows}
    with replay_file.open("w", encoding="utf-8") as f:
        for row in rows:  # a resumed run's, written again whole (its last line may be cut)
            f.write(json.dumps(row, allow_nan=False) + "\n")
        jobs = [
            (log, name, args.profile) for name in filters for log in kept if (log, name) not in done
        ]
        for row in _map(replay_one, jobs, args.jobs):
            rows.append(row)
            f.write(json.dumps(row, allow_nan=False) + "\n")
            f.flush()
    rows = [r for r in rows if r["filter"] in filters and r["log"] in set(kept)]
    table = summary_table(rows, filters)
    (out / "summary.md").write_text(
        f"Careful drives ({args.profile}, {len(kept)} logs: random:{args.seed}.."
        f"{args.seed + args.random - 1} and MRPB tests with a careful path), replayed per "
        "filter (`python -m egc_experiments.careful_logs`).\n\n" + table,
        encoding="utf-8",
    )
    print(table, end="")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
