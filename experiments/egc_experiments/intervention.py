"""``docs/intervention.md``: the filter family's intervention, safety and cost in one table
(issue 28 item 4; DESIGN 13), made by one command:

    python -m egc_experiments.intervention --out docs/intervention [--quick] [--jobs N]
        [--reuse] [--cache DIR] [--worlds 10] [--dwa-worlds 5] [--careful-worlds 20]
        [--first-world 6000] [--delays 0,500]

It composes the pieces that measure each part, and reimplements none of them:

1. **Careful drives, own worlds**: ``egc_experiments.careful_logs`` (the ``careful`` operator in
   direct mode on ``random:S``.., each drive written as a ROS 2 MCAP log, kept only when it
   arrived with its clearance, then replayed per filter as ``egc-teleop replay`` does). The logs
   go to the cache (``--cache``, never into git); ``OUT/careful-drives.jsonl`` and
   ``OUT/careful.jsonl`` are its ``drives.jsonl`` and ``replay.jsonl``.
2. **Mapping1**: ``../shared/bags/Mapping1.bag`` (a third party's log) replayed per filter with
   the ``jackal`` profile (``careful_logs.replay_one``, the engine of ``egc-teleop replay``;
   docs/replay.md): ``OUT/mapping1.jsonl``.
3. **Closed loop**: an experiment grid (DESIGN 10), written to ``OUT/grid.toml`` and run in
   ``simulated`` mode by ``experiment_cli.run_grid`` into ``OUT/closed-loop/runs.jsonl``
   (``egc-teleop experiment --grid OUT/grid.toml --out OUT/closed-loop`` runs the same): the
   ``goal`` operator, the ``sighted`` operator at each of ``--delays`` one-way, and the
   ``careful`` operator, per filter, on the Jackal in ``random`` worlds (``dwa``, 10 times
   slower per call, on the first ``--dwa-worlds`` of them).
4. **Cost per call**: ``bench/bench_filter.py`` (``egc-teleop bench filter``) in its own
   process: ``OUT/bench_filter.json``; each filter's median per call at 720 points relative to
   EGC's in the same run.

Then ``OUT.md`` (``docs/intervention.md`` for ``--out docs/intervention``): the table, every
number computed here from those files (``table_rows``), and how it was made (command, machine,
date, commit, code hash, worlds and seeds, wall time per part; also ``OUT/made.json``).

Seeds: random worlds from 6000 on by default, held out: cbf's parameters were set on seeds
0-1019, the careful-log default is 5000 on, the sweeps of issues 28 and 29 use 7000-8599.

``--reuse`` keeps the results already in OUT when they were made by the same sources (a hash of
the robot, simulator, common and experiment code) and runs only what is missing (a stopped run
goes on): the careful drives and the bench when their scale is the same, every closed-loop
episode of the grid (a smaller scale reuses what a larger one ran); without it every part runs
again. ``--quick`` is a tiny scale
for the test (1 careful world, 1 world per closed-loop cell, short episodes, few bench calls).
"""

from __future__ import annotations

import argparse
import datetime
import hashlib
import json
import os
import shlex
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from egc_common.errors import UsageError
from egc_common.profiles import get_profile
from egc_robot.pipeline import FILTERS

from egc_experiments import arena, careful_logs
from egc_experiments.bench_results import commit_record, machine_record
from egc_experiments.experiment_cli import check_point, run_grid, run_key
from egc_experiments.grid import GridError, load_grid

