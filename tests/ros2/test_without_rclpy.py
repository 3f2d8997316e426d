"""Without rclpy, ``--driver ros2`` and ``sim --ros2`` say which extra to install, in one line,
and exit non-zero (DESIGN 11). rclpy is hidden by a module earlier on the path that fails to
import, the way a missing package does; these run whether or not ROS 2 is installed."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest
from egc_common.transport import free_tcp_port, loopback_endpoint


@pytest.fixture
def no_rclpy_env(tmp_path):
    hidden = tmp_path / "hide"
    hidden.mkdir()
    (hidden / "rclpy.py").write_text("raise ModuleNotFoundError(\"No module named 'rclpy'\")\n")
    path = os.pathsep.join(p for p in (str(hidden), os.environ.get("PYTHONPATH")) if p)
    return dict(os.environ, PYTHONPATH=path)


@pytest.mark.parametrize(
    "args",
    [
        ["robot", "--driver", "ros2", "--listen", "PORT"],
        ["sim", "--ros2"],
    ],
    ids=["robot", "sim"],
)
def test_missing_rclpy_is_one_line_naming_the_extra(no_rclpy_env, args):
    args = [loopback_endpoint(free_tcp_port()) if a == "PORT" else a for a in args]
    out = subprocess.run(
        [sys.executable, "-m", "egc_app.cli", *args],
        env=no_rclpy_env,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode != 0
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1, out.stderr
    assert "pip install -e '.[ros2]'" in lines[0]
    assert "Traceback" not in out.stderr + out.stdout


@pytest.mark.parametrize(
    ("args", "config", "message"),
    [
        (["--driver", "ros2", "--laser-pose", "-0.1,0"], None,
         "laser pose must be X,Y,YAW in metres and radians, got '-0.1,0'"),
        # The robot TOML's [ros2] is checked even when the robot runs on the simulator.
        (["--driver", "sim"], "[ros2]\nscan = 3\n", "ros2 scan must be a string, got 3"),
    ],
)  # fmt: skip
def test_bad_ros2_settings_are_one_line(tmp_path, args, config, message):
    if config is not None:
        (tmp_path / "robot.toml").write_text(config)
        args = [*args, "--config", str(tmp_path / "robot.toml")]
    out = subprocess.run(
        [sys.executable, "-m", "egc_app.cli", "robot", *args],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 2
    assert out.stderr.strip().splitlines() == [f"egc-teleop robot: error: {message}"]
