"""``--profile NAME|FILE.toml`` on the command line (DESIGN 14): the same files work for
``filter``, ``replay`` and ``episode``, and a bad file is one line naming the key, exit 2,
before anything runs."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from tests.cli_worker import main
from tests.replay.logs import corridor_log
from tests.shapes import L_SHAPE_FILE, PENTAGON_FILE

ROOT = Path(__file__).resolve().parents[2]
MAPPING1 = ROOT / ".." / "shared" / "bags" / "Mapping1.bag"

BAD = """
[profile]
name = "cart"
source = "a test"
footprint = [[0.3, 0.3], [-0.3, -0.3], [0.3, -0.3], [-0.3, 0.3]]
v_max = 0.5
w_max = 1.0
a_max = 0.5
a_dec = 1.0
alpha_max = 2.0
r_max = 1.2
"""

# ``filter``, ``replay`` and ``episode`` command lines run in one long-lived CLI process
# (``tests.cli_worker``): what they print and return is the point. A bad file is checked in
# real processes: nothing may start before it is refused.


@pytest.mark.parametrize(
    "argv",
    [
        ["filter"],
        ["episode", "--map", "hallway"],
        ["replay", "LOG"],
        ["sim"],
        ["robot"],
        ["demo", "--no-view", "--duration", "1"],
    ],
    ids=lambda a: a[0],
)
def test_a_bad_file_is_one_line_naming_the_key(argv, tmp_path):
    bad = tmp_path / "bowtie.toml"
    bad.write_text(BAD)
    argv = [str(tmp_path / "log") if a == "LOG" else a for a in argv]
    if argv[0] == "replay":
        corridor_log(tmp_path / "log", "mcap")
    proc = subprocess.run(
        [sys.executable, "-m", "egc_app.cli", *argv, "--profile", str(bad)],
        capture_output=True,
        text=True,
        timeout=60,
        stdin=subprocess.DEVNULL,
        cwd=tmp_path,
    )
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and proc.stdout == "", proc.stderr
    assert len(lines) == 1, lines
    assert lines[0].startswith(f"egc-teleop {argv[0]}: error: ")
    assert f"{bad}: footprint: self-intersecting polygon" in lines[0]


@pytest.mark.parametrize("profile", ["turtlebot4", "husky", str(PENTAGON_FILE), str(L_SHAPE_FILE)])
def test_filter_takes_names_and_files(profile, capsys):
    # A wall 1 m ahead: the command is cut by each robot's own radii and limits.
    line = {"v": 0.3, "w": 0.0, "points": [[1.0, y / 10] for y in range(-10, 11)]}
    code = main(["filter", "--profile", profile], stdin=json.dumps(line) + "\n")
    stdout, stderr = capsys.readouterr()
    assert code == 0, stderr
    out = json.loads(stdout)
    assert "error" not in out and out["final"]["v"] <= 0.3


@pytest.mark.parametrize("profile", [str(PENTAGON_FILE), "turtlebot4"])
def test_replay_takes_the_same_files(profile, tmp_path, capsys):
    log = corridor_log(tmp_path / "log", "mcap")
    rrd = tmp_path / "replay.rrd"
    code = main(["replay", str(log), "--profile", profile, "--record", str(rrd)])
    out, err = capsys.readouterr()
    assert code == 0, err
    summary = json.loads(out)
    name = "pentagon-cart" if profile.endswith(".toml") else profile
    assert summary["profile"] == name and summary["scans"] > 0
    assert rrd.stat().st_size > 0


@pytest.mark.slow
def test_replay_of_mapping1_with_a_polygon_file(capsys):
    code = main(["replay", str(MAPPING1), "--profile", str(L_SHAPE_FILE), "--filter", "dwa"])
    out, err = capsys.readouterr()
    assert code == 0, err
    summary = json.loads(out)
    assert summary["profile"] == "l-shape" and summary["scans"] == 1727


def test_episode_takes_a_file(tmp_path, capsys):
    code = main(
        ["episode", "--map", "hallway", "--profile", str(L_SHAPE_FILE), "--max-time", "5", "--json"]
    )
    out, err = capsys.readouterr()
    assert code == 0, err
    result = json.loads(out)
    assert not result["collided"] and result["time_s"] > 0


def test_the_profiles_laser_pose_is_the_ros2_default():
    """A profile's laser_pose places the laser for --driver ros2 unless [ros2] or the flag
    says otherwise."""
    from egc_robot.ros2_core import ros2_settings

    mounted = (0.2, -0.05, 3.14159)
    laser = ros2_settings({}, {}, default_laser_pose=mounted).laser
    assert (laser.x_m, laser.y_m, laser.yaw_rad) == mounted
    table = {"laser_pose": [0.1, 0.0, 0.0]}
    assert ros2_settings(table, {}, default_laser_pose=mounted).laser.x_m == 0.1
    flags = {"laser_pose": "0.3,0,0"}
    assert ros2_settings(table, flags, default_laser_pose=mounted).laser.x_m == 0.3
    assert ros2_settings({}, {}).laser.x_m == 0.0


def test_a_recorded_episode_draws_the_files_shape(tmp_path):
    """episode --record with a profile file: the view in that process knows the file's
    profile by the name telemetry carries, and draws its outline (the pentagon's nose)."""
    from tests.view.rrd import read_recording

    rrd = tmp_path / "pentagon.rrd"
    argv = ["episode", "--map", "hallway", "--profile", str(PENTAGON_FILE), "--max-time", "2"]
    assert main([*argv, "--record", str(rrd)]) == 0
    strips = read_recording(rrd)["/robot/footprint"].column("LineStrips2D:strips")
    outline = [p for p in strips[0][0]]
    assert len(outline) == 6 and max(x for x, _ in outline) == pytest.approx(0.35)


def test_profile_named_knows_loaded_files():
    from egc_common.profiles import PIONEER3DX, load_profile, profile_named

    assert profile_named("pioneer3dx") is PIONEER3DX
    loaded = load_profile(str(L_SHAPE_FILE))
    assert profile_named("l-shape") is loaded
    assert profile_named("no-such-robot") is None