ROOT = Path(__file__).resolve().parents[2]
MAPPING1 = ROOT.parent / "shared" / "bags" / "Mapping1.bag"
PROFILE = "jackal"
FAMILY = ("none", "egc", "ek-egc", "assist", "dwa", "cbf")
SLOW_FILTERS = ("dwa",)  # on the first --dwa-worlds only
# The bench's rows for each filter at 720 points: the Jackal's cases, the most expensive one.
BENCH_ROWS = {
    "egc": ("egc",),
    "ek-egc": ("ek-egc",),
    "dwa": ("dwa jackal",),
    "cbf": ("cbf jackal", "cbf jackal 2"),
}
BENCH_POINTS = 720
# Sources the results depend on, beyond arena.code_hash's robot, simulator, common and episode.
CODE_FILES = (
    "experiments/egc_experiments/careful_logs.py",
    "experiments/egc_experiments/log_replay.py",
    "experiments/egc_experiments/simulated.py",
    "experiments/egc_experiments/run_point.py",
    "experiments/egc_experiments/link_model.py",
    "experiments/egc_experiments/grid.py",
    "bench/bench_filter.py",
)
CAREFUL_DRIVES = "careful-drives.jsonl"
CAREFUL = "careful.jsonl"
MAPPING = "mapping1.jsonl"
GRID = "grid.toml"
CLOSED = "closed-loop"
BENCH = "bench_filter.json"
MADE = "made.json"


@dataclass(frozen=True, slots=True)
class Scale:
    """How much is run: the same scale and sources make the same results (``--reuse``)."""

    careful_worlds: int
    worlds: int
    dwa_worlds: int
    first_world: int
    delays_ms: tuple[float, ...]
    max_time_s: float
    stall_time_s: float
    bench_repeats: int

    @property
    def careful_seeds(self) -> range:
        return range(self.first_world, self.first_world + self.careful_worlds)

    def seeds(self, filter_name: str) -> range:
        n = self.dwa_worlds if filter_name in SLOW_FILTERS else self.worlds
        return range(self.first_world, self.first_world + n)


# 20 worlds per cell (dwa 10) had made 222 of its 440 episodes after 30 min at --jobs 1 on the 2
# shared cores at load 10-12, with more than 45 min to go: 10 (dwa 5) is the default.
FULL = Scale(20, 10, 5, 6000, (0.0, 500.0), 150.0, 30.0, 2000)
QUICK = Scale(1, 1, 1, 6000, (0.0, 500.0), 10.0, 4.0, 20)  # for the test: minutes, not more


def columns(delays_ms: Sequence[float]) -> list[tuple[str, float]]:
    """The closed-loop columns: (operator, one-way delay ms)."""
    return [("goal", 0.0), *(("sighted", d) for d in delays_ms), ("careful", 0.0)]


# ---------------------------------------------------------------------------------------------
# The closed-loop grid


def grid_toml(scale: Scale, filters: Sequence[str]) -> str:
    """The experiment grid of part 3 (module docstring) as TOML: a sweep per column, and one
    more per column for the slow filters on their fewer worlds."""

    def seeds(r: range) -> str:
        return "[" + ", ".join(str(s) for s in r) + "]"

    fast = [f for f in filters if f not in SLOW_FILTERS]
    slow = [f for f in filters if f in SLOW_FILTERS]
    lines = [
        "# Made by python -m egc_experiments.intervention (docs/intervention.md); run it alone with",
        "#   egc-teleop experiment --grid GRID.toml --out DIR --mode simulated",
        'description = """',
        "Issue 28's closed loop for docs/intervention.md: the goal operator, the sighted operator at "
        + ", ".join(f"{d:g}" for d in scale.delays_ms)
        + " ms one-way delay and the careful operator drive the Jackal through held-out random "
        f'worlds (seeds {scale.first_world} on) with every filter of the family."""',
        "",
        'world = "random"',
        f'profile = "{PROFILE}"',
        "link_aware = true",
        f"max_time_s = {scale.max_time_s:g}",
        f"stall_time_s = {scale.stall_time_s:g}",
    ]
    for operator, delay in _grid_cells(scale.delays_ms):
        for group in (fast, slow):
            if not group:
                continue
            lines += [
                "",
                "[[sweep]]",
                f'name = "{operator}, {"/".join(group)}, {"/".join(f"{d:g}" for d in delay)} ms"',
                f'operator = "{operator}"',
                "filter = [" + ", ".join(f'"{f}"' for f in group) + "]",
                "delay_ms = [" + ", ".join(f"{d:g}" for d in delay) + "]",
                f"seeds = {seeds(scale.seeds(group[0]))}",
            ]
    return "\n".join(lines) + "\n"


