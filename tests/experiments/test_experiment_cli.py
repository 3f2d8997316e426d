"""``egc-teleop experiment`` (DESIGN 10): outputs, resume, and exit 2 on bad input.

The end-to-end run and two bad command lines go through the console script in its own process;
the rest through the subcommand's parser and ``run`` in this one (``experiment_here``).
"""

from __future__ import annotations

import json
import sys

import pytest
from egc_common.cli_args import CliArgumentParser
from egc_common.errors import UsageError
from egc_experiments import experiment_cli
from egc_experiments.experiment_cli import run_key
from egc_experiments.grid import load_grid
from egc_experiments.run_point import RESULT_KEYS

from tests.cli_process import main
from tests.experiments.subcommand import run_subcommand

TINY = """
description = "tiny"
world = "random:2"
operator = "sighted"
filter = "none"
max_time_s = 6
[[sweep]]
delay_ms = [0, 200]
"""


def write_grid(tmp_path, text=TINY):
    path = tmp_path / "grid.toml"
    path.write_text(text)
    return path


def experiment(grid, out, *extra):
    """``egc-teleop experiment`` as a real process (the console script)."""
    return main(["experiment", "--grid", str(grid), "--out", str(out), *extra])


def experiment_here(grid, out, *extra):
    """The same command line through the subcommand's parser and ``run`` in this process."""
    argv = ["--grid", str(grid), "--out", str(out), *extra]
    return run_subcommand(experiment_cli, "experiment", argv)


def lines(path):
    return [json.loads(line) for line in path.read_text().splitlines()]


def test_a_tiny_grid_end_to_end(tmp_path, capsys):
    grid, out = write_grid(tmp_path), tmp_path / "out"
    assert experiment(grid, out, "--jobs", "2") == 0
    rows = lines(out / "runs.jsonl")
    assert len(rows) == 2
    assert {r["delay_ms"] for r in rows} == {0.0, 200.0}
    for r in rows:
        assert set(RESULT_KEYS) <= set(r)
        assert r["run_mode"] == "simulated" and r["key"].startswith("simulated:")
    report = (out / "report.md").read_text()
    assert "tiny" in report and "## Against delay" in report and "--jobs 2" in report
    for name in ("outcome_vs_delay.png", "time_vs_delay.png", "hold_vs_delay.png"):
        assert (out / name).read_bytes().startswith(b"\x89PNG")
        assert f"]({name})" in report
    err = capsys.readouterr().err
    assert "2 of 2 runs" in err and "2 new" in err


def test_a_grid_jittered_at_every_delay_still_gets_its_delay_plots(tmp_path):
    """Outside check: jitter 20 ms at every delay point wrote report.md and no PNG at all."""
    grid = write_grid(
        tmp_path, TINY.replace("delay_ms = [0, 200]", "delay_ms = [50, 200]\njitter_ms = 20")
    )
    out = tmp_path / "out"
    assert experiment_here(grid, out) == 0
    report = (out / "report.md").read_text()
    for name in ("outcome_vs_delay.png", "time_vs_delay.png", "hold_vs_delay.png"):
        assert (out / name).read_bytes().startswith(b"\x89PNG")
        assert f"]({name})" in report


def test_a_rerun_with_another_grid_leaves_no_plot_of_the_earlier_one(tmp_path):
    """Outside check: the loss plot of an earlier grid stayed beside the new report in the same
    out dir (report.md did not link it, but a user saw it); files not ours are left alone."""
    out = tmp_path / "out"
    lossy = TINY.replace("[[sweep]]", 'transport = "udp"\n[[sweep]]\nloss = [0, 5]')
    assert experiment_here(write_grid(tmp_path, lossy), out) == 0
    assert (out / "outcome_vs_loss.png").exists()
    (out / "mine.png").write_bytes(b"the user's")
    assert experiment_here(write_grid(tmp_path), out) == 0
    report = (out / "report.md").read_text()
    pngs = sorted(p.name for p in out.glob("*.png"))
    assert pngs == ["hold_vs_delay.png", "mine.png", "outcome_vs_delay.png", "time_vs_delay.png"]
    assert all(f"]({name})" in report for name in pngs if name != "mine.png")
    assert (out / "mine.png").read_bytes() == b"the user's"


def test_the_delay_plots_take_the_least_jitter_at_each_delay():
    from egc_experiments.report import least_jitter_per_delay

    rows = [
        {"delay_ms": d, "jitter_ms": j}
        for d, j in [(0, 0), (100, 0), (100, 30), (200, 0), (200, 60)]
    ]
    kept, note = least_jitter_per_delay(rows)
    assert [(r["delay_ms"], r["jitter_ms"]) for r in kept] == [(0, 0), (100, 0), (200, 0)]
    assert note == "no jitter"
    kept, note = least_jitter_per_delay([r for r in rows if r["jitter_ms"]])
    assert len(kept) == 2 and note == "the least jitter at each delay"
    kept, note = least_jitter_per_delay([{"delay_ms": 5, "jitter_ms": 20}])
    assert note == "jitter 20 ms"


