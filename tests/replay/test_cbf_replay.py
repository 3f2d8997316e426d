"""``cbf`` through the replay (DESIGN 11, 13): silent on careful driving, holding before a crash.

Logs are built in memory and fed to ``replay_core`` the way ``egc-teleop replay`` feeds a file:
``LogScan`` + the command in effect, one scan at a time, then ``summarize``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from egc_common.profiles import JACKAL
from egc_robot.replay_core import (
    LogScan,
    Replayer,
    ScanVerdict,
    VelocitySample,
    scan_points,
    summarize,
)
from egc_sim.random_field import random_world

from tests.replay.careful_drives import careful_drive, replay_drive
from tests.replay.logs import wall_ranges

PERIOD_NS = 100_000_000  # 10 Hz, as Mapping1.bag's scans
BEAMS = 360
A_MIN, A_INC = -math.pi, 2 * math.pi / BEAMS


def replay(ranges: list[np.ndarray], commands: list[tuple[float, float]], name: str):
    replayer = Replayer.for_filter(name, JACKAL)
    verdicts: list[ScanVerdict] = []
    for i, (r, (v, w)) in enumerate(zip(ranges, commands, strict=True)):
        t = (i + 1) * PERIOD_NS
        scan = LogScan(t, t, A_MIN, A_INC, 0.05, 10.0, np.asarray(r, dtype=np.float64))
        verdict, *_ = replayer.step(
            scan, scan_points(scan, JACKAL.half_size_m), VelocitySample(t, v, w)
        )
        verdicts.append(verdict)
    limits = (JACKAL.v_max_mps, JACKAL.w_max_radps)
    return verdicts, summarize(verdicts, name, JACKAL.name, None, limits).as_dict()


def test_a_drive_into_a_wall_at_half_a_metre_per_second_is_held_half_a_second_before_contact():
    speed = 0.5
    front = 0.5 * JACKAL.length_m
    # The wall ahead of the laser (at the robot's centre), 5 cm nearer every scan, until contact.
    walls = [3.0 - speed * 0.1 * i for i in range(200)]
    walls = [d for d in walls if d >= front]
    verdicts, summary = replay([wall_ranges(d) for d in walls], [(speed, 0.0)] * len(walls), "cbf")
    contact_s = (walls[0] - front) / speed  # log time from the first scan
    held_from = None
    for i, verdict in enumerate(verdicts):
        if verdict.held and held_from is None:
            held_from = i * 0.1
        elif not verdict.held:
            held_from = None  # the hold must last until contact
    assert held_from is not None
    assert contact_s - held_from >= 0.5, (contact_s, held_from)
    assert summary["max_cut_mps"] >= 0.4
    assert summary["hold_s"] >= 0.5
    # Nothing changed while the wall was far: no more than a second's worth of braking before.
    first_change = next(i for i, v in enumerate(verdicts) if v.changed) * 0.1
    assert contact_s - first_change <= 1.0


@pytest.mark.parametrize("world", ["free", "far walls"])
def test_an_open_field_changes_nothing(world):
    rng = np.random.default_rng(3)
    n = 300
    if world == "free":
        ranges = [np.full(BEAMS, np.inf)] * n  # REP 117: nothing within range_max
    else:
        a = A_MIN + A_INC * np.arange(BEAMS)
        room = np.minimum(6.0 / np.abs(np.cos(a) + 1e-12), 6.0 / np.abs(np.sin(a) + 1e-12))
        ranges = [np.minimum(room, 9.5)] * n
    commands = [(float(v), float(w)) for v, w in rng.uniform([-0.8, -1.5], [2.0, 1.5], (n, 2))]
    _, summary = replay(ranges, commands, "cbf")
    assert summary["commands"] == n
    assert (summary["changed"], summary["changed_share"], summary["mean_cut"]) == (0, 0.0, 0.0)
    assert summary["hold_s"] == 0.0


def test_the_summary_carries_design_13s_metrics():
    walls = [1.0, 0.6, 0.4]
    _, summary = replay([wall_ranges(d) for d in walls], [(0.5, 0.5)] * 3, "cbf")
    assert summary["changed_share"] == pytest.approx(summary["changed"] / summary["commands"])
    assert 0.0 < summary["mean_cut"] <= 2.0
    assert {"changed", "changed_share", "mean_cut", "hold_s"} <= summary.keys()


def test_a_careful_drive_is_left_alone():
    """A drive that keeps its footprint 0.2 m clear of everything at up to 0.8 m/s, through a
    random obstacle field: cbf changes at most 5 % of its commands, and no more than dwa."""
    world = random_world(0)
    drive = careful_drive(world, JACKAL, world.start_pose, world.goal)
    assert drive is not None and drive.reached and drive.min_clearance_m >= 0.2
    assert max(c.linear_mps for c in drive.commands) == pytest.approx(0.8)
    cbf = replay_drive(drive, "cbf", JACKAL)
    dwa = replay_drive(drive, "dwa", JACKAL)
    assert cbf["changed_share"] <= 0.05
    assert cbf["changed"] <= dwa["changed"]
