"""Many headless episodes (``egc_experiments.episode``) in parallel worker processes: the suite
files of ``egc-teleop episode --batch`` and the runner the CLI, the experiments and the arena
share (DESIGN 2).

A suite file holds one JSON object per line with the single-episode options as keys: ``map``
(required), ``start`` ([x, y, yaw]), ``goal`` ([x, y]), ``operator``, ``filter``, ``profile``,
``max_time``, ``goal_tolerance``, ``seed``, ``dt``, ``stall_time``, ``via``; missing keys take the
base settings' values (the command line's). Blank lines and lines starting with ``#`` are
skipped; a bad line is a ``UsageError`` naming the file and line.

``run_batch`` yields the summaries in input order; an episode whose settings are bad becomes an
``{"error": ...}`` record instead of ending the batch.
"""

from __future__ import annotations

import contextlib
import json
import math
import multiprocessing
import signal
import sys
import threading
from collections.abc import Iterator, Sequence
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

from egc_common.errors import UsageError
from egc_robot.pipeline import FILTERS

from egc_experiments.episode import VIA_CHOICES, EpisodeSettings, parse_floats, run_settings

SUITE_KEYS = {
    "map",
    "start",
    "goal",
    "operator",
    "filter",
    "profile",
    "max_time",
    "goal_tolerance",
    "seed",
    "dt",
    "stall_time",
    "via",
}


def suite_settings(path: str, base: EpisodeSettings) -> list[EpisodeSettings]:
    try:
        lines = Path(path).read_text(encoding="utf-8").splitlines()
    except OSError as exc:
        raise UsageError(f"cannot read suite {path}: {exc.strerror or exc}") from None
    out = []
    for no, line in enumerate(lines, start=1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        where = f"{path}:{no}"
        try:
            item = json.loads(line)
        except json.JSONDecodeError as exc:
            raise UsageError(f"{where}: not JSON ({exc.msg})") from None
        if not isinstance(item, dict) or "map" not in item:
            raise UsageError(f"{where}: expected an object with at least a 'map' key")
        unknown = sorted(set(item) - SUITE_KEYS)
        if unknown:
            raise UsageError(f"{where}: unknown key(s) {', '.join(unknown)}")
        try:
            out.append(_apply_suite_item(item, base))
        except (TypeError, ValueError, UsageError) as exc:
            raise UsageError(f"{where}: {exc}") from None
    if not out:
        raise UsageError(f"suite {path} holds no episodes")
    return out


def _apply_suite_item(item: dict[str, Any], base: EpisodeSettings) -> EpisodeSettings:
    def numbers(key: str, n: int) -> tuple[float, ...]:
        value = item[key]
        if isinstance(value, str):
            return parse_floats(value, n, key)
        if not isinstance(value, list) or len(value) != n:
            raise ValueError(f"{key} must be a list of {n} numbers")
        return parse_floats(",".join(str(v) for v in value), n, key)

    s = replace(base, map=str(item["map"]))
    if "start" in item:
        x, y, yaw = numbers("start", 3)
        s = replace(s, start=(x, y, yaw))
    if "goal" in item:
        gx, gy = numbers("goal", 2)
        s = replace(s, goal=(gx, gy))
    for key, field in (
        ("operator", "operator"),
        ("filter", "filter"),
        ("profile", "profile"),
        ("via", "via"),
    ):
        if key in item:
            s = replace(s, **{field: str(item[key])})
    if s.filter not in FILTERS:
        raise ValueError(f"filter must be one of {', '.join(FILTERS)}")
    if s.via not in VIA_CHOICES:
        raise ValueError(f"via must be one of {', '.join(VIA_CHOICES)}")
    for key, field in (
        ("max_time", "max_time_s"),
        ("goal_tolerance", "goal_tolerance_m"),
        ("dt", "dt_s"),
        ("stall_time", "stall_time_s"),
    ):
        if key in item:
            value = float(item[key])
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{key} must be a positive number")
            s = replace(s, **{field: value})
    if "seed" in item:
        s = replace(s, seed=int(item["seed"]))
    return s


def _run_one_safely(settings: EpisodeSettings) -> dict[str, Any]:
    """Worker: one episode; a bad episode becomes an error record instead of ending the batch."""
    try:
        return run_settings(settings)[1]
    except UsageError as exc:
        return {"error": str(exc), **{k: v for k, v in asdict(settings).items() if v is not None}}


def _worker_init() -> None:
    """Worker: a terminal's Ctrl-C (SIGINT to the whole process group) is the batch's to
    answer; it stops its workers itself (``Pool.terminate``: SIGTERM), with no traceback each."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _stop_on_sigterm(signum: int, _frame: object) -> None:
    signal.signal(signal.SIGTERM, signal.SIG_IGN)  # a second one must not cut the cleanup short
    raise SystemExit(128 + signum)


@contextlib.contextmanager
def _sigterm_stops_the_batch() -> Iterator[None]:
    """While the pool runs, SIGTERM raises SystemExit(143) in the main thread, so the pool's
    ``with`` terminates the workers on the way out. (SIGTERM's default action ended this process
    alone: the workers, children of the fork server, ran their episodes on for minutes.) A
    handler someone else installed, or a batch run off the main thread, is left as it is."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.getsignal(signal.SIGTERM)
    if previous not in (signal.SIG_DFL, None):
        yield
        return
    signal.signal(signal.SIGTERM, _stop_on_sigterm)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)


def run_batch(
    settings: Sequence[EpisodeSettings], jobs: int, progress: bool = True
) -> Iterator[dict[str, Any]]:
    """Summaries of the episodes, in input order, computed by ``jobs`` worker processes.

    SIGINT (KeyboardInterrupt) or SIGTERM (SystemExit 143) in the main thread, or closing the
    generator, terminates the workers before the exception goes on. A caller that does work
    between summaries should close the generator on the way out (``contextlib.closing``).
    """
    from tqdm import tqdm

    bar = tqdm(total=len(settings), unit="episode", file=sys.stderr, disable=not progress)
    try:
        if jobs <= 1 or len(settings) <= 1:
            for s in settings:
                yield _run_one_safely(s)
                bar.update()
            return
        # Not fork: workers forked from a process with other threads (a Zenoh runtime, a test
        # harness's servers) can inherit a lock held at that instant and hang; a batch in CI
        # hung so with two of its three episodes done. The fork server starts clean.
        ctx = multiprocessing.get_context("forkserver" if sys.platform == "linux" else "spawn")
        with (
            _sigterm_stops_the_batch(),
            ctx.Pool(min(jobs, len(settings)), initializer=_worker_init) as pool,
        ):
            for summary in pool.imap(_run_one_safely, settings):
                yield summary
                bar.update()
    finally:
        bar.close()
