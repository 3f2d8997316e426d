"""``egc-teleop episode``: pinned JSON keys, errors, batch, recording, the robot's pipeline."""

from __future__ import annotations

import json

import egc_experiments.episode as episode
import egc_robot.pipeline
import numpy as np
import pytest
from egc_sim.episodes import OUTCOMES

from tests.cli_process import main
from tests.sim.helpers import write_map_yaml

PINNED = {
    "reached",
    "collided",
    "time_s",
    "path_m",
    "min_clearance_m",
    "interventions",
    "steps",
    "wall_s",
}


def run_cli(capsys, *argv):
    code = main(["episode", *argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_single_episode_prints_one_json_object(capsys):
    code, out, err = run_cli(
        capsys,
        "--map",
        "hallway",
        "--start",
        "0.6,0.6,0",
        "--goal",
        "4,2",
        "--operator",
        "forward",
        "--filter",
        "none",
        "--max-time",
        "30",
        "--json",
    )
    assert code == 0 and err == ""
    lines = out.strip().splitlines()
    assert len(lines) == 1
    result = json.loads(lines[0])
    assert set(result) >= PINNED
    # Straight into obstacle A (x = 3.2 - 0.3 at y 0.6): contact after ~2.1 m.
    assert result["collided"] and not result["reached"] and result["outcome"] == "collided"
    assert result["min_clearance_m"] == 0.0 and result["interventions"] == 0
    assert 2.0 < result["path_m"] < 2.4
    assert result["steps"] == round(result["time_s"] / 0.05)


def test_egc_episode_counts_interventions_and_stays_clear(capsys):
    code, out, _ = run_cli(
        capsys, "--map", "hallway", "--operator", "forward", "--max-time", "40", "--json"
    )
    result = json.loads(out)
    assert code == 0 and not result["collided"]
    assert result["filter"] == "egc" and result["interventions"] > 10
    assert result["min_clearance_m"] > 0.2 and result["outcome"] == "timeout"


def test_the_controller_is_the_robots_pipeline():
    assert episode.step_command is egc_robot.pipeline.step_command


def test_deadman_released_means_no_motion(tmp_path, capsys):
    csv = tmp_path / "stick.csv"
    csv.write_text("t_s,x,y,deadman\n0.0,1.0,0.0,0\n")
    code, out, _ = run_cli(
        capsys, "--map", "hallway", "--operator", str(csv), "--max-time", "5", "--json"
    )
    result = json.loads(out)
    assert code == 0 and result["path_m"] == 0.0 and result["steps"] == 100


def test_stall_time_ends_a_deadlocked_episode(capsys):
    # The naive goal operator pushes at the obstacle on the line; EGC stops the robot for good.
    code, out, _ = run_cli(capsys, "--map", "random:0", "--stall-time", "3", "--json")
    result = json.loads(out)
    assert code == 0 and result["outcome"] == "stalled" and result["time_s"] < 30
    assert not result["reached"] and not result["collided"]


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--map", "no/such/map.yaml"], "cannot load map"),
        (["--map", "hallway", "--start", "1,2"], "--start X,Y,YAW"),
        (["--map", "hallway", "--goal", "a,b"], "--goal X,Y"),
        (["--map", "hallway", "--goal", ""], "--goal X,Y"),  # was the map's goal, silently
        (["--map", "hallway", "--start", ""], "--start X,Y,YAW"),
        (["--map", "hallway", "--goal", "1000,1000"], "outside map 'hallway' (x -0.2 to 18.2"),
        (["--map", "hallway", "--filter", "teleport"], "--filter"),
        (["--map", "hallway", "--profile", "roomba"], "--profile"),
        (["--map", "hallway", "--max-time", "-1"], "--max-time"),
        (["--map", "hallway", "--goal-tolerance", "0"], "--goal-tolerance"),
        (["--map", "hallway", "--start", "0.05,0.6,0"], "into an obstacle"),
        (["--map", "random:1", "--operator", "nope.csv"], "joystick file"),
        (["--random-worlds", "2", "--record", "out.rrd"], "single episode"),
        ([], "--map is required"),
    ],
)
def test_bad_arguments_exit_2_with_one_line(capsys, argv, message):
    code, out, err = run_cli(capsys, *argv, "--json")
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and message in err


