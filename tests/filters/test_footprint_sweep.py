"""The pipeline's footprint rules on shapes beyond the rectangle (DESIGN 5.10, 14): the sweep,
the sensor-reach cap and the too-close points measure the footprint as given."""

from __future__ import annotations

import math

import numpy as np
import pytest
from egc_common.footprint import signed_distance
from egc_common.profiles import HUSKY
from egc_common.scan import obstacle_points, too_close_points
from egc_robot.pipeline import PipelineConfig, filter_velocity
from egc_robot.safety import (
    SweepParams,
    footprint_clearance,
    horizon_scale,
    stopping_time_s,
    sweep_min_clearance,
    sweep_scale,
)
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.shapes import DISC, L_SHAPE, PENTAGON

SHAPES = [PENTAGON, L_SHAPE, DISC, HUSKY]
PARAMS = SweepParams()
coords = st.floats(-2.0, 2.0, allow_nan=False)


@settings(max_examples=150, deadline=None)
@given(
    st.sampled_from(SHAPES),
    st.floats(-1.0, 1.0),
    st.floats(-1.0, 1.0),
    st.lists(st.tuples(coords, coords), min_size=1, max_size=40),
)
def test_the_scaled_command_sweeps_clear(profile, fv, fw, cloud):
    """Whatever the sweep lets through keeps the margin along the stop (or, closer already,
    does not get closer), measured on a finer sampling of the arc than the sweep's own."""
    pts = np.array(cloud, dtype=float)
    now = footprint_clearance(pts, profile)
    if now <= 0.0:
        return  # touching already: nothing to keep
    v, w = fv * profile.v_max_mps, fw * profile.w_max_radps
    s = sweep_scale(v, w, pts, profile, PARAMS)
    if s == 0.0:
        return
    fine = SweepParams(step_m=0.002, step_rad=0.005)
    t = stopping_time_s(s * v, s * w, profile, PARAMS)
    swept = sweep_min_clearance(s * v, s * w, t, pts, profile, fine)
    # The sweep samples every 2 cm / 0.05 rad: between its samples the footprint may come at
    # most that much closer than its check saw, well inside the 3 cm margin.
    assert swept >= min(PARAMS.margin_m, now) - 0.02 - 1e-9


def test_an_obstacle_in_the_l_notch_is_outside_the_robot():
    """A post in the L's notch is 0.15 m from it (its bounding box would put it inside): the
    robot may creep ahead until the notch's inner edge comes within the margin, no farther."""
    post = np.array([[0.15, -0.15]])
    assert footprint_clearance(post, L_SHAPE) == pytest.approx(0.15)
    fast = sweep_scale(L_SHAPE.v_max_mps, 0.0, post, L_SHAPE, PARAMS)
    assert 0.0 < fast < 1.0
    v = fast * L_SHAPE.v_max_mps
    t = stopping_time_s(v, 0.0, L_SHAPE, PARAMS)
    assert v * t <= 0.15 - PARAMS.margin_m + 1e-3  # it stops with the margin kept
    assert sweep_scale(0.05, 0.0, post, L_SHAPE, PARAMS) == 1.0  # a crawl is clear
    # Backing out of the notch is free.
    assert sweep_scale(-L_SHAPE.v_max_mps, 0.0, post, L_SHAPE, PARAMS) == 1.0


def test_a_disc_turns_in_place_against_a_wall():
    """Round robots turn in place next to a wall: nothing of them moves."""
    wall = np.column_stack((np.full(41, DISC.footprint.radius_m + 0.01), np.linspace(-1, 1, 41)))
    assert sweep_scale(0.0, DISC.w_max_radps, wall, DISC, PARAMS) == 1.0
    assert sweep_scale(DISC.v_max_mps, 0.0, wall, DISC, PARAMS) == 0.0


def test_sensor_reach_counts_from_the_real_front():
    """horizon_scale: the stop must fit between the footprint's front (the pentagon's nose at
    0.35 m, not half its length) and what the sensor saw."""
    x_max = PENTAGON.footprint.bounds[1]
    assert x_max == pytest.approx(0.35) and PENTAGON.length_m / 2 == pytest.approx(0.3)
    v = PENTAGON.v_max_mps
    stop = v * PARAMS.period_s + v * v / (2 * PENTAGON.decel_max_mps2)
    seen = obstacle_points(np.array([[5.0, 5.0]]), seen_ahead_m=x_max + PARAMS.margin_m + stop)
    assert horizon_scale(v, 0.0, seen, PENTAGON, PARAMS) == 1.0
    short = obstacle_points(
        np.array([[5.0, 5.0]]), seen_ahead_m=x_max + PARAMS.margin_m + 0.5 * stop
    )
    assert horizon_scale(v, 0.0, short, PENTAGON, PARAMS) < 1.0


def test_too_close_points_in_the_notch_are_kept():
    """A -inf beam into the L's notch (laser at base_link, the L's inner corner): the object may
    be anywhere up to range_min; its places, inside the bounding box but outside the robot, come
    back just outside the real edge (a box footprint would have dropped them all)."""
    pts = too_close_points(np.array([-math.pi / 4]), 0.3, 0.0, 0.0, L_SHAPE.footprint)
    assert len(pts) > 0
    d = signed_distance(L_SHAPE.footprint, pts[:, 0], pts[:, 1])
    assert np.all(d > 0.0) and np.all(d <= 0.0011)
    boxed = too_close_points(np.array([-math.pi / 4]), 0.3, 0.0, 0.0, L_SHAPE.half_size_m)
    assert len(boxed) == 0  # what the bounding box made of it


@pytest.mark.parametrize("profile", SHAPES, ids=lambda p: p.name)
def test_driving_into_a_wall_stops_at_the_margin(profile):
    """The whole pipeline (DWA, which drives up to obstacles, then the limits and the sweep)
    on a wall ahead, cycle after cycle: each shape's front ends within a few centimetres of the
    wall and never on it (the margin is 3 cm)."""
    config = PipelineConfig(profile)
    front = profile.footprint.bounds[1]
    wall_x = front + 0.6
    x, previous = 0.0, (0.0, 0.0)
    dt = 0.05
    for _ in range(400):
        wall = np.column_stack((np.full(81, wall_x - x), np.linspace(-2, 2, 81)))
        out = filter_velocity(
            config, profile.v_max_mps, 0.0, "shared", wall, previous, dt, filter_name="dwa"
        )
        stopped = out.v_cmd_mps == 0.0 and (out.v_cmd_mps, out.w_cmd_radps) == previous
        previous = (out.v_cmd_mps, out.w_cmd_radps)
        x += out.v_cmd_mps * dt
        if stopped:
            # Stopped, and sent what it was sent before: the next cycle's inputs are this
            # one's (a cycle is a pure function of them), so every later cycle is this one.
            break
    gap = wall_x - (x + front)
    assert PARAMS.margin_m - 1e-3 <= gap <= 0.05
