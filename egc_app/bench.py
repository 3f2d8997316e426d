"""``egc-teleop bench [NAME ...]`` and ``egc-teleop bench NAME [OPTION ...]``: run the
benchmarks in bench/ (from a source checkout); ``egc-teleop bench report`` renders their results.

Each benchmark is a script ``bench/bench_<name>.py`` that prints a table, writes its result to
``bench/results/<name>.json`` with the machine, date and commit (``egc_experiments.bench_results``)
and exits non-zero when it misses a target. After a run that wrote a result there,
``docs/benchmarks.md`` is rendered again from all of them (``egc_experiments.bench_report``);
``bench report [--out FILE]`` does only that. Several names run one after the
other with their defaults; after one name, everything from the first option on goes to that
script (``egc-teleop bench view --minutes 0.3``, ``egc-teleop bench link --trials 1``), and
``egc-teleop bench NAME --help`` shows the script's own options. A bad option of the script is
one line on stderr and exit 2, as for every subcommand (DESIGN 2).
"""

from __future__ import annotations

import argparse
import contextlib
import runpy
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any, NoReturn

from egc_common.errors import UsageError
from egc_experiments import bench_report
from egc_experiments.bench_results import PAGE, RESULTS_DIR

BENCH_DIR = Path(__file__).resolve().parents[1] / "bench"


def available() -> list[str]:
    return sorted(p.stem.removeprefix("bench_") for p in BENCH_DIR.glob("bench_*.py"))


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "words",
        nargs=argparse.REMAINDER,
        metavar="NAME ... | NAME OPTION ...",
        help="benchmarks to run (default: all; 'list' shows them), or one benchmark and its "
        "own options (egc-teleop bench NAME --help shows them); 'report [--out FILE]' writes "
        "docs/benchmarks.md from bench/results/ (a run that writes a result there does too)",
    )


def split_words(words: list[str]) -> tuple[list[str], list[str]]:
    """The benchmark names (the words before the first option) and the options for the script;
    a ``--`` after the names is dropped (``bench view -- --minutes 1`` works too)."""
    cut = next((i for i, w in enumerate(words) if w.startswith("-")), len(words))
    names, options = words[:cut], words[cut:]
    if options[:1] == ["--"]:
        options = options[1:]
    return names, options


@contextlib.contextmanager
def _one_line_errors(name: str) -> Iterator[None]:
    """While a script runs: its argparse errors are one line and exit 2 (argparse's own print
    the usage first), naming ``egc-teleop bench NAME``. Restored afterwards."""

    def error(parser: argparse.ArgumentParser, message: str) -> NoReturn:
        prog = f"egc-teleop bench {name}"
        parser.exit(2, f"{prog}: error: {message} (see {prog} --help)\n")

    saved = argparse.ArgumentParser.error
    argparse.ArgumentParser.error = error  # type: ignore[method-assign,assignment]
    try:
        yield
    finally:
        argparse.ArgumentParser.error = saved  # type: ignore[method-assign]


def _exit_status(code: Any) -> int:
    """``sys.exit(code)`` as a process would report it: None is 0, a message is 1."""
    if code is None:
        return 0
    if isinstance(code, int):
        return code
    print(code, file=sys.stderr)
    return 1


def _report(options: list[str]) -> int:
    """``bench report [--out FILE]``: the page from the results, nothing run."""
    out = PAGE
    if options[:1] == ["--out"] and len(options) == 2:
        out = Path(options[1])
    elif options:
        raise UsageError(f"'report' takes only --out FILE, got {' '.join(options)}")
    if out.is_dir() or not out.parent.is_dir():
        raise UsageError(f"--out {out}: not a file in an existing folder")
    print(f"wrote {bench_report.write_page(out)}")
    return 0


def _result_stamps() -> dict[Path, int]:
    return {p: p.stat().st_mtime_ns for p in RESULTS_DIR.glob("*.json")}


def run(args: argparse.Namespace) -> int:
    names, options = split_words(args.words)
    names = names or ["all"]
    if not BENCH_DIR.is_dir():
        raise UsageError(f"benchmarks live in a source checkout; {BENCH_DIR} does not exist")
    known = available()
    if names == ["list"]:
        if options:
            raise UsageError(f"'list' takes no options, got {' '.join(options)}")
        print("\n".join(known))
        return 0
    if names == ["report"]:
        return _report(options)
    unknown = [n for n in names if n not in (*known, "all")]
    if unknown:
        raise UsageError(f"unknown benchmark(s) {', '.join(unknown)} (known: {', '.join(known)})")
    if "all" in names:
        names = known
    if options and len(names) != 1:
        raise UsageError(
            f"options ({' '.join(options)}) go to one benchmark's script: name exactly one, "
            "e.g. egc-teleop bench view --minutes 0.3"
        )
    status = 0
    before = _result_stamps()
    for name in names:
        if len(names) > 1:  # which table is which
            print(f"== bench {name} ==", flush=True)
        saved = sys.argv
        sys.argv = [str(BENCH_DIR / f"bench_{name}.py"), *options]
        try:
            with _one_line_errors(name):
                runpy.run_path(sys.argv[0], run_name="__main__")
        except SystemExit as exc:
            status = status or _exit_status(exc.code)
        finally:
            sys.argv = saved
    if _result_stamps() != before and PAGE.parent.is_dir():  # a result in bench/results/
        print(f"wrote {bench_report.write_page()}")
    return status
