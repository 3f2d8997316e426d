"""RunStats: the numbers of the demo's summary."""

from __future__ import annotations

import numpy as np
import pytest
from egc_common.messages import Odometry, Telemetry
from egc_robot.run_stats import RunStats


def tel(limiter: str) -> Telemetry:
    return Telemetry(1, 1, "DRIVING", "shared", 0.1, 0.0, 0.1, 0.0, 1.0, limiter=limiter)


def odom(x: float, y: float, collided: bool = False) -> Odometry:
    return Odometry(1, x, y, 0.0, 0.0, 0.0, collided)


def test_distance_interventions_collisions_and_latency():
    s = RunStats()
    for x, y, hit in [(0, 0, False), (3, 4, False), (3, 4, True), (3, 5, True), (3, 6, False)]:
        s.on_odometry(odom(x, y, hit))
    for limiter in ["none", "egc", "egc", "sweep", "none", "limits", "egc"]:
        s.on_cycle(tel(limiter))
    for ms in (1, 2, 3, 4):
        s.on_latency(ms * 1_000_000)
    out = s.summary()
    assert out["distance_m"] == pytest.approx(7.0)
    assert out["collisions"] == 1
    assert out["interventions"] == 4  # cycles, as the episode counts them
    assert out["intervention_onsets"] == 2  # egc..sweep is one stretch, the last egc another
    assert out["command_latency"]["p50_ms"] == pytest.approx(2.5)
    assert out["cycles_by_state"] == {"DRIVING": 7}


def test_empty_summary_has_no_percentiles():
    assert RunStats().summary()["command_latency"] == {
        "n": 0,
        "p50_ms": None,
        "p90_ms": None,
        "p99_ms": None,
        "max_ms": None,
    }


def test_view_timeline_per_second():
    """DESIGN 12's view_timeline: per second of the robot's clock, the view age's largest and
    median, the view plane's kbit/s and budget, camera frames sent, the newest camera frame's
    age at best and the largest command latency."""
    s = RunStats()
    second = 1_000_000_000
    frames = 0
    for i in range(80):  # 4 s at 20 Hz, the view age a 20-70 ms sawtooth
        t = 10 * second + i * 50_000_000
        age = 20.0 + i % 6 * 10
        s.on_cycle(Telemetry(i, t, "DRIVING", "shared", 0.1, 0.0, 0.1, 0.0, 1.0, view_age_ms=age))
        frames += i % 2  # 10 frames a second
        s.on_view_rate(t, 300.0, budget_kbps=350.0, camera_frames=frames)
        s.on_camera_age(120.0 - i % 2 * 40, t)
        s.on_latency((5 + i) * 1_000_000, t)
    timeline = {e["t_s"]: e for e in s.summary()["view_timeline"]}
    first, later = timeline[10], timeline[13]
    assert first["view_age_ms"] == 70.0 and first["view_age_p50_ms"] == 40.0
    assert later["view_age_p50_ms"] == 40.0  # the last second, flushed by summary()
    assert later["kbps"] == 300.0 and later["budget_kbps"] == 350.0 and later["cam_frames"] == 10
    assert "kbps" not in first  # a partial first window is left out
    assert first["camera_age_ms"] == 80.0 and first["cmd_age_ms"] == 24.0
    assert later["cmd_age_ms"] == 84.0


def test_the_fixed_rate_loop_s_lateness_against_its_period():
    stats = RunStats()
    assert stats.summary()["loop_overrun_p99"] is None  # no cycle yet
    for k in range(200):  # 50 ms period; two cycles in a hundred start 40 ms late
        stats.on_loop_start(40_000_000 if k % 50 == 0 else 1_000_000, 50_000_000)
    stats.on_loop_start(-5, 50_000_000)  # early (a clock read before the deadline): 0
    s = stats.summary()
    assert s["loop_period_ms"] == 50.0 and s["loop_late_ms"]["n"] == 201
    assert s["loop_late_ms"]["p50_ms"] == pytest.approx(1.0)
    assert s["loop_overrun_p99"] == pytest.approx(s["loop_late_ms"]["p99_ms"] / 50.0, abs=1e-3)
    assert s["loop_overrun_p99"] > 0.5  # 2 % of the cycles more than half a period late


def test_a_long_run_keeps_bounded_samples_with_exact_count_and_max():
    """Five hours of 50 Hz command latencies: the series keeps at most its cap, evenly spread
    (the percentiles of a slow ramp stay where the ramp's are), and n and max are exact."""
    from egc_robot.run_stats import SERIES_CAP, _Series

    series = _Series()
    n = 5 * 3600 * 50
    ramp = np.linspace(0.0, 100.0, n)  # ms; the true p50 is 50, p90 90
    for value in ramp:
        series.add(float(value))
    assert series.n == n and series.max == 100.0
    assert SERIES_CAP // 2 <= series.values.size <= SERIES_CAP
    assert np.percentile(series.values, 50) == pytest.approx(50.0, abs=0.05)
    assert np.percentile(series.values, 90) == pytest.approx(90.0, abs=0.05)
    small = _Series(cap=8)
    for value in range(100):
        small.add(float(value))
    assert small.values.size <= 8 and small.n == 100 and small.max == 99.0
    assert np.all(np.diff(small.values) > 0)  # in order, spread over the whole run
    assert small.values[-1] >= 80.0 and small.values[0] <= 10.0


def test_memory_is_fixed_from_the_start():
    """Issue 31's soak: what the statistics hold is allocated when they start, so a robot's RSS
    does not climb through its first hour. Four minutes of 50 Hz commands and 20 Hz cycles with
    every timeline column filled: nothing retained grows after the first minute."""
    import tracemalloc

    second = 1_000_000_000
    stats = RunStats()
    tracemalloc.start()
    try:
        after_first_minute = 0
        for k in range(4 * 60 * 50):
            t = 100 * second + k * 20_000_000
            stats.on_latency(5_000_000 + k % 7 * 1_000_000, t)
            stats.on_camera_age(100.0 + k % 5, t)
            if k % 5 == 0:
                stats.on_view_rate(t, 300.0, budget_kbps=350.0, camera_frames=k // 5)
            if k % 2 == 0:
                view = Telemetry(k, t, "DRIVING", "shared", 0.1, 0.0, 0.1, 0.0, 1.0, 40.0 + k % 3)
                stats.on_cycle(view)
                stats.on_loop_start(1_000_000, 50_000_000)
            if k == 60 * 50:
                after_first_minute = tracemalloc.get_traced_memory()[0]
        grown = tracemalloc.get_traced_memory()[0] - after_first_minute
    finally:
        tracemalloc.stop()
    assert grown < 20_000, f"{grown} bytes more after four minutes than after one"
    timeline = stats.summary()["view_timeline"]
    assert len(timeline) == 240 and timeline[-1]["t_s"] == 339
