"""Scenarios after the paper's Fig. 10: the GC expands away from a frontal obstacle."""

from __future__ import annotations

import numpy as np
import pytest
from egc_robot.filters.egc import EgcParams, Side, egc_filter

P3DX = EgcParams(r_min_m=0.455, r_max_m=0.595, horizon_s=0.595 / 0.14)


def frontal_face(slope, half_w=0.2, n=41):
    """A frontal obstacle across the path whose face is turned: x = 1 + slope * y.

    slope > 0 brings its right part (y < 0) nearer, so the nearest point is right of the line.
    """
    ys = np.linspace(-half_w, half_w, n)
    return np.column_stack((1.0 + slope * ys, ys))


@pytest.mark.parametrize("slope", [0.1, 0.3, 0.5])
def test_obstacle_right_of_reference_line_expands_left(slope):
    pts = frontal_face(slope)
    res = egc_filter(0.14, 0.0, pts, P3DX)
    nearest = pts[np.argmin(np.hypot(pts[:, 0] - 0.595, pts[:, 1]))]
    assert nearest[1] < 0  # the nearest point is right of the reference line
    assert res.side is Side.LEFT
    assert res.p_agc[1] > 0 and res.p_egc[1] > 0
    assert res.w_radps > 0  # the robot is steered left


@pytest.mark.parametrize("slope", [-0.1, -0.3, -0.5])
def test_obstacle_left_of_reference_line_expands_right(slope):
    pts = frontal_face(slope)
    res = egc_filter(0.14, 0.0, pts, P3DX)
    assert res.side is Side.RIGHT
    assert res.p_agc[1] < 0 and res.p_egc[1] < 0
    assert res.w_radps < 0


def test_expanded_circle_is_safer_than_the_initial_one():
    pts = frontal_face(0.3)
    res = egc_filter(0.14, 0.0, pts, P3DX)
    assert res.r_egc_m > res.r_igc_m
    assert 0 < res.v_mps < 0.14


def test_reverse_motion_obstacle_behind_is_regulated():
    pts = -frontal_face(-0.3)  # behind the robot; its right part (y < 0) is nearer
    res = egc_filter(-0.14, 0.0, pts, P3DX)
    assert res.modified and res.v_mps <= 0.0 and abs(res.v_mps) < 0.14
    nearest = pts[np.argmin(np.hypot(pts[:, 0] + 0.595, pts[:, 1]))]
    assert nearest[1] < 0
    # the expanded centre moves off the reference line, away from the nearest point
    assert res.p_egc[1] > 0 and res.r_egc_m > res.r_igc_m
