"""``egc-teleop demo`` headless: separate processes, a saved view, a summary, no orphans."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from tests.view.rrd import read_recording

pytestmark = [pytest.mark.integration, pytest.mark.timeout(90)]


def children_of(pid: int) -> list[int]:
    out = subprocess.run(["ps", "-o", "pid=", "--ppid", str(pid)], capture_output=True, text=True)
    return [int(p) for p in out.stdout.split()]


def test_demo_runs_headless_and_prints_a_summary(tmp_path):
    rrd = tmp_path / "demo.rrd"
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    proc = subprocess.Popen(
        [sys.executable, "-m", "egc_app.cli", "demo", "--duration", "6", "--save", str(rrd)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=tmp_path,
        env=env,
    )
    try:
        out, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 0, err
    assert "demo summary" in out
    for field in ("distance", "interventions", "collisions", "command latency p50"):
        assert field in out
    assert "collisions      0" in out
    assert rrd.stat().st_size > 0 and str(rrd) in err  # the view says where it saved
    assert children_of(proc.pid) == []

    # Issue 5: the saved view has the robot-frame view, the time series and the text log.
    entities = read_recording(rrd)
    for path in (
        "/robot/scan",
        "/robot/footprint",
        "/robot/circles/igc",
        "/robot/command/sent",
        "/plots/v/ref",
        "/plots/v/cmd",
        "/plots/w/ref",
        "/plots/w/cmd",
        "/plots/w_si",
        "/log",
    ):
        assert path in entities and len(entities[path]) > 0, (path, sorted(entities))
    cycles = len(entities["/plots/v/cmd"])
    # 20 Hz telemetry for a good part of the 6 s run: 59 at load 11-17, where the processes
    # start late; a view that saved one sample a second or none would still fail.
    assert cycles >= 20 * 2
    assert len(entities["/robot/scan"]) == cycles
    assert "/world/map" in entities  # the robot's map, fetched from egc/<robot>/map
    texts = [row[0] for row in entities["/log"].column("TextLog:text")]
    assert any("DRIVING" in text for text in texts), texts
