"""``egc-teleop bench [NAME ...]``: run the benchmarks in bench/ (from a source checkout).

Each benchmark is a script ``bench/bench_<name>.py`` that prints a table, writes JSON under
``bench/results/`` and exits non-zero when it misses a target.
"""

from __future__ import annotations

import argparse
import runpy
import sys
from pathlib import Path

from egc_common.errors import UsageError

BENCH_DIR = Path(__file__).resolve().parents[1] / "bench"


def available() -> list[str]:
    return sorted(p.stem.removeprefix("bench_") for p in BENCH_DIR.glob("bench_*.py"))


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "names",
        nargs="*",
        metavar="NAME",
        help="benchmarks to run (default: all); 'list' shows them",
    )


def run(args: argparse.Namespace) -> int:
    names = args.names or ["all"]
    if not BENCH_DIR.is_dir():
        raise UsageError(f"benchmarks live in a source checkout; {BENCH_DIR} does not exist")
    known = available()
    if names == ["list"]:
        print("\n".join(known))
        return 0
    if "all" in names:
        names = known
    unknown = [n for n in names if n not in known]
    if unknown:
        raise UsageError(f"unknown benchmark(s) {', '.join(unknown)} (known: {', '.join(known)})")
    status = 0
    for name in names:
        print(f"== bench {name} ==", flush=True)
        saved = sys.argv
        sys.argv = [str(BENCH_DIR / f"bench_{name}.py")]
        try:
            runpy.run_path(sys.argv[0], run_name="__main__")
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else 1
            status = status or code
        finally:
            sys.argv = saved
    return status