def _grid_cells(delays_ms: Sequence[float]) -> list[tuple[str, tuple[float, ...]]]:
    return [("goal", (0.0,)), ("sighted", tuple(delays_ms)), ("careful", (0.0,))]


# ---------------------------------------------------------------------------------------------
# The table (pure: rows in, cells out)


def _share(rows: Sequence[dict[str, Any]]) -> tuple[int, int, float | None]:
    commands = sum(r["commands"] for r in rows)
    changed = sum(r["changed"] for r in rows)
    return changed, commands, (changed / commands if commands else None)


def _mean_cut(rows: Sequence[dict[str, Any]], commands_key: str = "commands") -> float | None:
    """Mean of DESIGN 13's ``mean_cut`` over every command of the rows (weighted by commands)."""
    rows = [r for r in rows if r.get("mean_cut") is not None and r.get(commands_key)]
    total = sum(r[commands_key] for r in rows)
    return sum(r["mean_cut"] * r[commands_key] for r in rows) / total if total else None


def pct(share: float | None) -> str:
    return "–" if share is None else f"{100 * share:.1f}%"


def cut(value: float | None) -> str:
    return "–" if value is None else f"{value:.3f}"


def outcome_cell(rows: Sequence[dict[str, Any]]) -> str:
    """Arrived of episodes, and collisions: ``18/20, 0``."""
    if not rows:
        return "–"
    reached = sum(bool(r["reached"]) for r in rows)
    collided = sum(bool(r["collided"]) for r in rows)
    return f"{reached}/{len(rows)}, {collided}"


def bench_cells(bench: dict[str, Any] | None, filter_name: str) -> tuple[str, str]:
    """(x egc, us) at 720 points for a filter, from bench_filter's result: the slowest of its
    Jackal rows (``BENCH_ROWS``); dashes for a filter the bench does not time."""
    names = BENCH_ROWS.get(filter_name)
    if bench is None or names is None:
        return "–", "–"
    egc = next(r for r in bench["rows"] if r["points"] == BENCH_POINTS)["median_us"]
    if filter_name == "egc":
        return "1.0x", f"{egc:.0f}"
    found = [r for r in bench["family"] if r["filter"] in names and r["points"] == BENCH_POINTS]
    if not found:
        return "–", "–"
    # The ratio the bench measured call for call, alternately with EGC on the same scan: a
    # median of another minute (the EGC row's) would set two loads against each other.
    worst = max(found, key=lambda r: r["ratio_to_egc"])
    return f"{worst['ratio_to_egc']:.1f}x", f"{worst['median_us']:.0f}"


def table_rows(
    filters: Sequence[str],
    careful: Sequence[dict[str, Any]],
    mapping1: Sequence[dict[str, Any]],
    closed: Sequence[dict[str, Any]],
    bench: dict[str, Any] | None,
    delays_ms: Sequence[float],
) -> list[list[str]]:
    """One row of cells per filter (``header`` names them), from the parts' records."""
    out = []
    for f in filters:
        mine = [r for r in careful if r["filter"] == f]
        theirs = [r for r in mapping1 if r["filter"] == f]
        loop = [r for r in closed if r["filter"] == f]
        cells = [f"`{f}`", pct(_share(mine)[2]), cut(_mean_cut(mine)), pct(_share(theirs)[2])]
        for operator, delay in columns(delays_ms):
            cells.append(
                outcome_cell(
                    [r for r in loop if r["operator"] == operator and r["delay_ms"] == delay]
                )
            )
        careful_loop = [r for r in loop if r["operator"] == "careful" and "changed" in r]
        changed = sum(r["changed"] for r in careful_loop)
        commands = sum(r["filter_commands"] for r in careful_loop)
        cells.append(pct(changed / commands if commands else None))
        cells += bench_cells(bench, f)
        out.append(cells)
    return out


