"""The filter arena (issue 10 item 5) and the assist experiment (issue 11 item 4).

    python -m egc_experiments.arena --out docs/filters --report docs/filters.md
        [--worlds 50] [--jobs 2] [--filters none,egc,...] [--operators goal,sighted]
        [--suites hallway,mrpb,random] [--reuse RUNS.jsonl ...]
    python -m egc_experiments.arena --experiment assist --out docs/assist --report docs/assist.md
        --worlds 100 [--reuse docs/filters/runs.jsonl]

Every filter runs on the same worlds, starts, goals, operators and via points, as headless
episodes of ``egc-teleop episode`` (``episode_batch.run_batch``; the robot's own pipeline):

- ``hallway``: the built-in hallway (pioneer3dx), via point at its goal;
- ``mrpb``: the 19 start/goal tests of ``../shared/worlds/mrpb/*/tests.txt`` (pioneer3dx), via
  points at the corners of a route planned on the map (``--via route``); ``--mrpb-dir`` points
  elsewhere. A suite that finds no world is an error (exit 2), never a run of nothing;
- ``random``: seeded random obstacle fields ``random:0`` ... ``random:N-1`` (jackal, as in the
  issue's "20 obstacle worlds"), via point at the goal.

Each episode ends at the goal, at a contact, after ``STALL_TIME_S`` standing still (stalled), or
at a time limit of ``max(60, 2 * route / v_max + 30)`` s, where ``route`` is the length of the
route planned on the map (timeout). Direct mode is ``--filter none``; every other filter runs in
shared mode. ``DIR/runs.jsonl`` holds one line per episode (the episode JSON plus ``suite``,
``case``, ``route_m``, ``settings`` and ``code``, a hash of the robot, simulator and episode
sources); ``--reuse`` takes episodes from earlier runs with the same settings and code hash
instead of running them again. ``--report`` writes the Markdown tables (and, for ``assist``,
``assist_*.png`` figures next to it).
"""

from __future__ import annotations

import argparse
import hashlib
import itertools
import json
import math
import os
import subprocess
import sys
import time
from collections import defaultdict
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

from egc_common.errors import UsageError
from egc_common.profiles import get_profile
from egc_robot.pipeline import FILTERS
from egc_sim.mrpb_tests import TESTS_FILE, parse_tests
from egc_sim.route import plan_route
from egc_sim.worlds import load_world

from egc_experiments.episode import EpisodeSettings, run_settings
from egc_experiments.episode_batch import run_batch

ROOT = Path(__file__).resolve().parents[2]
MRPB_DIR = ROOT.parent / "shared" / "worlds" / "mrpb"
SUITES = ("hallway", "mrpb", "random")
OPERATORS = ("goal", "sighted")
ARENA_FILTERS = ("none", "egc", "ek-egc", "dwa", "assist")
ASSIST_FILTERS = ("none", "egc", "assist")
STALL_TIME_S = 10.0
MIN_TIME_S = 60.0
SUITE_PROFILE = {"hallway": "pioneer3dx", "mrpb": "pioneer3dx", "random": "jackal"}
# The random worlds' profile: jackal as in issue 10's "20 obstacle worlds" (``egc-teleop
# episode`` itself defaults to pioneer3dx everywhere); ``--random-profile`` changes it.
SUITE_VIA = {"hallway": "goal", "mrpb": "route", "random": "goal"}
CODE_DIRS = ("robot/egc_robot", "sim_robot/egc_sim", "common/egc_common")
CODE_FILES = (
    "experiments/egc_experiments/episode.py",
    "experiments/egc_experiments/episode_batch.py",
)


@dataclass(frozen=True, slots=True)
class Case:
    """One world with its start and goal; the filter and operator are added per episode."""

    suite: str
    name: str
    settings: EpisodeSettings
    route_m: float


# ---------------------------------------------------------------------------------------------
# Cases


def mrpb_tests(
    mrpb_dir: Path = MRPB_DIR,
) -> list[tuple[str, Path, tuple[float, ...], tuple[float, ...]]]:
    """(name, map.yaml, start (x, y, yaw), goal (x, y)) of every MRPB test, in map order."""
    return [
        (
            f"{tests.parent.name}#{number}",
            tests.parent / "map.yaml",
            test.start_pose,
            test.goal_xy_m,
        )
        for tests in sorted(mrpb_dir.glob(f"*/{TESTS_FILE}"))
        for number, test in enumerate(parse_tests(tests.read_text(encoding="utf-8")), start=1)
    ]


