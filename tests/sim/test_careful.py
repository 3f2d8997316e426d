"""The ``careful`` operator model (issue 28): plans with clearance, drives smoothly, arrives."""

from __future__ import annotations

import math

import numpy as np
import pytest
from egc_common.profiles import JACKAL, PIONEER3DX
from egc_experiments.episode import EpisodeSettings, run_settings
from egc_sim.careful import (
    STEP_M,
    CarefulOperator,
    CarefulParams,
    curvature,
    footprint_clearances,
    plan_careful_path,
    speed_profile,
    wall_distance_m,
)
from egc_sim.collision import FootprintChecker
from egc_sim.grid_world import World
from egc_sim.observation import Observation
from egc_sim.operators import make_operator
from egc_sim.route import RouteError


def _room(gap_m: float) -> World:
    """6 m x 4 m room, a wall across x = 3 m with a gap of ``gap_m`` centred at y = 3 m."""
    occ = np.zeros((80, 120), dtype=bool)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = True
    lo, hi = round((3.0 - gap_m / 2) / 0.05), round((3.0 + gap_m / 2) / 0.05)
    occ[:lo, 59:61] = True
    occ[hi:, 59:61] = True
    return World("room", occ, np.zeros_like(occ), 0.05, 0.0, 0.0)


def _l_corridor(width_m: float) -> np.ndarray:
    """An L of corridors ``width_m`` wide: along x at the bottom, then up along y on the right
    (row 0 is the bottom row, as in an OccupancyGrid), in an 8 m x 8 m block."""
    occ = np.ones((160, 160), dtype=bool)
    w = round(width_m / 0.05)
    occ[20 : 20 + w, 20:140] = False  # bottom corridor, x 1 .. 7 m
    occ[20:140, 140 - w : 140] = False  # right corridor, y 1 .. 7 m
    return occ


def test_defaults_follow_the_profile():
    jackal = CarefulParams().resolved(JACKAL)
    assert jackal.speed_mps == pytest.approx(0.8)  # the careful drives of issue 28
    assert jackal.turn_radps == pytest.approx(1.0)
    assert jackal.accel_mps2 == pytest.approx(1.0) and jackal.decel_mps2 == pytest.approx(1.5)
    pioneer = CarefulParams().resolved(PIONEER3DX)
    assert pioneer.speed_mps == pytest.approx(0.4 * PIONEER3DX.v_max_mps)
    assert CarefulParams(speed_mps=9.0).resolved(JACKAL).speed_mps == JACKAL.v_max_mps
    with pytest.raises(ValueError, match="clearance_m"):
        CarefulParams(clearance_m=-0.1)
    with pytest.raises(ValueError, match="slow_fraction"):
        CarefulParams(slow_fraction=0.0)


def test_curvature_of_a_line_and_a_circle():
    s = np.arange(0.0, 3.0, STEP_M)
    line = np.stack([s, 0.5 * s], axis=1)
    assert np.allclose(curvature(line), 0.0)
    radius = 1.5
    a = np.arange(0.0, math.pi, STEP_M / radius)
    circle = np.stack([radius * np.cos(a), radius * np.sin(a)], axis=1)
    assert np.median(curvature(circle)) == pytest.approx(1 / radius, rel=0.02)