def header(delays_ms: Sequence[float]) -> list[str]:
    names = {"goal": "goal operator", "careful": "careful operator"}
    loop = [
        f"{names[op]} (arrived, collisions)" if op != "sighted" else f"sighted, {d:g} ms"
        for op, d in columns(delays_ms)
    ]
    return [
        "filter",
        "careful drives: changed",
        "careful drives: mean cut",
        "Mapping1: changed",
        *loop,
        "careful operator, closed loop: changed",
        f"cost per call (x egc, {BENCH_POINTS} points)",
        f"us per call ({BENCH_POINTS} points)",
    ]


def markdown_table(head: Sequence[str], rows: Iterable[Sequence[str]]) -> list[str]:
    return [
        "| " + " | ".join(head) + " |",
        "|" + "---|" * len(head),
        *("| " + " | ".join(r) + " |" for r in rows),
    ]


# ---------------------------------------------------------------------------------------------
# Reading the parts


def read_jsonl(path: Path) -> list[dict[str, Any]]:
    """The complete lines of a JSON-lines file (a line cut short by a stopped run is left out)."""
    if not path.exists():
        return []
    rows = []
    for line in path.read_text(encoding="utf-8").splitlines():
        try:
            row = json.loads(line)
        except json.JSONDecodeError:
            continue
        if isinstance(row, dict):
            rows.append(row)
    return rows


def read_parts(
    out: Path,
) -> tuple[list[dict[str, Any]], list[dict[str, Any]], list[dict[str, Any]], dict[str, Any] | None]:
    bench_path = out / BENCH
    bench = json.loads(bench_path.read_text(encoding="utf-8")) if bench_path.exists() else None
    return (
        read_jsonl(out / CAREFUL),
        read_jsonl(out / MAPPING),
        read_jsonl(out / CLOSED / "runs.jsonl"),
        bench,
    )


