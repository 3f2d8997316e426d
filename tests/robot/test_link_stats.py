"""Link statistics on the robot's clock (DESIGN 7, 9)."""

from __future__ import annotations

import pytest
from egc_robot.link_stats import LinkStats

MS = 1_000_000


def feed(stats: LinkStats, seqs, period_ms=20, age_ms=100, t0=0):
    t = t0
    for seq in seqs:
        t += period_ms * MS
        stats.on_arrival(seq, t)
        stats.on_accepted(age_ms * MS, 150, t)
    return t


def test_ages_and_tau():
    stats = LinkStats()
    t = feed(stats, range(1, 51), age_ms=100)
    f = stats.figures(t)
    assert f.cmd_age_p50_ms == pytest.approx(100) and f.cmd_age_p90_ms == pytest.approx(100)
    assert f.loop_delay_s == pytest.approx(0.1 + 0.15 + 0.25)
    assert f.link_loss == 0.0 and f.cmd_gap_max_ms == pytest.approx(20)


def test_loss_from_seq_gaps():
    stats = LinkStats()
    t = feed(stats, [s for s in range(1, 101) if s % 10], period_ms=10)  # every 10th lost
    assert stats.figures(t).link_loss == pytest.approx(0.1, abs=0.02)


def test_open_gap_grows_during_an_outage_and_the_window_forgets():
    stats = LinkStats()
    t = feed(stats, range(1, 11))
    assert stats.figures(t + 600 * MS).cmd_gap_max_ms == pytest.approx(600)
    t = feed(stats, range(11, 80), t0=t + 600 * MS)
    assert stats.figures(t).cmd_gap_max_ms == pytest.approx(20)  # > 1 s later


def test_reset_forgets_the_session():
    stats = LinkStats()
    t = feed(stats, range(1, 11))
    stats.reset()
    f = stats.figures(t)
    assert f.cmd_age_p50_ms is None and f.link_loss is None and f.view_age_ms is None


def test_percentiles_match_numpy():
    import numpy as np

    rng = np.random.default_rng(3)
    stats = LinkStats()
    ages = rng.integers(50, 400, size=37)
    for i, age in enumerate(ages):
        stats.on_arrival(i + 1, i * 20 * MS)
        stats.on_accepted(int(age) * MS, None, i * 20 * MS)
    f = stats.figures(36 * 20 * MS)
    assert f.cmd_age_p50_ms == pytest.approx(np.percentile(ages, 50))
    assert f.cmd_age_p90_ms == pytest.approx(np.percentile(ages, 90))


def test_run_totals_count_missing_seq_and_survive_a_new_session():
    stats = LinkStats()
    feed(stats, [1, 2, 4, 5, 9, 10])  # 3, 6, 7, 8 missing
    assert (stats.received_total, stats.missing_total) == (6, 4)
    stats.on_arrival(7, 0)  # late, fills one gap
    assert stats.missing_total == 3
    stats.reset()
    feed(stats, [1, 3])  # a new session numbers from 1 again
    assert (stats.received_total, stats.missing_total) == (9, 4)


def test_a_gap_longer_than_the_window_shows_once_it_ends():
    # An outside check: after a 1.8 s outage the first telemetry said "gap max 1 ms", since the
    # arrival before the gap had already left the 1 s window.
    stats = LinkStats()
    t = feed(stats, range(1, 11))
    t_back = t + 1800 * MS
    stats.on_arrival(11, t_back)
    assert stats.figures(t_back).cmd_gap_max_ms == pytest.approx(1800)
    assert stats.figures(t_back + 900 * MS).cmd_gap_max_ms == pytest.approx(1800)
    t = feed(stats, range(12, 80), t0=t_back + 20 * MS)
    assert stats.figures(t).cmd_gap_max_ms == pytest.approx(20)  # gone a second later
