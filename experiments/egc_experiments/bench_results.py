"""What a benchmark in ``bench/`` leaves behind: ``bench/results/NAME.json``, its numbers with
where, when and at which commit they were measured (issue 31). ``egc_experiments.bench_report``
renders the files into ``docs/benchmarks.md``.

A result file is the benchmark's own JSON object plus two records the benchmark does not make:

- ``machine``: ``cpu`` (the model name from /proc/cpuinfo), ``cores`` (``os.cpu_count()``),
  ``cores_usable`` (this process's CPU affinity), ``arch``, ``platform``, ``python``;
- ``run``: ``bench`` (the name), ``date`` (UTC, ISO 8601, when the result was written),
  ``commit`` (``git rev-parse --short HEAD`` of the checkout, ``null`` outside one) and
  ``dirty`` (tracked files changed, other than the results and the documentation),
  ``load_average`` (1, 5 and 15 min, when the result was written: the 5- and 15-minute
  figures cover most benchmarks' whole run), ``options`` (the script's command-line options).

This module is an IO adapter (files, git, /proc); the records are built once per write.
"""

from __future__ import annotations

import datetime
import json
import os
import platform
import subprocess
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
RESULTS_DIR = ROOT / "bench" / "results"
PAGE = ROOT / "docs" / "benchmarks.md"
# Changing these does not make a checkout "dirty": what a benchmark run writes, and the
# documentation (which measures nothing).
NOT_CODE = ("bench/results", "docs", "*.md")


def cpu_model() -> str:
    """The CPU's model name as /proc/cpuinfo gives it, else what ``platform`` knows."""
    try:
        for line in Path("/proc/cpuinfo").read_text(encoding="utf-8").splitlines():
            key, _, value = line.partition(":")
            if key.strip() in ("model name", "Model", "Hardware") and value.strip():
                return value.strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"


def machine_record() -> dict[str, Any]:
    usable = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return {
        "cpu": cpu_model(),
        "cores": os.cpu_count(),
        "cores_usable": usable,
        "arch": platform.machine(),
        "platform": platform.platform(),
        "python": platform.python_version(),
    }


def _git(root: Path, *args: str) -> str | None:
    try:
        proc = subprocess.run(
            ["git", "-C", str(root), *args],
            capture_output=True,
            text=True,
            timeout=30,
            stdin=subprocess.DEVNULL,
        )
    except (OSError, subprocess.TimeoutExpired):
        return None
    return proc.stdout.strip() if proc.returncode == 0 else None


def commit_record(root: Path = ROOT) -> dict[str, Any]:
    """The checkout's commit, and whether tracked files other than the results and the
    documentation differ from it; ``None`` for both outside a git checkout."""
    commit = _git(root, "rev-parse", "--short=10", "HEAD")
    if commit is None:
        return {"commit": None, "dirty": None}
    excluded = [f":(exclude){p}" for p in NOT_CODE]
    status = _git(root, "status", "--porcelain", "--untracked-files=no", "--", ".", *excluded)
    return {"commit": commit, "dirty": bool(status) if status is not None else None}


def run_record(name: str, options: list[str]) -> dict[str, Any]:
    now = datetime.datetime.now(datetime.UTC)
    return {
        "bench": name,
        "date": now.isoformat(timespec="seconds"),
        **commit_record(),
        "load_average": [round(x, 2) for x in os.getloadavg()],
        "options": options,
    }


def write_result(name: str, result: dict[str, Any], out: str | Path | None = None) -> Path:
    """Write ``result`` with its ``machine`` and ``run`` records to ``out`` (default
    ``bench/results/NAME.json``) and return the path. A ``machine`` key the benchmark set
    itself is replaced by the full record."""
    path = Path(out) if out is not None else RESULTS_DIR / f"{name}.json"
    record = {k: v for k, v in result.items() if k not in ("machine", "run")}
    record["machine"] = machine_record()
    record["run"] = run_record(name, sys.argv[1:])
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(record, indent=2, default=str) + "\n", encoding="utf-8")
    tmp.replace(path)
    return path


def load_results(folder: Path = RESULTS_DIR) -> dict[str, dict[str, Any]]:
    """Every result file in ``folder`` that this module wrote (it has a ``run`` record), by
    name. Files of another shape (older runs) and unreadable ones are left out."""
    found: dict[str, dict[str, Any]] = {}
    if not folder.is_dir():
        return found
    for path in sorted(folder.glob("*.json")):
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            continue
        if isinstance(data, dict) and isinstance(data.get("run"), dict):
            found[path.stem] = data
    return found