def grid_runs(out: Path, rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """The episodes of OUT/grid.toml, one per run point in grid order (the last line of a key
    wins, as in ``egc-teleop experiment``'s resume; a larger scale's other episodes are left
    out)."""
    by_key = {r["key"]: r for r in rows if isinstance(r.get("key"), str)}
    keys = [run_key("simulated", p) for p in load_grid(out / GRID).points]
    return [by_key[k] for k in keys if k in by_key]


# ---------------------------------------------------------------------------------------------
# Running the parts (IO)


def code_hash() -> str:
    h = hashlib.sha256(arena.code_hash().encode())
    for name in CODE_FILES:
        h.update(name.encode())
        h.update((ROOT / name).read_bytes())
    return h.hexdigest()[:12]


def _log(text: str) -> None:
    print(f"intervention: {text}", file=sys.stderr, flush=True)


def run_careful(
    out: Path, cache: Path, scale: Scale, filters: Sequence[str], jobs: int, reuse: bool
) -> None:
    """Part 1: careful_logs into the cache (the MCAP logs stay there), its two files to OUT
    with each log named by its file name (the cache's path means nothing in git)."""
    work = cache / "careful"
    resume = reuse and (work / "drives.jsonl").exists()
    argv = [
        "--out",
        str(work),
        "--random",
        str(scale.careful_worlds),
        "--seed",
        str(scale.first_world),
        "--mrpb",
        "none",
        "--profile",
        PROFILE,
        "--filters",
        ",".join(filters),
        "--jobs",
        str(jobs),
    ]
    code = careful_logs.main([*argv, "--resume"] if resume else argv)
    if code != 0:
        raise UsageError(f"careful_logs {' '.join(argv)} failed (exit {code})")
    for src, dst in (("drives.jsonl", CAREFUL_DRIVES), ("replay.jsonl", CAREFUL)):
        rows = read_jsonl(work / src)
        with (out / dst).open("w", encoding="utf-8") as fh:
            for r in rows:
                if r.get("log"):
                    r["log"] = Path(r["log"]).name
                fh.write(json.dumps(r, allow_nan=False) + "\n")


def careful_complete(out: Path, filters: Sequence[str]) -> bool:
    drives = read_jsonl(out / CAREFUL_DRIVES)
    kept = {r["log"] for r in drives if r.get("log")}
    done = {(r["log"], r["filter"]) for r in read_jsonl(out / CAREFUL)}
    return bool(drives) and all((log, f) in done for log in kept for f in filters)


def run_mapping1(out: Path, bag: Path, filters: Sequence[str]) -> None:
    """Part 2: the filters Mapping1 lacks in OUT/mapping1.jsonl, appended as each ends."""
    done = {r["filter"] for r in read_jsonl(out / MAPPING)}
    for f in filters:
        if f in done:
            continue
        t0 = time.perf_counter()
        row = careful_logs.replay_one((str(bag), f, PROFILE))
        row["log"] = bag.name
        with (out / MAPPING).open("a", encoding="utf-8") as fh:
            fh.write(json.dumps(row, allow_nan=False) + "\n")
        _log(f"Mapping1 {f}: {pct(row['changed_share'])} ({time.perf_counter() - t0:.0f} s)")


def run_closed_loop(out: Path, scale: Scale, filters: Sequence[str], jobs: int) -> None:
    """Part 3: the grid written to OUT/grid.toml and run (resuming what runs.jsonl holds)."""
    grid_path = out / GRID
    grid_path.write_text(grid_toml(scale, filters), encoding="utf-8")
    try:
        grid = load_grid(grid_path, check_point=check_point)
    except GridError as exc:
        raise UsageError(str(exc)) from None
    (out / CLOSED).mkdir(exist_ok=True)
    rows, new, errors = run_grid(grid, out / CLOSED, "simulated", jobs)
    _log(f"closed loop: {len(rows)} of {len(grid.points)} episodes ({new} new)")
    if errors:
        raise UsageError(f"{len(errors)} closed-loop runs failed; see {out / CLOSED}/errors.log")


def run_bench(out: Path, repeats: int) -> None:
    """Part 4: ``egc-teleop bench filter`` in its own process (its exit code says whether its
    targets were met, which is a result here, not a failure)."""
    paths = [ROOT / d for d in ("common", "robot", "operator", "sim_robot", "experiments")]
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(
        [*(str(p) for p in paths), str(ROOT), *filter(None, [env.get("PYTHONPATH")])]
    )
    cmd = [sys.executable, "-m", "egc_app.cli", "bench", "filter"]
    cmd += ["--repeats", str(repeats), "--out", str(out / BENCH)]
    proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True)
    if not (out / BENCH).exists():
        raise UsageError(f"bench filter wrote no result (exit {proc.returncode}): {proc.stderr}")


# ---------------------------------------------------------------------------------------------
# The page