def test_a_rerun_skips_what_is_done_and_redoes_a_cut_line(tmp_path, capsys):
    grid, out = write_grid(tmp_path), tmp_path / "out"
    out.mkdir()
    points = load_grid(grid).points
    fake = {k: 0 for k in RESULT_KEYS} | {
        "key": run_key("simulated", points[0]),
        "outcome": "fake",
        "delay_ms": 0.0,
        "loss": 0.0,
        "jitter_ms": 0.0,
        "transport": "tcp",
        "mode": "direct",
        "filter": "none",
        "operator": "sighted",
        "world": "random:2",
    }
    cut = json.dumps({"key": run_key("simulated", points[1]), "outcome": "reached"})[:30]
    (out / "runs.jsonl").write_text(json.dumps(fake) + "\n" + cut)
    assert experiment_here(grid, out) == 0
    rows = lines(out / "runs.jsonl")
    assert rows[0]["outcome"] == "fake"  # kept, not run again
    assert len(rows) == 2 and rows[1]["delay_ms"] == 200.0
    err = capsys.readouterr().err
    assert "dropped 1 unreadable line" in err and "1 new" in err
    assert experiment_here(grid, out) == 0
    assert len(lines(out / "runs.jsonl")) == 2
    assert "0 new" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("grid_text", "message"),
    [
        ("[[sweep]\n", "not valid TOML"),
        (TINY.replace("random:2", "atlantis"), "world 'atlantis'"),
        (TINY.replace('filter = "none"', 'filter = "magic"'), "unknown filter"),
        (TINY.replace('"sighted"', '"pilot"'), "operator 'pilot'"),
        (TINY + "loss = 5\n", "loss is not possible on a TCP link"),
        (
            TINY.replace("delay_ms = [0, 200]", 'delay_ms = "fast"'),
            "delay_ms values must be numbers",
        ),
        # Outside check: a goal off the map ran (exit 0) to 'timeout', goal_distance_m 698.
        (
            TINY.replace('"random:2"', '"x"')
            + '[worlds.x]\nmap = "office02"\nstart = [-7, -1, 1.5708]\ngoal = [500, 500]\n',
            "grid.toml: [worlds.x]: goal 500,500 is outside map 'office02' "
            "(x -15 to 15, y -15 to 15 m)",
        ),
        (TINY.replace("delay_ms = [0, 200]", "delay_ms = [0, 1e15]"), "more than 600000 ms"),
    ],
)
def test_bad_grids_exit_2_with_one_line_and_write_nothing(tmp_path, capsys, grid_text, message):
    grid, out = write_grid(tmp_path, grid_text), tmp_path / "out"
    assert experiment_here(grid, out) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "\n" not in err and err.startswith("egc-teleop experiment: error")
    assert not out.exists()


def test_an_unwritable_out_dir_exits_2_before_running(tmp_path, capsys):
    grid = write_grid(tmp_path)
    blocker = tmp_path / "file"
    blocker.write_text("")
    assert experiment_here(grid, blocker) == 2
    assert "not a directory" in capsys.readouterr().err
    assert experiment_here(grid, blocker / "sub") == 2
    assert "cannot write to --out" in capsys.readouterr().err


@pytest.mark.parametrize("name", ["report.md", "runs.jsonl", "hold_vs_delay.png", "report.md.tmp"])
def test_an_output_file_that_is_a_directory_exits_2_before_running(tmp_path, capsys, name):
    grid, out = write_grid(tmp_path), tmp_path / "out"
    (out / name).mkdir(parents=True)
    assert experiment_here(grid, out) == 2
    err = capsys.readouterr().err.strip()
    assert f"{name}: it is a directory" in err and "\n" not in err
    assert sorted(p.name for p in out.iterdir()) == [name]  # nothing run, nothing written


def test_an_empty_out_exits_2(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    grid = write_grid(tmp_path)
    assert experiment_here(grid, "") == 2
    assert "--out needs a directory name" in capsys.readouterr().err
    assert not (tmp_path / "runs.jsonl").exists()


def test_bad_arguments_exit_2(tmp_path, capsys):
    """Two of them through the console script: its UsageError line and its parser's error are
    what ``experiment_here`` restates for the other tests of this file."""
    grid = write_grid(tmp_path)
    assert experiment(tmp_path / "none.toml", tmp_path / "o") == 2
    err = capsys.readouterr().err.strip()
    assert "does not exist" in err and "\n" not in err
    assert err.startswith("egc-teleop experiment: error: ")
    assert experiment_here(grid, tmp_path / "o", "--jobs", "0") == 2
    assert "--jobs" in capsys.readouterr().err
    assert experiment(grid, tmp_path / "o", "--mode", "real") == 2
    assert "invalid choice: 'real'" in capsys.readouterr().err


def test_emulated_mode_without_its_module_is_refused(tmp_path, monkeypatch):
    """In this process (the module hidden from it), through the subcommand's own parser and
    ``run``: its UsageError is the one line and exit 2 of every subcommand (egc_app.cli)."""
    monkeypatch.setitem(sys.modules, "egc_experiments.emulated", None)
    parser = CliArgumentParser(prog="egc-teleop experiment")
    experiment_cli.configure(parser)
    grid = write_grid(tmp_path)
    args = parser.parse_args(
        ["--grid", str(grid), "--out", str(tmp_path / "o"), "--mode", "emulated"]
    )
    with pytest.raises(UsageError, match="--mode emulated needs"):
        experiment_cli.run(args)
    assert not (tmp_path / "o").exists()
