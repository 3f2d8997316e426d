"""Smoke test of the operator-view benchmark (the full run is ``python bench/bench_view.py``)."""

from __future__ import annotations

import json
import runpy
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[2] / "bench" / "bench_view.py"


def test_a_short_run_reports_lag_cost_and_verdict(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bench = runpy.run_path(str(SCRIPT))
    out = tmp_path / "bench_view.json"
    code = bench["main"](["--minutes", "0.1", "--window", "2", "--out", str(out)])
    result = json.loads(out.read_text())
    assert code == (0 if result["keeps_up"] else 1)
    assert result["messages"] == 120 and len(result["windows"]) == 3
    for row in result["windows"]:
        assert row["messages"] == 40
        assert 0 < row["cost_median_ms"] <= row["lag_median_ms"] < 1000
    assert result["file_mb"] > 0
    assert "keeps up:" in capsys.readouterr().out