def write_page(page: Path, out: Path, made: dict[str, Any]) -> None:
    scale = Scale(**{**made["scale"], "delays_ms": tuple(made["scale"]["delays_ms"])})
    filters = made["filters"]
    careful, mapping1, closed, bench = read_parts(out)
    closed = grid_runs(out, closed)
    drives = read_jsonl(out / CAREFUL_DRIVES)
    kept = [r for r in drives if r.get("log")]
    rel = os.path.relpath(out, page.parent)
    rows = table_rows(filters, careful, mapping1, closed, bench, scale.delays_ms)
    commands = sum(r["commands"] for r in careful if r["filter"] == filters[0])
    m1 = next((r for r in mapping1 if r["filter"] == filters[0]), None)
    first, s = scale.first_world, scale
    loop_n = {f: len({r["seed"] for r in closed if r["filter"] == f}) for f in filters}
    machine, run = made["machine"], made["run"]
    bench_run = (bench or {}).get("run", {})
    lines = [
        "# Intervention, safety and cost across the filter family",
        "",
        "Issue 28 (DESIGN 13): a safety layer that rewrites a careful operator's commands gets "
        "switched off. Each filter of the family, on the Jackal, in one table: how much it "
        "changes careful drives (logs of our own worlds, and a third party's log), whether it "
        "keeps model operators from collisions and still lets them arrive, with and without "
        "link delay, and what a call costs. Every number below is computed from the files in "
        f"[`{rel}/`]({rel}/) by the command at the end.",
        "",
        *markdown_table(header(scale.delays_ms), rows),
        "",
        "Columns:",
        "",
        f"- **careful drives**: {len(kept)} careful drives of {len(drives)} worlds "
        f"(`random:{first}`..`random:{first + s.careful_worlds - 1}`; a drive is kept when it "
        f"arrived with the footprint never within 0.2 m of anything), {commands} commands, "
        "written as ROS 2 MCAP logs and replayed through each filter as `egc-teleop replay LOG "
        f"--filter F --profile {PROFILE}` does: the share of commands changed over all logs, and "
        "DESIGN 13's mean cut, mean over commands of |dv|/v_max + |dw|/w_max "
        f"(`{CAREFUL}`, `{CAREFUL_DRIVES}`).",
        "- **Mapping1**: `../shared/bags/Mapping1.bag` (Stage, a third party's drive, "
        f"{m1['commands'] if m1 else '–'} commands from its poses) with the `{PROFILE}` profile "
        f"(`{MAPPING}`; docs/replay.md).",
        "- **closed loop**: arrived / episodes, collisions, in `--mode simulated` experiments "
        f"(`{GRID}`, `{CLOSED}/runs.jsonl`) on the Jackal in random worlds "
        f"`random:{first}`.. ({', '.join(f'`{f}` {loop_n[f]}' for f in filters)} worlds), "
        "link-aware driving on, each episode ending at the goal, at a contact, stalled (no "
        f"0.1 m of progress in {s.stall_time_s:g} s) or after {s.max_time_s:g} s. `goal`: "
        "steers straight at the goal (the via point, which `assist` and `dwa` use), blind to "
        "obstacles; `sighted`: sees only the operator view, as late as the link delivers it, "
        "and steers through the free direction nearest the goal (0.25 s reaction time, "
        "steering noise); `careful`: plans with 0.2 m clearance and drives smoothly. `none` is "
        "direct mode: what the operator alone would do. The careful operator's *changed* is "
        "the share of its commands the filter and the sweep changed in closed loop.",
        "- **cost per call**: `egc-teleop bench filter` in its own process (`bench_filter.json`): "
        f"at {BENCH_POINTS} scan points, each call timed alternately with an EGC call on the "
        "same scan, the ratio of their medians (`ratio_to_egc`; `egc` with the Pioneer's radii "
        "on the bench's room scan; `dwa` and `cbf` with the Jackal, for `cbf` the slower of its "
        "1.2 and 2 m/s cases); us per call is the filter's median. `assist` is not timed by the "
        "bench; `none` computes nothing.",
        "",
        "## How it was made",
        "",
        "```sh",
        made["command"],
        "```",
        "",
        f"- date: {made['started']} to {made.get('finished', '(not finished)')} (UTC); wall "
        + ", ".join(f"{k} {v:.0f} s" for k, v in made.get("wall_s", {}).items()),
        f"- commit `{run['commit']}`"
        + (" with local changes" if run.get("dirty") else "")
        + f"; sources hash `{made['code']}` (robot, simulator, common, experiment code)",
        f"- machine: {machine['cpu']}, {machine['cores']} cores ({machine['cores_usable']} "
        f"usable), {machine['platform']}, Python {machine['python']}; {made['jobs']} worker "
        f"process(es); load average at the start {made['load_start']}, at the end "
        f"{made.get('load_end', '–')}"
        + (
            f" (the bench ran at {bench_run['load_average']})"
            if bench_run.get("load_average")
            else ""
        ),
        f"- worlds and seeds: random worlds from seed {first} on, held out (never used to tune "
        "anything: cbf's parameters were set on seeds 0-1019; other runs use 5000-5049 and "
        "7000-8599); the closed-loop episode's seed is its world's seed.",
        f"- scale: {s.careful_worlds} careful drives, {s.worlds} worlds per closed-loop cell "
        f"(`dwa` {s.dwa_worlds}), sighted at "
        + ", ".join(f"{d:g}" for d in s.delays_ms)
        + f" ms, bench with --repeats {s.bench_repeats}"
        + (f". {made['note']}" if made.get("note") else ""),
        "- the MCAP logs are data and stay out of git: the command makes them again, the same "
        "bytes for the same seeds; `--reuse` keeps the results in "
        f"`{rel}/` that the same sources made (the careful drives and the bench at the same "
        "scale, every episode of the grid) and runs only what is missing.",
        "",
    ]
    page.write_text("\n".join(lines), encoding="utf-8")