def test_a_map_without_a_start_asks_for_one(tmp_path, capsys):
    free = np.full((40, 40), 254, dtype=np.uint8)
    map_yaml = write_map_yaml(tmp_path, free)  # no tests.txt beside it: no suggested start
    code, out, err = run_cli(capsys, "--map", str(map_yaml), "--json")
    assert code == 2 and out == ""
    assert err.strip().splitlines() == [
        f"egc-teleop episode: error: map {str(map_yaml)!r} suggests no start pose: "
        "give --start X,Y,YAW"
    ]


def test_an_mrpb_map_starts_at_its_first_test(capsys):
    # office02's tests.txt: test 1 starts at (-12.547, 8.542, 0) with its goal at (13.059, 1.702)
    code, out, _ = run_cli(
        capsys, "--map", "office02", "--operator", "forward", "--max-time", "1", "--json"
    )
    result = json.loads(out)
    assert code == 0 and not result["collided"]
    assert result["start"][:2] == pytest.approx([-12.547, 8.542], abs=0.01)


def test_argparse_errors_exit_2(capsys):
    assert main(["episode", "--max-time", "soon"]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


def test_batch_suite_runs_in_parallel_and_keeps_the_order(tmp_path, capsys):
    suite = tmp_path / "suite.jsonl"
    suite.write_text(
        '{"map": "hallway", "operator": "forward", "filter": "none", "max_time": 30}\n'
        "# a comment\n"
        '{"map": "random:3", "filter": "egc", "max_time": 20, "stall_time": 2}\n'
        '{"map": "hallway", "start": [0.05, 0.6, 0]}\n'
    )
    out_file = tmp_path / "results.jsonl"
    code, _out, err = run_cli(capsys, "--batch", str(suite), "--jobs", "2", "--out", str(out_file))
    rows = [json.loads(line) for line in out_file.read_text().splitlines()]
    assert code == 2  # the third episode cannot start
    assert [r.get("map") for r in rows] == ["hallway", "random:3", "hallway"]
    assert rows[0]["collided"] and rows[0]["filter"] == "none"
    assert rows[1]["outcome"] in OUTCOMES and not rows[1]["collided"]
    assert "into an obstacle" in rows[2]["error"]
    assert "3 episodes: 0 reached, 1 collided" in err


def test_random_worlds_batch_to_stdout(capsys):
    code, out, _ = run_cli(
        capsys, "--random-worlds", "3", "--seed", "10", "--filter", "none", "--jobs", "2"
    )
    rows = [json.loads(line) for line in out.strip().splitlines()]
    assert code == 0 and [r["map"] for r in rows] == ["random:10", "random:11", "random:12"]
    assert all(set(r) >= PINNED for r in rows)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ('{"operator": "goal"}\n', "at least a 'map'"),
        ('{"map": "hallway", "speed": 3}\n', "unknown key"),
        ("not json\n", "not JSON"),
        ('{"map": "hallway", "start": [1, 2]}\n', "start"),
        ('{"map": "hallway", "goal": "a,b"}\n', "suite.jsonl:1: goal must be 2"),
        ("\n", "no episodes"),
    ],
)
def test_bad_suites(tmp_path, capsys, text, message):
    suite = tmp_path / "suite.jsonl"
    suite.write_text(text)
    code, _, err = run_cli(capsys, "--batch", str(suite))
    assert code == 2 and message in err


def test_record_saves_the_operator_view_one_row_per_cycle(tmp_path, capsys):
    from tests.view.rrd import read_recording

    path = tmp_path / "episode.rrd"
    code, out, _ = run_cli(
        capsys,
        "--map",
        "hallway",
        "--operator",
        "forward",
        "--max-time",
        "3",
        "--record",
        str(path),
        "--json",
    )
    assert code == 0 and json.loads(out)["steps"] == 60
    recording = read_recording(path)
    assert len(recording["/plots/v/cmd"]) == 60 and len(recording["/robot/scan"]) == 60
    assert recording["/plots/v/ref"].column("Scalars:scalars")[-1] == [0.14]
    assert len(recording["/world/robot"]) == 60


def test_a_reader_that_goes_away_ends_it_quietly():
    """``egc-teleop episode ... | head -1``: no traceback when the pipe closes."""
    import subprocess
    import sys

    proc = subprocess.Popen(
        [sys.executable, "-m", "egc_app.cli", "episode", "--random-worlds", "4", "--jobs", "1",
         "--filter", "none", "--max-time", "5"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE,
    )  # fmt: skip
    assert proc.stdout is not None and proc.stderr is not None
    proc.stdout.readline()
    proc.stdout.close()  # the reader goes after the first line
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=60) == 141, err
    assert "Traceback" not in err
