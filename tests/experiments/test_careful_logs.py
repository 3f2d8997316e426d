"""Careful-drive logs of our own worlds and the filters' intervention on them (issue 28)."""

from __future__ import annotations

import json

import pytest
from egc_experiments.careful_logs import drives, main, summary_table

from tests.sim.helpers import MRPB


def test_the_drives_are_fresh_random_worlds_and_every_mrpb_test():
    todo = drives(3, 5000, "jackal", MRPB)
    names = [d.name for d in todo]
    assert names[:3] == ["random-5000", "random-5001", "random-5002"]
    assert {d.settings.operator for d in todo} == {"careful"}
    assert {d.settings.filter for d in todo} == {"none"}  # nothing helps the careful driver
    mrpb = [d for d in todo if d.name.startswith("mrpb-")]
    assert len(mrpb) == 19 and "mrpb-shopping_mall-1" in names
    assert all(d.settings.start is not None and d.settings.goal is not None for d in mrpb)


def test_the_table_adds_up_over_logs():
    rows = [
        {"filter": "egc", "commands": 100, "changed": 90, "mean_cut": 0.3, "hold_s": 1.0},
        {"filter": "egc", "commands": 300, "changed": 30, "mean_cut": 0.1, "hold_s": 0.5},
        {"filter": "none", "commands": 100, "changed": 0, "mean_cut": 0.0, "hold_s": 0.0},
    ]
    table = summary_table(rows, ["none", "egc", "cbf"])
    egc = next(line for line in table.splitlines() if line.startswith("| egc"))
    # 120 of 400 over both logs; per log 10% and 90%; mean cut weighted by commands.
    assert egc == "| egc | 2 | 400 | 120 | 30.0% | 90.0% | 90.0% | 0.1500 | 1.50 |"
    assert "| none | 1 | 100 | 0 | 0.0% |" in table and "| cbf" not in table


def test_a_careful_log_is_made_kept_and_replayed(tmp_path, capsys):
    out = tmp_path / "careful"
    argv = ["--out", str(out), "--random", "1", "--seed", "5001", "--mrpb", "none"]
    assert main([*argv, "--filters", "none,egc", "--jobs", "1"]) == 0
    (record,) = [json.loads(line) for line in (out / "drives.jsonl").read_text().splitlines()]
    assert record["outcome"] == "reached" and record["min_clearance_m"] >= 0.2
    assert record["log"] == str(out / "logs" / "random-5001.mcap") and record["why_not"] is None
    rows = [json.loads(line) for line in (out / "replay.jsonl").read_text().splitlines()]
    assert [r["filter"] for r in rows] == ["none", "egc"]
    assert rows[0]["scans"] == rows[0]["commands"] == record["steps"]
    assert rows[0]["changed"] == 0 and rows[1]["changed"] > 0
    assert "| egc | 1 |" in (out / "summary.md").read_text()
    # The same logs again: refused, nothing written over.
    before = (out / "logs" / "random-5001.mcap").read_bytes()
    assert main(argv) == 2
    assert "already holds" in capsys.readouterr().err
    assert (out / "logs" / "random-5001.mcap").read_bytes() == before
    # A run stopped during the replays (its last line cut short) goes on where it was.
    drives_text = (out / "drives.jsonl").read_text()
    first = (out / "replay.jsonl").read_text().splitlines()[0]
    (out / "replay.jsonl").write_text(first + "\n" + '{"log": "cut sho')
    assert main([*argv, "--filters", "none,egc", "--resume"]) == 0
    again = [json.loads(line) for line in (out / "replay.jsonl").read_text().splitlines()]
    assert again == rows
    assert (out / "drives.jsonl").read_text() == drives_text
    assert (out / "logs" / "random-5001.mcap").read_bytes() == before


@pytest.mark.parametrize(
    "argv", [["--filters", "egc,fast"], ["--jobs", "0"], ["--mrpb", "/nowhere"]]
)
def test_bad_arguments_exit_2(tmp_path, capsys, argv):
    assert main(["--out", str(tmp_path / "x"), "--random", "1", *argv]) == 2
    assert "careful_logs" in capsys.readouterr().err
