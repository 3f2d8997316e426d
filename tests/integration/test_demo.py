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
    stamps_ns = entities["/plots/v/cmd"].rows.column("robot_time").cast("int64").to_pylist()
    span_s = (stamps_ns[-1] - stamps_ns[0]) / 1e9
    # The view's sample rate over the drive, not a count over the 6 s: on a saturated machine
    # the processes start late and the drive is shorter (CI run 157: 37 samples over 3.4 s,
    # 10.8 a second). A view that saved one sample a second, or a handful, still fails.
    assert cycles >= 20, cycles
    assert cycles / span_s >= 5.0, (cycles, span_s)
    assert len(entities["/robot/scan"]) == cycles
    assert "/world/map" in entities  # the robot's map, fetched from egc/<robot>/map
    texts = [row[0] for row in entities["/log"].column("TextLog:text")]
    assert any("DRIVING" in text for text in texts), texts