# ---------------------------------------------------------------------------------------------
# Command line


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m egc_experiments.intervention",
        description="docs/intervention.md: the filter family's intervention, safety and cost "
        "in one table (issue 28).",
    )
    p.add_argument("--out", required=True, help="folder for the parts' results (the page: OUT.md)")
    p.add_argument("--page", help="the page to write (default OUT.md)")
    p.add_argument("--quick", action="store_true", help="a tiny scale (for the test)")
    p.add_argument("--jobs", type=int, default=1, help="worker processes (1)")
    p.add_argument("--reuse", action="store_true", help="keep results of the same code and scale")
    p.add_argument("--cache", help="folder for the MCAP logs (default: a new temporary folder)")
    p.add_argument("--worlds", type=int, help=f"worlds per closed-loop cell ({FULL.worlds})")
    p.add_argument("--dwa-worlds", type=int, help=f"the same for dwa ({FULL.dwa_worlds})")
    p.add_argument("--careful-worlds", type=int, help=f"careful drives ({FULL.careful_worlds})")
    p.add_argument("--first-world", type=int, help=f"first random world ({FULL.first_world})")
    p.add_argument("--delays", help="the sighted operator's one-way delays, ms (0,500)")
    p.add_argument(
        "--bench-repeats", type=int, help=f"bench filter --repeats ({FULL.bench_repeats})"
    )
    p.add_argument("--mapping1", default=str(MAPPING1), help="the Mapping1 bag")
    p.add_argument("--note", default="", help="a sentence for the page's scale line")
    return p


def scale_from(args: argparse.Namespace) -> Scale:
    base = QUICK if args.quick else FULL
    delays = base.delays_ms
    if args.delays:
        try:
            delays = tuple(float(d) for d in args.delays.split(","))
        except ValueError:
            raise UsageError(f"--delays: a comma list of ms, got {args.delays!r}") from None
    scale = Scale(
        careful_worlds=_given(args.careful_worlds, base.careful_worlds),
        worlds=_given(args.worlds, base.worlds),
        dwa_worlds=_given(args.dwa_worlds, base.dwa_worlds),
        first_world=_given(args.first_world, base.first_world),
        delays_ms=delays,
        max_time_s=base.max_time_s,
        stall_time_s=base.stall_time_s,
        bench_repeats=_given(args.bench_repeats, base.bench_repeats),
    )
    if min(scale.careful_worlds, scale.worlds, scale.dwa_worlds, scale.first_world) < 0 or not (
        scale.careful_worlds and scale.worlds and scale.dwa_worlds and scale.bench_repeats > 0
    ):
        raise UsageError("world counts and --bench-repeats must be >= 1, --first-world >= 0")
    if any(d < 0 for d in delays):
        raise UsageError(f"--delays must be >= 0 ms, got {args.delays!r}")
    return scale


def _given(value: int | None, default: int) -> int:
    return default if value is None else value


def _made_now(args: argparse.Namespace, argv: Sequence[str], scale: Scale) -> dict[str, Any]:
    return {
        "command": "python -m egc_experiments.intervention " + shlex.join(argv),
        "started": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "code": code_hash(),
        "scale": {**asdict(scale), "delays_ms": list(scale.delays_ms)},
        "filters": list(FAMILY),
        "jobs": args.jobs,
        "machine": machine_record(),
        "run": commit_record(ROOT),
        "load_start": [round(x, 2) for x in os.getloadavg()],
        "note": args.note,
        "wall_s": {},
    }