def _route_length(settings: EpisodeSettings) -> float:
    profile = get_profile(settings.profile)
    world = load_world(
        settings.map,
        seed=settings.seed,
        reach_m=profile.footprint.reach_m,
        footprint=profile.footprint,
    )
    start = settings.start or world.start_pose
    goal = settings.goal or world.goal
    assert start is not None and goal is not None
    half_width = profile.half_size_m[1]
    route = plan_route(
        world.occupancy, world.resolution_m, world.origin, start[:2], goal, half_width + 0.1
    )
    if len(route) < 2:
        return math.dist(start[:2], goal)
    return float(sum(math.dist(a, b) for a, b in itertools.pairwise(route)))


def time_limit(route_m: float, profile: str) -> float:
    """The episode's time limit (module docstring), in whole seconds."""
    return float(math.ceil(max(MIN_TIME_S, 2.0 * route_m / get_profile(profile).v_max_mps + 30)))


def _case(suite: str, name: str, settings: EpisodeSettings) -> Case:
    route_m = _route_length(settings)
    settings = replace(
        settings,
        via=SUITE_VIA[suite],
        stall_time_s=STALL_TIME_S,
        max_time_s=time_limit(route_m, settings.profile),
    )
    return Case(suite, name, settings, round(route_m, 3))


def build_cases(
    suites: Sequence[str],
    worlds: int,
    mrpb_dir: Path = MRPB_DIR,
    mrpb_limit: int | None = None,
    random_profile: str | None = None,
    first_world: int = 0,
) -> list[Case]:
    """The cases of ``suites``, in order. A suite that finds no world is a UsageError naming
    where it looked (a run of nothing would report 0 collisions: a pass it never earned)."""
    cases: list[Case] = []
    for suite in suites:
        before = len(cases)
        profile = SUITE_PROFILE.get(suite, "")
        if suite == "random" and random_profile:
            profile = random_profile
        if suite == "hallway":
            cases.append(_case(suite, "hallway", EpisodeSettings(map="hallway", profile=profile)))
        elif suite == "mrpb":
            for name, path, start, goal in mrpb_tests(mrpb_dir)[:mrpb_limit]:
                s = EpisodeSettings(
                    map=str(path),
                    start=(start[0], start[1], start[2]),
                    goal=(goal[0], goal[1]),
                    profile=profile,
                    via="route",
                )
                cases.append(_case(suite, name, s))
        elif suite == "random":
            for seed in range(first_world, first_world + worlds):
                s = EpisodeSettings(map=f"random:{seed}", seed=seed, profile=profile)
                cases.append(_case(suite, f"random:{seed}", s))
        else:
            raise UsageError(f"unknown suite {suite!r}; choose from {', '.join(SUITES)}")
        if len(cases) == before:
            raise UsageError(_no_worlds(suite, worlds, mrpb_dir, mrpb_limit))
    return cases


def _no_worlds(suite: str, worlds: int, mrpb_dir: Path, mrpb_limit: int | None) -> str:
    """The one line for a suite that found no world: where it looked, what to change."""
    if suite == "random":
        return f"suite random has no worlds: --worlds is {worlds} (give --worlds N, N >= 1)"
    if mrpb_limit is not None and mrpb_limit <= 0:
        return f"suite mrpb has no worlds: --mrpb-limit is {mrpb_limit} (give 1 or more)"
    where = mrpb_dir.resolve()
    found = "does not exist" if not where.is_dir() else f"has no */{TESTS_FILE}"
    return (
        f"suite mrpb found no worlds: {where} {found} "
        f"(point --mrpb-dir at the MRPB worlds, the folder holding <map>/{TESTS_FILE})"
    )


def episodes(
    cases: Sequence[Case], filters: Sequence[str], operators: Sequence[str]
) -> list[tuple[Case, EpisodeSettings]]:
    """Every case x operator x filter, with the same settings apart from the filter."""
    return [
        (c, replace(c.settings, operator=op, filter=f))
        for c in cases
        for op in operators
        for f in filters
    ]


# ---------------------------------------------------------------------------------------------
# Running


def code_hash(root: Path = ROOT) -> str:
    """A hash of the sources an episode runs (robot, simulator, common, the episode engine)."""
    h = hashlib.sha256()
    paths = [p for d in CODE_DIRS for p in (root / d).rglob("*.py")]
    paths += [root / f for f in CODE_FILES]
    for p in sorted(paths):
        h.update(str(p.relative_to(root)).encode())
        h.update(p.read_bytes())
    return h.hexdigest()[:12]


