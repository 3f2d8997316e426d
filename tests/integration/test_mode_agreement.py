"""The two experiment modes agree on the same grid point (DESIGN 10).

One point, ``hallway``, the ``forward`` operator (stick held forward, the paper's Fig. 9), EGC in
shared mode, link-aware, TCP, 100 ms delay with 20 ms jitter (normal) in each direction, 15 s,
run by ``egc_experiments.simulated.run_simulated`` (one process, simulated clock, the link model)
and by ``egc_experiments.emulated.run_emulated`` (the real robot, operator and relay processes
over Zenoh, in network namespaces when root, else on loopback).

Tolerances (also in docs/transport.md, "Simulated and emulated agree"):

- ``outcome`` equal (here ``timeout``: the corridor is longer than 15 s of driving);
- ``path_m`` within 15 % of the simulated one;
- ``hold_s`` within 1.0 s;
- ``min_clearance_m`` within 0.05 m;
- ``cmd_age_p50_ms`` within 30 ms (both near the 100 ms delay);
- ``interventions`` within 25 % (+- 5 cycles).

The relay must have forwarded what 15 s of driving sends: more than 500 commands up (50 Hz)
and 200 telemetry messages down (20 Hz), at its 100 ms delay.

Measured on this machine (15 s; two emulated runs): path 1.967 m (simulated) and 1.971-1.974 m
(emulated), hold 0.1 s and 0.0 s, clearance 0.3725 m in both, command age p50 106 ms and
109 ms, 61 and 57-59 interventions; the relay forwarded ~795 up and ~450 down at p50 107 ms.
The episode was 30 s until the suite had to fit its 10 min (path 4.035 m and 4.039 m, 92 and
93 interventions); 15 s compares the same things. docs/transport.md has both.
"""

from __future__ import annotations

import pytest
from egc_experiments.emulated import run_emulated
from egc_experiments.run_point import RESULT_KEYS, RunPoint
from egc_experiments.simulated import run_simulated

pytestmark = [pytest.mark.integration, pytest.mark.timeout(180)]

POINT = RunPoint(
    world="hallway",
    operator="forward",
    filter="egc",
    mode="shared",
    transport="tcp",
    delay_ms=100.0,
    jitter_ms=20.0,
    seed=0,
    max_time_s=15.0,
)


@pytest.mark.slow
def test_simulated_and_emulated_agree_on_one_grid_point(tmp_path):
    simulated = run_simulated(POINT)
    emulated = run_emulated(POINT, tmp_path / "emulated")
    for result in (simulated, emulated):
        assert set(RESULT_KEYS) <= set(result)
    pairs = {k: (simulated[k], emulated[k]) for k in RESULT_KEYS}
    assert emulated["outcome"] == simulated["outcome"], pairs
    assert emulated["reached"] == simulated["reached"] and not emulated["collided"], pairs
    assert emulated["path_m"] == pytest.approx(simulated["path_m"], rel=0.15), pairs
    assert abs(emulated["hold_s"] - simulated["hold_s"]) <= 1.0, pairs
    assert emulated["min_clearance_m"] == pytest.approx(simulated["min_clearance_m"], abs=0.05)
    assert emulated["cmd_age_p50_ms"] == pytest.approx(simulated["cmd_age_p50_ms"], abs=30), pairs
    assert emulated["interventions"] == pytest.approx(
        simulated["interventions"], rel=0.25, abs=5
    ), pairs
    # the commands really crossed the relay, both ways, with its delay
    link = emulated["link"]
    assert link["up"]["forwarded"] > 500 and link["down"]["forwarded"] > 200, link
    assert link["up"]["p50_ms"] == pytest.approx(100, abs=15), link


# The goal operator with DWA, which steers to the operator's via point: the emulated operator
# process must send the goal as its via point as the simulated mode does (before, it sent none
# and every emulated run stalled where the simulated one reached the goal). The start and goal
# are the middle 40 % of random:2's own start-goal line, so its on-line obstacle stands between
# them: with the via point both modes go round it and reach the goal in ~16 s (the whole line
# took 40 s); without it (``RobotController.on_goal`` a no-op) the simulated run stalls after
# 1.0 m, in front of the obstacle. Measured on this machine: reached in 15.45 s over 2.13 m
# simulated (the same for seeds 0-7 and with 20 ms of delay), 15.46-15.48 s over 2.12-2.13 m
# emulated on a quiet machine (on a busy one, 20.4-21.4 s over 2.81 m the other way round in
# three CI runs); the test took 21 s (50 s with the whole line).
# Interventions are not compared (DWA's limiter is counted per telemetry message, and the
# robot also cycles on each 50 Hz command).
VIA_POINT = RunPoint(
    world="random:2",
    operator="goal",
    filter="dwa",
    mode="shared",
    transport="tcp",
    seed=11,
    start=(2.38, 1.55, 0.02),
    goal=(4.62, 1.59),
    max_time_s=40.0,
    stall_time_s=20.0,
)


@pytest.mark.slow
def test_both_modes_steer_to_the_operators_via_point(tmp_path):
    simulated = run_simulated(VIA_POINT)
    emulated = run_emulated(VIA_POINT, tmp_path / "emulated")
    shown = ("outcome", "path_m", "time_s", "hold_s", "cmd_age_p50_ms", "min_clearance_m")
    pairs = {k: (simulated.get(k), emulated.get(k)) for k in shown}
    assert simulated["outcome"] == "reached", pairs
    assert emulated["outcome"] == simulated["outcome"], pairs
    assert not emulated["collided"], pairs
    # The obstacle stands on the start-goal line, so DWA may pass it on either side: +y over
    # 2.13 m (the simulated run), or -y over 2.81 m (CI runs 52, 55 and 57). Run 57's robot was
    # not late: command age p50 12 ms and cycle lateness p50 15 ms, as in run 56's +y drive
    # beside it (16 and 15 ms), and no HOLD. Either side is a way round; a robot that stalled,
    # wandered or backed off would drive further.
    assert 0.85 * simulated["path_m"] <= emulated["path_m"] <= 1.45 * simulated["path_m"], pairs
    # Real processes on a busy machine run late and hold now and then, so the emulated run
    # takes longer (15.4 s simulated against 26.8 s emulated at load 11-17); it is never much
    # faster, and not so slow that it stalled or wandered on the way.
    assert 0.75 * simulated["time_s"] <= emulated["time_s"] <= 2.5 * simulated["time_s"], pairs