def test_speed_profile_slows_for_bends_and_narrow_places_and_stops_at_the_end():
    p = CarefulParams().resolved(JACKAL)
    assert p.speed_mps is not None and p.decel_mps2 is not None
    s = np.arange(0.0, 8.0 + STEP_M / 2, STEP_M)
    straight = np.stack([s, np.zeros_like(s)], axis=1)
    roomy = np.full(len(s), 2.0)
    v = speed_profile(straight, roomy, p)
    assert v[-1] == 0.0 and v.max() == pytest.approx(p.speed_mps)
    # Braking to the end at the comfortable deceleration, no harder.
    assert np.all(v[:-1] ** 2 - v[1:] ** 2 <= 2 * p.decel_mps2 * STEP_M + 1e-9)
    assert v[len(s) // 2] == pytest.approx(p.speed_mps)
    # A narrow stretch in the middle: slow there, and already braking before it.
    narrow = roomy.copy()
    narrow[70:90] = p.clearance_m
    v_narrow = speed_profile(straight, narrow, p)
    assert v_narrow[80] == pytest.approx(p.slow_fraction * p.speed_mps)
    assert v_narrow[68] < p.speed_mps and v_narrow[40] == pytest.approx(p.speed_mps)
    # A bend of radius 0.5 m: the lateral acceleration caps the speed there.
    a = np.arange(0.0, math.pi, STEP_M / 0.5)
    bend = np.stack([0.5 * np.cos(a), 0.5 * np.sin(a)], axis=1)
    v_bend = speed_profile(bend, np.full(len(a), 2.0), p)
    assert p.lateral_accel_mps2 is not None
    assert v_bend[len(a) // 2] <= math.sqrt(p.lateral_accel_mps2 * 0.5) * 1.05


def test_wall_distance_is_to_the_cell_squares():
    occ = np.zeros((20, 20), dtype=bool)
    occ[10, 10] = True
    d = wall_distance_m(occ, 0.05)
    assert d[10, 11] == pytest.approx(0.025)  # next to the cell: half a cell to its side
    assert d[10, 14] == pytest.approx(0.175)
    assert d[13, 14] == pytest.approx(0.05 * math.hypot(2.5, 3.5))
    assert d[0, 5] == pytest.approx(0.025)  # the outside of the grid blocks


def test_the_path_goes_through_the_middle_of_a_wide_enough_gap():
    world = _room(1.4)
    p = CarefulParams().resolved(JACKAL)
    path = plan_careful_path(world, (1.0, 1.0), (5.0, 1.0), JACKAL, p)
    assert tuple(path.xy[0]) == (1.0, 1.0) and tuple(path.xy[-1]) == (5.0, 1.0)
    crossing = path.xy[np.argmin(np.abs(path.xy[:, 0] - 3.0))]
    assert crossing[1] == pytest.approx(3.0, abs=0.1)
    checker = FootprintChecker(world, JACKAL.footprint)
    assert footprint_clearances(path.xy, checker).min() >= p.clearance_m + p.check_margin_m
    assert path.speed_mps[-1] == 0.0 and path.speed_mps.max() <= p.speed_mps


def test_a_gap_too_narrow_for_the_clearance_is_refused():
    # The Jackal is 0.43 m wide: 0.2 m each side needs more than 0.83 m.
    with pytest.raises(RouteError, match=r"0\.2 m from everything"):
        plan_careful_path(_room(0.8), (1.0, 1.0), (5.0, 1.0), JACKAL, CarefulParams())


def test_a_corner_too_tight_to_turn_round_is_refused():
    # Corridors 0.9 m wide: the centre line keeps 0.45 m from the walls, but a Jackal with
    # 0.2 m all round (0.91 m x 0.83 m) cannot turn a right angle in them.
    occ = _l_corridor(0.9)
    world = World("L", occ, np.zeros_like(occ), 0.05, 0.0, 0.0)
    with pytest.raises(RouteError, match="no room to spare"):
        plan_careful_path(world, (1.5, 1.45), (6.55, 6.5), JACKAL, CarefulParams().resolved(JACKAL))


def test_the_operator_waits_for_the_view_then_drives_the_path():
    world = _room(1.4)
    op = CarefulOperator.on_world(world, (1.0, 1.0, 0.0), (5.0, 1.0), JACKAL, "direct")
    stick = op.command(0.0, (1.0, 1.0, 0.0))
    assert (stick.x_o, stick.y_o, stick.deadman, stick.mode) == (0.0, 0.0, True, "direct")
    op.observe(0.0, Observation(0.0, (1.0, 1.0, 0.0)))
    # The path heads up to the gap (left of the heading): turn left, on the spot first.
    sticks = [op.command(0.25 + 0.05 * k, (0.0, 0.0, 0.0)) for k in range(5)]
    assert all(s.y_o > 0 for s in sticks[1:])
    # Speeds up no faster than its comfortable accelerations allow.
    p = op.params
    assert p.angular_accel_radps2 is not None
    w = [s.y_o * JACKAL.w_max_radps for s in sticks]
    assert np.all(np.abs(np.diff(w)) <= p.angular_accel_radps2 * 0.05 + 1e-9)


def test_the_seen_pose_is_brought_forward_with_the_commands_sent_since():
    world = _room(1.4)
    op = CarefulOperator.on_world(world, (1.0, 1.0, 0.0), (5.0, 1.0), JACKAL, "direct")
    op._commands.extend([(0.0, 0.0, 0.0), (0.1, 0.5, 0.0), (0.2, 0.5, 1.0)])
    seen = Observation(0.1, (1.0, 1.0, 0.0))
    x, y, yaw = op.predicted_pose(0.3, seen)
    # 0.1 s straight at 0.5 m/s, then 0.1 s on an arc at 0.5 m/s, 1 rad/s.
    arc_x = 1.05 + 0.5 * math.sin(0.1)
    arc_y = 1.0 + 0.5 * (1 - math.cos(0.1))
    assert (x, y, yaw) == pytest.approx((arc_x, arc_y, 0.1), abs=1e-9)


def test_make_operator_builds_careful_and_names_what_it_needs():
    world = _room(1.4)
    op = make_operator(
        "careful:speed_mps=0.5,clearance_m=0.25",
        (5.0, 1.0),
        "shared",
        world=world,
        start=(1.0, 1.0, 0.0),
        profile=JACKAL,
    )
    inner = op.operator if hasattr(op, "operator") else op
    assert isinstance(inner, CarefulOperator)
    assert inner.params.speed_mps == 0.5 and inner.params.clearance_m == 0.25
    with pytest.raises(ValueError, match="robot profile"):
        make_operator("careful", (5.0, 1.0), "shared", world=world, start=(1.0, 1.0, 0.0))
    with pytest.raises(ValueError, match="unknown option 'fast'"):
        make_operator("careful:fast=1", (5.0, 1.0), "shared", world=world, profile=JACKAL)
    with pytest.raises(ValueError, match="not a number"):
        make_operator("careful:speed_mps=quick", (5.0, 1.0), "shared", profile=JACKAL)


@pytest.mark.parametrize("seed", [1000, 1030, 1035])
def test_careful_drives_arrive_clear_of_everything(seed):
    """Direct mode, the Jackal: seeds with the narrowest passages of random:1000-1099."""
    result, summary = run_settings(
        EpisodeSettings(
            map=f"random:{seed}",
            seed=seed,
            operator="careful",
            filter="none",
            profile="jackal",
            max_time_s=60.0,
        ),
        record_trace=True,
    )
    assert summary["outcome"] == "reached"
    assert summary["min_clearance_m"] >= 0.2
    v = np.array([r.v_ref_mps for r in result.trace])
    w = np.array([r.w_ref_radps for r in result.trace])
    assert v.max() <= 0.8 + 1e-9 and v.min() >= 0.0
    assert v.max() > 0.6  # it does get going
    # Smooth: within the comfortable accelerations (what the driver asks, before any limit).
    p = CarefulParams().resolved(JACKAL)
    assert p.decel_mps2 is not None and p.angular_accel_radps2 is not None
    assert np.abs(np.diff(v)).max() <= p.decel_mps2 * 0.05 + 1e-9
    assert np.abs(np.diff(w)).max() <= p.angular_accel_radps2 * 0.05 + 1e-9
    # The base did what the driver asked: no limit of the robot's had to step in.
    assert {r.limiter for r in result.trace} == {"none"}


def test_careful_turns_round_a_corner_without_cutting_it(tmp_path):
    path = tmp_path / "l.npy"
    np.save(path, _l_corridor(1.5))
    _, summary = run_settings(
        EpisodeSettings(
            map=str(path),
            start=(1.5, 1.75, 0.0),
            goal=(6.25, 6.5),
            operator="careful",
            filter="none",
            profile="jackal",
            max_time_s=60.0,
        )
    )
    assert summary["outcome"] == "reached" and summary["min_clearance_m"] >= 0.2


def test_careful_drives_with_a_filter_too():
    _, summary = run_settings(
        EpisodeSettings(
            map="random:1001",
            seed=1001,
            operator="careful",
            filter="assist",
            profile="jackal",
            max_time_s=60.0,
        )
    )
    assert summary["outcome"] == "reached" and not summary["collided"]