def settings_key(settings: EpisodeSettings | dict[str, Any]) -> str:
    d = asdict(settings) if isinstance(settings, EpisodeSettings) else settings
    return json.dumps(
        {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}, sort_keys=True
    )


def load_runs(paths: Iterable[str | Path]) -> list[dict[str, Any]]:
    out = []
    for path in paths:
        for line in Path(path).read_text(encoding="utf-8").splitlines():
            if line.strip():
                out.append(json.loads(line))
    return out


def run_arena(
    todo: Sequence[tuple[Case, EpisodeSettings]],
    jobs: int,
    reuse: Sequence[dict[str, Any]] = (),
    progress: bool = True,
    partial: Path | None = None,
    any_code: bool = False,
) -> list[dict[str, Any]]:
    """The records of ``todo`` in order; episodes found in ``reuse`` (same code) are not rerun.

    ``partial``: each fresh episode is appended there as it ends (reusable after a crash).
    """
    code = code_hash()
    known = {
        settings_key(r["settings"]): r
        for r in reuse
        if (any_code or r.get("code") == code) and "settings" in r and "error" not in r
    }
    missing = [s for _, s in todo if settings_key(s) not in known]
    fresh: dict[str, dict[str, Any]] = {}
    fh = open(partial, "w", encoding="utf-8") if partial else None  # noqa: SIM115
    try:
        for s, summary in zip(missing, run_batch(missing, jobs, progress), strict=True):
            key = settings_key(s)
            fresh[key] = summary
            if fh is not None:
                fh.write(json.dumps({**summary, "settings": json.loads(key), "code": code}) + "\n")
                fh.flush()
    finally:
        if fh is not None:
            fh.close()
    records = []
    for case, s in todo:
        key = settings_key(s)
        summary = dict(known.get(key) or fresh[key])
        summary.setdefault("code", code)
        summary.update(
            suite=case.suite,
            case=case.name,
            route_m=case.route_m,
            max_time_s=s.max_time_s,
            stall_time_s=s.stall_time_s,
            settings=json.loads(key),
        )
        records.append(summary)
    return records


# ---------------------------------------------------------------------------------------------
# Report


def _mean(values: Sequence[float]) -> float | None:
    return sum(values) / len(values) if values else None


def _fmt(value: float | None, digits: int = 1) -> str:
    return "–" if value is None else f"{value:.{digits}f}"


