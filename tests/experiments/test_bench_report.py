"""Benchmark results with their provenance, and the page rendered from them (issue 31)."""

from __future__ import annotations

import datetime
import json
import platform
import re
import subprocess
import sys
from pathlib import Path

from egc_experiments import bench_report
from egc_experiments.bench_results import ROOT, load_results, write_result


def _git_head() -> str:
    return subprocess.run(
        ["git", "-C", str(ROOT), "rev-parse", "--short=10", "HEAD"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()


def test_a_result_says_where_when_and_at_which_commit(tmp_path: Path) -> None:
    out = write_result("demo", {"value_ms": 1.5, "machine": "x86_64"}, tmp_path / "demo.json")
    data = json.loads(out.read_text())
    assert data["value_ms"] == 1.5
    machine, run = data["machine"], data["run"]
    assert machine["python"] == platform.python_version() and machine["cores"] >= 1
    assert machine["cpu"] and machine["arch"] == platform.machine()
    assert run["bench"] == "demo" and run["commit"] == _git_head()
    assert isinstance(run["dirty"], bool)
    when = datetime.datetime.fromisoformat(run["date"])
    assert when.utcoffset() == datetime.timedelta(0)
    assert abs((datetime.datetime.now(datetime.UTC) - when).total_seconds()) < 3600
    assert len(run["load_average"]) == 3 and all(x >= 0 for x in run["load_average"])
    assert not list(tmp_path.glob("*.tmp"))


def test_only_files_with_a_run_record_are_results(tmp_path: Path) -> None:
    write_result("good", {"x": 1}, tmp_path / "good.json")
    (tmp_path / "bench_old.json").write_text(json.dumps({"rows": []}))
    (tmp_path / "broken.json").write_text("{not json")
    assert set(load_results(tmp_path)) == {"good"}
    assert load_results(tmp_path / "missing") == {}


def _filter_result(median_720_us: float) -> dict:
    rows = [
        {"input": f"scan {n}", "points": n, "median_us": m, "p95_us": m * 1.1,
         "loop_median_us": m * 5, "speedup": 5.0}
        for n, m in ((360, 17.0), (720, median_720_us), (1440, 21.6))
    ]  # fmt: skip
    return {
        "rows": rows,
        "family": [],
        "targets": {"720 points <= 50 us": median_720_us <= 50.0},
        "machine": {"cpu": "Test CPU", "cores": 2, "cores_usable": 2, "arch": "x86_64",
                    "python": "3.11.7"},
        "run": {"bench": "filter", "date": "2026-11-27T07:00:00+00:00", "commit": "abcdef1234",
                "dirty": False, "load_average": [0.5, 0.4, 0.3], "options": ["--repeats", "9"]},
    }  # fmt: skip


def test_the_page_shows_results_provenance_targets_and_what_did_not_run() -> None:
    results = {"filter": _filter_result(70.0), "relay": {"run": {"bench": "relay"}, "tcp": 1}}
    page = bench_report.render(results, ["filter", "relay", "sim"], {"sim": "one step"})
    assert "| scan 720 | 720 | 70.0 |" in page
    assert "at commit `abcdef1234` on Test CPU (2 cores, x86_64), Python 3.11.7" in page
    assert "load average (1 / 5 / 15 min) 0.50 / 0.40 / 0.30" in page
    assert "`egc-teleop bench filter --repeats 9`" in page
    assert "720 points <= 50 us: **missed**" in page
    assert "Not run yet: `egc-teleop bench sim`" in page
    # a result of another shape is shown as its numbers, not a crash
    assert "does not have the shape this page expects" in page and "| `tcp` | 1 |" in page
    # the summary's links go to the sections' headings
    headings = {bench_report.anchor(h) for h in re.findall(r"^## (.*)$", page, re.M)}
    targets = re.findall(r"\]\(#([^)]+)\)", page)
    assert len(targets) == 3 and set(targets) <= headings
    assert (
        bench_report.render({"filter": _filter_result(19.4)}, ["filter"], {}).count("**missed**")
        == 0
    )


def test_bench_report_writes_the_page_from_the_results(tmp_path: Path) -> None:
    out = tmp_path / "benchmarks.md"
    cli = [sys.executable, "-m", "egc_app.cli", "bench", "report"]
    proc = subprocess.run([*cli, "--out", str(out)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert out.read_text() == bench_report.page_text()
    proc = subprocess.run([*cli, "--bogus"], capture_output=True, text=True, timeout=120)
    err = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(err) == 1 and "'report' takes only --out" in err[0]
    proc = subprocess.run(
        [*cli, "--out", str(tmp_path / "no" / "page.md")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2 and "not a file in an existing folder" in proc.stderr


def test_every_committed_result_renders_with_its_own_section() -> None:
    """A benchmark whose result file changed shape must get its renderer changed with it: the
    committed results all render without the generic fallback (the bandwidth section showed
    only its top-level numbers for a day)."""
    results = load_results()
    assert "bandwidth" in results
    for name, result in results.items():
        renderer = bench_report.RENDERERS.get(name)
        if renderer is None:
            continue
        assert "does not have the shape" not in "\n".join(
            bench_report._rendered(renderer, result)
        ), name