PARTS = ("careful", "mapping1", "closed loop", "bench")
PART_FILES = {
    "careful": (CAREFUL_DRIVES, CAREFUL),
    "mapping1": (MAPPING,),
    "closed loop": (GRID, f"{CLOSED}/runs.jsonl", f"{CLOSED}/errors.log"),
    "bench": (BENCH,),
}


def stale_parts(old: dict[str, Any], new: dict[str, Any]) -> list[str]:
    """The parts whose results in OUT another scale made (same sources). The closed loop is
    never stale: its runs are keyed by their whole run point, and the page reads only the
    grid's own (a smaller scale reuses what a larger one ran)."""
    stale = []
    if (old["careful_worlds"], old["first_world"]) != (new["careful_worlds"], new["first_world"]):
        stale.append("careful")
    if old["bench_repeats"] != new["bench_repeats"]:
        stale.append("bench")
    return stale


def _clear(out: Path, parts: Iterable[str]) -> None:
    """This command's own files of ``parts`` in OUT go (nothing else there is touched)."""
    for part in parts:
        for name in PART_FILES[part]:
            (out / name).unlink(missing_ok=True)


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = build_parser().parse_args(argv)
    try:
        if args.jobs < 1:
            raise UsageError("--jobs must be >= 1")
        scale = scale_from(args)
        bag = Path(args.mapping1)
        if not bag.is_file():
            raise UsageError(f"--mapping1 {bag}: no such file")
        get_profile(PROFILE)
        missing = [f for f in FAMILY if f not in FILTERS]
        if missing:
            raise UsageError(f"filters {', '.join(missing)} are not in this checkout")
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        page = Path(args.page) if args.page else out.with_suffix(".md")
        made = _made_now(args, argv, scale)
        old = json.loads((out / MADE).read_text()) if (out / MADE).exists() else None
        if args.reuse and old and old["code"] == made["code"]:
            # The results' own history: when their making started, and its time so far.
            for key in ("started", "load_start", "wall_s"):
                made[key] = old.get(key, made[key])
            _clear(out, stale_parts(old["scale"], made["scale"]))
            _log(f"reusing the results in {out} (sources {made['code']})")
        else:
            if args.reuse and old:
                _log("the results in OUT were made by other sources: rerunning")
            _clear(out, PARTS)
        (out / MADE).write_text(json.dumps(made, indent=2) + "\n", encoding="utf-8")
        cache = Path(args.cache) if args.cache else Path(tempfile.mkdtemp(prefix="intervention-"))
        if not args.cache:
            _log(f"MCAP logs in {cache}")
        parts: tuple[tuple[str, Callable[[], bool], Callable[[], None]], ...] = (
            (
                "careful",
                lambda: careful_complete(out, FAMILY),
                lambda: _careful(out, cache, scale, args),
            ),
            ("mapping1", lambda: False, lambda: run_mapping1(out, bag, FAMILY)),
            ("closed loop", lambda: False, lambda: run_closed_loop(out, scale, FAMILY, args.jobs)),
            ("bench", lambda: (out / BENCH).exists(), lambda: run_bench(out, scale.bench_repeats)),
        )
        for name, done, run in parts:
            if done():
                continue
            t0 = time.perf_counter()
            _log(f"{name} ...")
            run()
            made["wall_s"][name] = made["wall_s"].get(name, 0.0) + time.perf_counter() - t0
            (out / MADE).write_text(json.dumps(made, indent=2) + "\n", encoding="utf-8")
        made["finished"] = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
        made["load_end"] = [round(x, 2) for x in os.getloadavg()]
        (out / MADE).write_text(json.dumps(made, indent=2) + "\n", encoding="utf-8")
        write_page(page, out, made)
    except UsageError as exc:
        print(f"intervention: error: {exc}", file=sys.stderr)
        return 2
    _log(f"wrote {page}")
    return 0


def _careful(out: Path, cache: Path, scale: Scale, args: argparse.Namespace) -> None:
    run_careful(out, cache, scale, FAMILY, args.jobs, args.reuse)


if __name__ == "__main__":
    raise SystemExit(main())