def outcome_table(
    records: Sequence[dict[str, Any]], filters: Sequence[str], operators: Sequence[str]
) -> list[str]:
    """Per operator and filter: outcomes, time and path of reached runs, interventions, and
    DESIGN 13's metrics over every cycle of the episodes that report them (``changed`` share,
    ``mean_cut``, ``hold_s``; older records without them show a dash)."""
    lines = [
        "| operator | filter | episodes | reached | collided | stalled | timeout | error "
        "| time s (reached, mean) | path m (reached, mean) | interventions / episode "
        "| interventions / s | changed share | mean cut | hold s / episode |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for op in operators:
        for f in filters:
            rows = [r for r in records if r.get("operator") == op and r.get("filter") == f]
            if not rows:
                continue
            count = defaultdict(int)
            for r in rows:
                count[r.get("outcome", "error")] += 1
            reached = [r for r in rows if r.get("outcome") == "reached"]
            ok = [r for r in rows if "error" not in r]
            total_t = sum(r["time_s"] for r in ok)
            total_i = sum(r["interventions"] for r in ok)
            measured = [r for r in ok if "changed" in r and "commands" in r]
            commands = sum(r["commands"] for r in measured)
            share = sum(r["changed"] for r in measured) / commands if commands else None
            cut = (
                sum(r["mean_cut"] * r["commands"] for r in measured) / commands
                if commands
                else None
            )
            lines.append(
                f"| {op} | {f} | {len(rows)} | {count['reached']} | {count['collided']} "
                f"| {count['stalled']} | {count['timeout']} | {count['error']} "
                f"| {_fmt(_mean([r['time_s'] for r in reached]))} "
                f"| {_fmt(_mean([r['path_m'] for r in reached]), 2)} "
                f"| {_fmt(_mean([r['interventions'] for r in ok]), 0)} "
                f"| {_fmt(total_i / total_t if total_t else None, 1)} "
                f"| {_fmt(share, 3)} | {_fmt(cut, 3)} "
                f"| {_fmt(_mean([r['hold_s'] for r in measured]), 1)} |"
            )
    return lines


def collision_table(
    records: Sequence[dict[str, Any]], filters: Sequence[str], suites: Sequence[str]
) -> list[str]:
    lines = [
        "| filter | mode | " + " | ".join(suites) + " | all |",
        "|---|---|" + "---:|" * (len(suites) + 1),
    ]
    for f in filters:
        rows = [r for r in records if r.get("filter") == f]
        per = [
            f"{sum(r.get('outcome') == 'collided' for r in rows if r['suite'] == s)} / "
            f"{sum(r['suite'] == s for r in rows)}"
            for s in suites
        ]
        total = f"{sum(r.get('outcome') == 'collided' for r in rows)} / {len(rows)}"
        mode = "direct" if f == "none" else "shared"
        lines.append(f"| {f} | {mode} | " + " | ".join(per) + f" | {total} |")
    return lines


def reproduce_command(r: dict[str, Any], record: str | None = None) -> str:
    s = r["settings"]
    parts = ["egc-teleop episode", f"--map {s['map']}"]
    if s.get("start"):
        parts.append("--start=" + ",".join(f"{v:g}" for v in s["start"]))
    if s.get("goal"):
        parts.append("--goal=" + ",".join(f"{v:g}" for v in s["goal"]))
    parts += [
        f"--operator {s['operator']}",
        f"--filter {s['filter']}",
        f"--via {s['via']}",
        f"--profile {s['profile']}",
        f"--seed {s['seed']}",
        f"--max-time {s['max_time_s']:g}",
        f"--stall-time {s['stall_time_s']:g}",
    ]
    if record:
        parts.append(f"--record {record}")
    return " ".join(parts) + " --json"


def shared_collisions(records: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    return [r for r in records if r.get("outcome") == "collided" and r.get("filter") != "none"]


def _git_head() -> str:
    try:
        out = subprocess.run(
            ["git", "log", "-1", "--format=%h %cd", "--date=iso"],
            cwd=ROOT,
            capture_output=True,
            text=True,
            check=True,
        )
        return out.stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def _header(
    title: str, command: str, records: Sequence[dict[str, Any]], wall_s: float
) -> list[str]:
    codes = sorted({r.get("code", "?") for r in records})
    episode_s = sum(r.get("wall_s", 0.0) for r in records)
    return [
        f"# {title}",
        "",
        "Generated by (from the repository root, in the venv; the episode loops took "
        f"{episode_s / 60:.0f} min of wall time in total, about {episode_s / 120:.0f} min with "
        f"`--jobs 2` on 2 busy cores; this invocation took {wall_s / 60:.0f} min):",
        "",
        "```sh",
        command,
        "```",
        "",
        f"Code: HEAD {_git_head()}, sources hash {', '.join(codes)} (`arena.code_hash`: robot, "
        "simulator, common and the episode engine as they were in the working tree); "
        f"{len(records)} episodes.",
        "",
    ]


def setup_text(records: Sequence[dict[str, Any]]) -> list[str]:
    """The setup paragraph, with the profiles the records actually used."""
    profiles = {
        suite: ", ".join(sorted({r["profile"] for r in records if r.get("suite") == suite}))
        or SUITE_PROFILE[suite]
        for suite in SUITES
    }
    return [line.format(**profiles) for line in SETUP_TEXT]


SETUP_TEXT = [
    "Setup (`egc_experiments/arena.py`): headless `egc-teleop episode` runs through the robot's "
    "own pipeline (filter, profile limits, footprint sweep, no-dead-lock rule). `none` is direct "
    "mode; every other filter runs in shared mode. Suites: `hallway` ({hallway}, via point at "
    "the goal), `mrpb` (the 19 tests of the MRPB maps, {mrpb}, via points at the corners of "
    "a route planned on the map, `--via route`) and `random` (seeded random obstacle fields "
    "`random:S..S+N-1`, S `--first-world` (0 unless given), N `--worlds`, {random}, via point "
    "at the goal). Every filter gets the same via points; "
    "only `assist` and `dwa` use them. Operators: `goal` steers straight at the active via "
    "point (the robot echoes it in its telemetry and the operator view draws it; the goal once "
    "the via points are done) and cannot see the obstacles; `sighted` sees what the operator "
    "view shows (after a 0.25 s reaction time) and steers through the free direction nearest to "
    "the active via point. An episode ends `reached` (within the "
    "goal tolerance), `collided` (footprint contact), `stalled` (standing still for "
    f"{STALL_TIME_S:g} s) or `timeout` (after max(60, 2 x planned route / v_max + 30) s). "
    "Times and paths are means over reached episodes; interventions are control cycles in which "
    "the filter changed the command or the sweep scaled it down. Changed share, mean cut and "
    "hold s are DESIGN 13's metrics over every cycle (`egc_robot.intervention`): the share of "
    "commands whose v or w the filter or sweep moved by more than 0.01 from what direct mode "
    "would have sent, the mean of |dv|/v_max + |dw|/w_max, and the time a moving command was "
    "stopped.",
    "",
]


def write_filters_report(
    path: Path,
    records: Sequence[dict[str, Any]],
    filters: Sequence[str],
    operators: Sequence[str],
    suites: Sequence[str],
    command: str,
    wall_s: float,
) -> None:
    lines = _header("The filter arena (issue 10)", command, records, wall_s) + setup_text(records)
    lines += ["## Collisions (the must-show: none in shared mode)", ""]
    lines += [*collision_table(records, filters, suites), ""]
    bad = shared_collisions(records)
    if bad:
        lines += ["Shared-mode collisions, with the command that reproduces each:", ""]
        for r in bad:
            pose = ", ".join(f"{v:.2f}" for v in r["final_pose"])
            lines += [
                f"- {r['case']} / {r['operator']} / `{r['filter']}`: contact at t = "
                f"{r['time_s']:.2f} s, pose ({pose})",
                f"  `{reproduce_command(r)}`",
            ]
        lines.append("")
    else:
        lines += ["No shared-mode episode touched anything.", ""]
    for suite in suites:
        rows = [r for r in records if r.get("suite") == suite]
        if not rows:
            continue
        n_cases = len({r["case"] for r in rows})
        lines += [f"## {suite} ({n_cases} {'case' if n_cases == 1 else 'cases'})", ""]
        lines += [*outcome_table(rows, filters, operators), ""]
    lines += ["## Reading", "", *reading_filters(records, filters, operators, suites), ""]
    path.write_text("\n".join(lines), encoding="utf-8")


def _rate(records: Sequence[dict[str, Any]], **match: Any) -> tuple[int, int]:
    rows = [r for r in records if all(r.get(k) == v for k, v in match.items())]
    return sum(r.get("outcome") == "reached" for r in rows), len(rows)


def _count(records: Sequence[dict[str, Any]], outcome: str, **match: Any) -> int:
    return sum(
        r.get("outcome") == outcome and all(r.get(k) == v for k, v in match.items())
        for r in records
    )


def reading_filters(
    records: Sequence[dict[str, Any]],
    filters: Sequence[str],
    operators: Sequence[str],
    suites: Sequence[str],
) -> list[str]:
    """Plain-words reading of the numbers (generated, so that it always matches the tables)."""
    out = []
    bad = shared_collisions(records)
    shared = [f for f in filters if f != "none"]
    n_shared = sum(r.get("filter") in shared for r in records)
    if bad:
        which = sorted({r["filter"] for r in bad})
        out.append(
            f"- Safety: {len(bad)} of {n_shared} shared-mode episodes ended in a contact "
            f"(filters: {', '.join(which)}); the must-show (no collision, ever, in shared mode) "
            "does not hold for them. See the list above."
        )
    elif n_shared:
        out.append(
            f"- Safety: none of the {n_shared} shared-mode episodes touched anything; direct "
            f"mode (`none`) collided in {_count(records, 'collided', filter='none')} of "
            f"{sum(r.get('filter') == 'none' for r in records)}."
        )
    for suite in suites:
        for op in operators:
            parts = []
            for f in filters:
                k, n = _rate(records, suite=suite, operator=op, filter=f)
                if n:
                    parts.append(f"`{f}` {k}/{n}")
            if parts:
                out.append(f"- {suite}, `{op}` operator, reached: " + ", ".join(parts) + ".")
    for f in filters:
        for op in operators:
            rows = [r for r in records if r.get("filter") == f and r.get("operator") == op]
            if not rows:
                continue
            misses = defaultdict(int)
            for r in rows:
                if r.get("outcome") != "reached":
                    misses[r.get("outcome", "error")] += 1
            if misses:
                how = ", ".join(
                    f"{k} {v}" for k, v in sorted(misses.items(), key=lambda kv: -kv[1])
                )
                out.append(
                    f"- `{f}` with the `{op}` operator, over all suites: of "
                    f"{sum(misses.values())} episodes that did not arrive: {how}."
                )
    out.append(
        "- How to read it: `stalled` means the filter held the robot still in front of "
        "something (safe, but the operator is stuck); `timeout` means it kept moving without "
        "getting there in time (circling, rocking or crawling); `collided` in direct mode is "
        "what the operator alone would have done."
    )
    return out


# ---------------------------------------------------------------------------------------------
# The assist report


def _paired_times(
    records: Sequence[dict[str, Any]], a: dict[str, Any], b: dict[str, Any]
) -> tuple[int, float | None, float | None]:
    """Cases reached under both settings a and b: count and mean times."""

    def index(match: dict[str, Any]) -> dict[str, dict[str, Any]]:
        return {
            r["case"]: r
            for r in records
            if r.get("outcome") == "reached" and all(r.get(k) == v for k, v in match.items())
        }

    ia, ib = index(a), index(b)
    both = sorted(set(ia) & set(ib))
    if not both:
        return 0, None, None
    return (
        len(both),
        _mean([ia[c]["time_s"] for c in both]),
        _mean([ib[c]["time_s"] for c in both]),
    )


def write_assist_report(
    path: Path,
    records: Sequence[dict[str, Any]],
    filters: Sequence[str],
    operators: Sequence[str],
    suites: Sequence[str],
    command: str,
    wall_s: float,
    figures: Sequence[str] = (),
) -> None:
    lines = _header(
        "The rule-based assistant with via points (issue 11): the paper's experiment",
        command,
        records,
        wall_s,
    ) + setup_text(records)
    lines += [
        "Without assistance is `none` (direct mode: the operator's command as it is) and `egc` "
        "(the obstacle filter alone, no via point); with assistance is `assist` with the via "
        "points above.",
        "",
    ]
    for suite in suites:
        rows = [r for r in records if r.get("suite") == suite]
        if not rows:
            continue
        n_cases = len({r["case"] for r in rows})
        lines += [f"## {suite} ({n_cases} {'case' if n_cases == 1 else 'cases'})", ""]
        lines += [*outcome_table(rows, filters, operators), ""]
    lines += ["## Time with and without assistance (cases reached by both)", ""]
    lines += [
        "| suite | compared | cases reached by both | mean time A s | mean time B s |",
        "|---|---|---:|---:|---:|",
    ]
    # (operator, filter) of A and of B: with assistance against without it.
    pairs = [
        (("goal", "assist"), ("sighted", "none")),
        (("goal", "assist"), ("goal", "egc")),
        (("goal", "assist"), ("goal", "none")),
        (("sighted", "assist"), ("sighted", "none")),
        (("sighted", "assist"), ("sighted", "egc")),
    ]
    for suite in suites:
        for (op_a, filter_a), (op_b, filter_b) in pairs:
            n, ta, tb = _paired_times(
                records,
                {"suite": suite, "operator": op_a, "filter": filter_a},
                {"suite": suite, "operator": op_b, "filter": filter_b},
            )
            lines.append(
                f"| {suite} | A {op_a}+{filter_a} vs B {op_b}+{filter_b} | {n} "
                f"| {_fmt(ta)} | {_fmt(tb)} |"
            )
    lines.append("")
    for fig in figures:
        lines += [f"![{Path(fig).stem}]({fig})", ""]
    lines += ["## Which of the paper's claims hold here", "", *reading_assist(records, suites), ""]
    path.write_text("\n".join(lines), encoding="utf-8")


REACH_THRESHOLD = 0.8  # issue 11: "at least 80% of the worlds with no collision"


def reading_assist(records: Sequence[dict[str, Any]], suites: Sequence[str]) -> list[str]:
    """Per suite: does the blind operator arrive with assist, and faster than without?"""
    out = []
    for suite in suites:
        ka, na = _rate(records, suite=suite, operator="goal", filter="assist")
        ke, ne = _rate(records, suite=suite, operator="goal", filter="egc")
        kn, nn = _rate(records, suite=suite, operator="goal", filter="none")
        if not na:
            continue
        ca = _count(records, "collided", suite=suite, operator="goal", filter="assist")
        cn = _count(records, "collided", suite=suite, operator="goal", filter="none")
        reaches = ka >= REACH_THRESHOLD * na and ca == 0
        out.append(
            f"- {suite}: the blind (`goal`) operator with `assist` and via points reached "
            f"{ka}/{na} ({100 * ka / na:.0f}%) with {ca} collisions; without assistance "
            f"`egc` reached {ke}/{ne} and direct {kn}/{nn} (direct collided {cn}). "
            f"Claim 1, 'with a via point an operator who cannot see reaches the destination' "
            f"(read as >= {100 * REACH_THRESHOLD:.0f}% reached, no collision): "
            f"**{'holds' if reaches else 'does not hold'}**."
        )
        better = ka > max(ke, kn)
        n, ta, tb = _paired_times(
            records,
            {"suite": suite, "operator": "goal", "filter": "assist"},
            {"suite": suite, "operator": "goal", "filter": "egc"},
        )
        timing = (
            f" On the {n} cases both reached, mean time {ta:.1f} s with assist vs "
            f"{tb:.1f} s with `egc`."
            if n and ta is not None and tb is not None
            else ""
        )
        if ka == 0:
            verdict = "not shown (assist did not get the blind operator there)"
        elif better:
            verdict = "holds in the sense that it arrives more often than without assistance"
        else:
            verdict = "does not hold (no more arrivals than without assistance)"
        out.append(f"  Claim 2, 'faster than without assistance': {verdict}.{timing}")
        n, ta, tb = _paired_times(
            records,
            {"suite": suite, "operator": "sighted", "filter": "assist"},
            {"suite": suite, "operator": "sighted", "filter": "none"},
        )
        if n and ta is not None and tb is not None:
            out.append(
                f"  Sighted operator (the paper: assistance is 'a little less efficient' when "
                f"the operator can see): on {n} cases both reached, {ta:.1f} s with assist vs "
                f"{tb:.1f} s direct."
            )
    return out


def write_assist_figures(
    out_dir: Path,
    records: Sequence[dict[str, Any]],
    filters: Sequence[str],
    operators: Sequence[str],
    suites: Sequence[str],
    path_worlds: Sequence[int] = (0, 1, 2, 3),
    stem: str = "assist",
) -> list[str]:
    """Reach rate per suite/operator/filter, and paths of the goal operator on a few worlds."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    names = []
    fig, axes = plt.subplots(1, len(suites), figsize=(4.2 * len(suites), 3.4), squeeze=False)
    width = 0.8 / max(1, len(filters))
    for ax, suite in zip(axes[0], suites, strict=True):
        for i, f in enumerate(filters):
            rates = []
            for op in operators:
                k, n = _rate(records, suite=suite, operator=op, filter=f)
                rates.append(100.0 * k / n if n else 0.0)
            ax.bar(
                np.arange(len(operators)) + (i - (len(filters) - 1) / 2) * width,
                rates,
                width,
                label=f,
            )
        ax.set_xticks(range(len(operators)), [f"{op} operator" for op in operators])
        ax.set_ylim(0, 100)
        ax.set_title(suite)
        ax.set_ylabel("reached %")
    axes[0][0].legend(fontsize="small")
    fig.tight_layout()
    name = f"{stem}_reach.png"
    fig.savefig(out_dir / name, dpi=110)
    plt.close(fig)
    names.append(name)

    if "random" in suites and path_worlds:
        fig, axes = plt.subplots(
            1, len(path_worlds), figsize=(4.2 * len(path_worlds), 3.2), squeeze=False
        )
        for ax, seed in zip(axes[0], path_worlds, strict=True):
            used = {r.get("profile") for r in records if r.get("world") == f"random:{seed}"}
            name = used.pop() if len(used) == 1 else None
            reach = get_profile(name).footprint.reach_m if name else None
            world = load_world(f"random:{seed}", seed=seed, reach_m=reach)
            h, w = world.occupancy.shape
            x0, y0 = world.origin
            ax.imshow(
                world.occupancy,
                origin="lower",
                cmap="Greys",
                extent=(x0, x0 + w * world.resolution_m, y0, y0 + h * world.resolution_m),
            )
            for f in filters:
                rec = next(
                    (
                        r
                        for r in records
                        if r.get("case") == f"random:{seed}"
                        and r.get("operator") == "goal"
                        and r.get("filter") == f
                    ),
                    None,
                )
                if rec is None or "error" in rec:
                    continue
                s = EpisodeSettings(
                    **{
                        k: tuple(v) if isinstance(v, list) else v
                        for k, v in rec["settings"].items()
                    }
                )
                result, _ = run_settings(s, record_trace=True)
                xs = [row.x_m for row in result.trace]
                ys = [row.y_m for row in result.trace]
                ax.plot(xs, ys, label=f"{f}: {result.outcome}")
            gx, gy = rec["goal"] if rec else world.goal
            ax.plot([gx], [gy], "r*", markersize=12)
            ax.set_title(f"random:{seed}, goal operator")
            ax.set_aspect("equal")
            ax.legend(fontsize="x-small", loc="lower left")
        fig.tight_layout()
        name = f"{stem}_paths.png"
        fig.savefig(out_dir / name, dpi=110)
        plt.close(fig)
        names.append(name)
    return names


# ---------------------------------------------------------------------------------------------
# Command line


def _names(text: str, allowed: Sequence[str], what: str) -> tuple[str, ...]:
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    bad = [n for n in names if n not in allowed]
    if bad or not names:
        raise UsageError(f"--{what} must be a comma list of {', '.join(allowed)}, got {text!r}")
    return names


def _shown_args(argv: list[str]) -> list[str]:
    """The command line without ``--reuse`` (reused episodes are the same episodes)."""
    out, skip = [], False
    for a in argv:
        if skip:
            skip = False
        elif a == "--reuse":
            skip = True
        elif not a.startswith("--reuse"):
            out.append(a)
    return out


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m egc_experiments.arena",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--experiment", choices=("arena", "assist"), default="arena")
    p.add_argument("--out", required=True, help="directory for runs.jsonl (and figures)")
    p.add_argument("--report", help="Markdown report to write (default DIR/report.md)")
    p.add_argument("--worlds", type=int, help="random worlds (arena 50, assist 100)")
    p.add_argument(
        "--first-world",
        type=int,
        default=0,
        help="seed of the first random world (worlds never used for tuning: e.g. 1000)",
    )
    p.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    p.add_argument("--filters", help="comma list (arena: all five; assist: none,egc,assist)")
    p.add_argument("--operators", default=",".join(OPERATORS))
    p.add_argument("--suites", default=",".join(SUITES))
    p.add_argument("--mrpb-dir", default=str(MRPB_DIR))
    p.add_argument("--random-profile", default="jackal", help="profile on random worlds (jackal)")
    p.add_argument("--mrpb-limit", type=int, help="only the first N MRPB tests (for tests)")
    p.add_argument("--reuse", action="append", default=[], help="earlier runs.jsonl to reuse")
    p.add_argument(
        "--reuse-other-code",
        action="store_true",
        help="reuse episodes even if the sources changed since (the report lists every hash)",
    )
    p.add_argument("--no-figures", action="store_true")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    args = p.parse_args(argv)
    try:
        assist = args.experiment == "assist"
        filters = _names(
            args.filters or ",".join(ASSIST_FILTERS if assist else ARENA_FILTERS),
            FILTERS,
            "filters",
        )
        operators = _names(args.operators, ("goal", "forward", "sighted", "route"), "operators")
        suites = _names(args.suites, SUITES, "suites")
        worlds = args.worlds if args.worlds is not None else (100 if assist else 50)
        if worlds < 0 or args.jobs < 1 or args.first_world < 0:
            raise UsageError("--worlds and --first-world must be >= 0 and --jobs >= 1")
        out = Path(args.out)
        report = Path(args.report) if args.report else out / "report.md"
        t0 = time.perf_counter()
        cases = build_cases(
            suites,
            worlds,
            Path(args.mrpb_dir),
            args.mrpb_limit,
            args.random_profile,
            args.first_world,
        )
        out.mkdir(parents=True, exist_ok=True)
        todo = episodes(cases, filters, operators)
        reuse = load_runs(args.reuse)
        partial = out / "partial.jsonl"
        records = run_arena(todo, args.jobs, reuse, not args.quiet, partial, args.reuse_other_code)
        with open(out / "runs.jsonl", "w", encoding="utf-8") as fh:
            for r in records:
                fh.write(json.dumps(r, allow_nan=False) + "\n")
        partial.unlink(missing_ok=True)
        wall_s = time.perf_counter() - t0
        command = "python -m egc_experiments.arena " + " ".join(
            _shown_args(list(sys.argv[1:] if argv is None else argv))
        )
        if assist:
            figures: list[str] = []
            if not args.no_figures:
                first = args.first_world
                names = write_assist_figures(
                    report.parent,
                    records,
                    filters,
                    operators,
                    suites,
                    stem=report.stem,
                    path_worlds=range(first, first + min(4, worlds)),
                )
                figures = [os.path.relpath(report.parent / n, report.parent) for n in names]
            write_assist_report(
                report, records, filters, operators, suites, command, wall_s, figures
            )
        else:
            write_filters_report(report, records, filters, operators, suites, command, wall_s)
    except UsageError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    bad = shared_collisions(records)
    print(
        f"{len(records)} episodes in {wall_s:.0f} s; shared-mode collisions: {len(bad)}; "
        f"report {report}",
        file=sys.stderr,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
