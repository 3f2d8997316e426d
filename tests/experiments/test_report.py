"""``egc_experiments.report`` on made-up runs: what the tables and plots show."""

from __future__ import annotations

from typing import Any

import pytest
from egc_experiments.report import write_plots, write_report


def run(**changes: Any) -> dict[str, Any]:
    """One runs.jsonl line (the keys the report reads), reached in 20 s."""
    row: dict[str, Any] = {
        "world": "random:2",
        "operator": "sighted",
        "filter": "none",
        "mode": "direct",
        "transport": "tcp",
        "delay_ms": 0.0,
        "jitter_ms": 0.0,
        "dist": "normal",
        "loss": 0.0,
        "burst": 0.0,
        "outages": [],
        "seed": 0,
        "link_aware": True,
        "outcome": "reached",
        "time_s": 20.0,
        "hold_s": 1.0,
        "hold_events": 1,
        "stale_rejected": 0,
        "mean_speed_mps": 0.3,
        "min_clearance_m": 0.4,
    }
    return row | changes


@pytest.fixture
def legend_labels(monkeypatch: pytest.MonkeyPatch) -> list[list[str]]:
    """The labels of every figure legend drawn, figure by figure."""
    from matplotlib.figure import Figure

    drawn: list[list[str]] = []
    legend = Figure.legend

    def spy(self: Figure, *args: Any, **kwargs: Any) -> Any:
        drawn.append(list(args[1]))
        return legend(self, *args, **kwargs)

    monkeypatch.setattr(Figure, "legend", spy)
    return drawn


def test_a_grid_with_only_burst_loss_gets_its_loss_plot(tmp_path, legend_labels):
    """Outside check: loss = [0, 5] with burst = 3 (Gilbert-Elliott loss only) gave a report
    without outcome_vs_loss.png: the plot took independent loss alone."""
    rows = [
        run(transport="udp", delay_ms=100.0, loss=loss, burst=burst, hold_s=hold, seed=seed)
        for loss, burst, hold in [(0.0, 0.0, 1.0), (5.0, 3.0, 4.0)]
        for seed in (0, 1)
    ]
    written = write_plots(rows, tmp_path)
    assert "outcome_vs_loss.png" in written
    assert (tmp_path / "outcome_vs_loss.png").read_bytes().startswith(b"\x89PNG")
    assert legend_labels == [["direct, link-aware on, bursts of 3"]]


def test_the_loss_plot_has_one_line_per_kind_of_loss(tmp_path, legend_labels):
    """Independent and bursty loss each get a line from the loss-free runs; a grid with
    independent loss alone keeps its plain labels."""
    rows = [
        run(transport="udp", loss=loss, burst=burst)
        for loss, burst in [(0, 0), (1, 0), (5, 0), (5, 3), (5, 10)]
    ]
    assert write_plots(rows, tmp_path) == ["outcome_vs_loss.png"]
    assert legend_labels[-1] == [
        "direct, link-aware on, bursts of 10",
        "direct, link-aware on, bursts of 3",
        "direct, link-aware on, independent",
    ]
    assert write_plots([r for r in rows if r["burst"] <= 1], tmp_path) == ["outcome_vs_loss.png"]
    assert legend_labels[-1] == ["direct, link-aware on"]


def section(report: str, heading: str) -> list[str]:
    """The table lines of one section of report.md."""
    body = report.split(f"## {heading}", 1)[1].split("\n## ", 1)[0]
    return [line for line in body.splitlines() if line.startswith("|")]


def test_jitter_at_delay_0_is_shown_in_ms_not_as_0_percent(tmp_path):
    """Outside check: the "jitter %" column read 0 at delay 0 whatever the jitter (a share of a
    zero delay), and put the jittered runs there in one line with the unjittered ones."""
    rows = [
        run(delay_ms=delay, jitter_ms=jitter, outcome=outcome, time_s=20.0 + jitter)
        for delay, jitter, outcome in [
            (0.0, 0.0, "reached"),
            (0.0, 20.0, "collided"),
            (100.0, 0.0, "reached"),
            (100.0, 30.0, "reached"),
        ]
    ]
    path = tmp_path / "report.md"
    write_report(rows, path, "jitter")
    report = path.read_text()
    assert "jitter %" not in report
    lines = section(report, "Against delay")
    assert lines[0].startswith("| delay ms | jitter ms | mode |"), lines[0]
    assert any(line.startswith("| 0 | 0 | direct | on | 1 | 100 | 0 |") for line in lines), lines
    assert any(line.startswith("| 0 | 20 | direct | on | 1 | 0 | 100 |") for line in lines), lines
    assert any(line.startswith("| 100 | 30 | direct | on | 1 | 100 |") for line in lines), lines
    for row in rows:  # the runs themselves are as they were
        assert set(row) >= {"delay_ms", "jitter_ms"} and "jitter_pct" not in row


def test_plots_an_earlier_grid_left_are_removed_and_nothing_else(tmp_path):
    """Outside check: a rerun into an out dir of an earlier grid left its loss and outage plots
    beside the new report (which did not link them)."""
    ours = ["outcome_vs_loss.png", "hold_vs_outage.png", "hold_vs_outage.tmp.png"]
    users = ["notes.png", "outcome_vs_loss_mine.png", "old/outcome_vs_loss.png", "runs.jsonl"]
    for name in ours + users:
        (tmp_path / name).parent.mkdir(exist_ok=True)
        (tmp_path / name).write_bytes(b"earlier")
    rows = [run(delay_ms=d) for d in (0.0, 200.0)]
    written = write_plots(rows, tmp_path)
    assert written == ["outcome_vs_delay.png", "time_vs_delay.png", "hold_vs_delay.png"]
    for name in ours:
        assert not (tmp_path / name).exists(), name
    for name in users:
        assert (tmp_path / name).read_bytes() == b"earlier", name
    for name in written:
        assert (tmp_path / name).read_bytes().startswith(b"\x89PNG")
