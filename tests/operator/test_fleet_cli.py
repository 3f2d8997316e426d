"""``egc-teleop operator`` without ``--robot`` (DESIGN 15): its options checked up front."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--robot", "r1", "--first", "r2"], "--first is for an operator without --robot"),
        (["--goal", "1,2"], "--goal and --route need --robot"),
        (["--first", "r/2"], "--first robot id 'r/2' must be"),
    ],
)
def test_fleet_options_are_checked_in_one_line(tmp_path: Path, argv: list[str], message: str):
    done = subprocess.run(
        [sys.executable, "-m", "egc_app.cli", "operator", "--script", "demo", "--no-view", *argv],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=60,
        stdin=subprocess.DEVNULL,
    )
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], done.stderr
