"""Beyond-the-paper rules (DESIGN 5.10): no dead-lock, limits after the filter, footprint sweep."""

from __future__ import annotations

import math

import numpy as np
import pytest
from egc_common.kinematics import signed_distance_to_rectangle
from egc_common.profiles import JACKAL, PIONEER3DX
from egc_robot.filters.egc import EgcCase
from egc_robot.pipeline import Limiter, PipelineConfig, filter_velocity, step_command
from egc_robot.safety import (
    SweepParams,
    brake_along,
    footprint_clearance,
    reachable,
    stopping_time_s,
    sweep_min_clearance,
    sweep_scale,
)

P3DX_CFG = PipelineConfig(PIONEER3DX)
JACKAL_CFG = PipelineConfig(JACKAL)


def wall_x(x, half=1.5, n=121):
    ys = np.linspace(-half, half, n)
    return np.column_stack((np.full(n, x), ys))


def test_signed_clearance_outside_inside():
    pts = np.array([[1.0, 0.0], [0.0, 0.0], [0.6, 0.4], [0.45, 0.0]])
    c = signed_distance_to_rectangle(pts[:, 0], pts[:, 1], 0.5, 0.25)
    assert c == pytest.approx([0.5, -0.25, math.hypot(0.1, 0.15), -0.05])


def test_reverse_away_from_a_close_wall_is_allowed():
    """Wall 0.3 m ahead (inside r_min): backing away is allowed, driving on is not."""
    pts = wall_x(0.3)
    out = step_command(P3DX_CFG, -1.0, 0.0, "shared", pts, (0.0, 0.0), 0.05)
    assert out.v_cmd_mps < 0.0
    # and driving on into the wall is not
    fwd = step_command(P3DX_CFG, 1.0, 0.0, "shared", pts, (0.0, 0.0), 0.05)
    assert fwd.v_cmd_mps == 0.0


def test_escape_rule_applies_when_the_paper_stops():
    pts = wall_x(0.26, half=0.3)
    slow_back = filter_velocity(P3DX_CFG, -0.02, 0.0, "shared", pts, (0.0, 0.0), 0.05)
    assert slow_back.filtered.case in (EgcCase.NO_INTERSECTION, EgcCase.EXPANDED)
    assert slow_back.filtered.w_si == 0.0  # the paper's equations alone would stop here
    assert slow_back.escape and slow_back.v_cmd_mps < 0.0


def test_turn_in_place_next_to_a_wall_is_allowed_when_the_swept_circle_is_clear():
    pts = wall_x(PIONEER3DX.half_diagonal_m + 0.05)
    out = step_command(P3DX_CFG, 0.0, 1.0, "shared", pts, (0.0, 0.5), 0.05)
    assert out.w_cmd_radps == pytest.approx(0.5)
    assert out.filtered.case is EgcCase.NO_TRANSLATION


def test_turn_in_place_is_blocked_by_a_point_the_corner_would_hit():
    # a point just off the left side near the front-left corner: that corner swings into it
    # when turning left (counter-clockwise) and away from it when turning right
    hl, hw = PIONEER3DX.length_m / 2, PIONEER3DX.width_m / 2
    pts = np.array([[hl - 0.02, hw + 0.01]])
    out = step_command(P3DX_CFG, 0.0, 1.0, "shared", pts, (0.0, 0.5), 0.05)
    assert out.limiter is Limiter.SWEEP and abs(out.w_cmd_radps) < 0.5
    # turning right moves the corner away from it: allowed
    right = step_command(P3DX_CFG, 0.0, -1.0, "shared", pts, (0.0, -0.5), 0.05)
    assert right.w_cmd_radps == pytest.approx(-0.5)


def test_velocity_limits_apply_after_the_filter():
    far = wall_x(50.0)
    out = filter_velocity(P3DX_CFG, 1.0, 3.0, "shared", far, (0.14, 0.5), 0.05)
    assert (out.v_cmd_mps, out.w_cmd_radps) == (PIONEER3DX.v_max_mps, PIONEER3DX.w_max_radps)
    assert out.limiter is Limiter.LIMITS


def test_acceleration_limits_apply_after_the_filter():
    far = wall_x(50.0)
    out = step_command(P3DX_CFG, 1.0, 0.0, "shared", far, (0.0, 0.0), 0.05)
    assert out.v_cmd_mps == pytest.approx(PIONEER3DX.accel_max_mps2 * 0.05)
    # braking uses the deceleration limit
    out = step_command(P3DX_CFG, 0.0, 0.0, "direct", far, (0.14, 0.0), 0.05)
    assert out.v_cmd_mps == pytest.approx(0.14 - PIONEER3DX.decel_max_mps2 * 0.05)


def _points_egc_passes_but_footprint_would_touch(cfg, v, w):
    """Grid points that the paper's circles ignore (>= r_max from P_IGC) but the sweep hits."""
    params = cfg.egc_params
    kT = params.horizon_s
    pig = (v * kT * math.cos(w * kT / 2), v * kT * math.sin(w * kT / 2))
    t = stopping_time_s(v, w, cfg.profile, cfg.sweep)
    found = []
    for x in np.arange(-1.2, 1.2, 0.05):
        for y in np.arange(-1.2, 1.2, 0.05):
            p = np.array([[x, y]])
            if math.hypot(x - pig[0], y - pig[1]) < params.r_max_m:
                continue
            if footprint_clearance(p, cfg.profile) < cfg.sweep.margin_m:
                continue
            if sweep_min_clearance(v, w, t, p, cfg.profile, cfg.sweep) < cfg.sweep.margin_m:
                found.append(p)
    return found


def test_footprint_sweep_limits_where_the_circles_see_nothing():
    """Jackal at full speed in a left turn: the paper's circles only judge the arc's end point."""
    v, w = 2.0, 2.0
    hits = _points_egc_passes_but_footprint_would_touch(JACKAL_CFG, v, w)
    assert hits, "expected geometry where EGC passes but the footprint touches"
    for p in hits:
        out = filter_velocity(JACKAL_CFG, v, w, "shared", p, None, 0.05)
        assert out.filtered.case is EgcCase.CLEAR  # the paper lets it through ...
        assert out.limiter is Limiter.SWEEP  # ... the last check does not
        assert out.sweep_scale < 1.0
        t = stopping_time_s(out.v_cmd_mps, out.w_cmd_radps, JACKAL, JACKAL_CFG.sweep)
        c = sweep_min_clearance(out.v_cmd_mps, out.w_cmd_radps, t, p, JACKAL, JACKAL_CFG.sweep)
        assert c >= JACKAL_CFG.sweep.margin_m - 1e-9


def test_sweep_scale_is_one_when_clear_and_zero_when_touching_head_on():
    params = SweepParams()
    assert sweep_scale(0.14, 0.0, wall_x(3.0), PIONEER3DX, params) == 1.0
    touching = wall_x(PIONEER3DX.length_m / 2 + 0.001)
    assert sweep_scale(0.14, 0.0, touching, PIONEER3DX, params) == 0.0


def test_direct_mode_bypasses_filter_and_sweep():
    pts = wall_x(0.3)
    out = step_command(P3DX_CFG, 1.0, 0.0, "direct", pts, (0.14, 0.0), 0.05)
    assert out.filtered is None and out.v_cmd_mps == pytest.approx(0.14)


def test_no_scan_in_shared_mode_stops():
    out = step_command(P3DX_CFG, 1.0, 0.0, "shared", np.empty((0, 2)), (0.14, 0.0), 0.05)
    assert out.filtered.case is EgcCase.NO_POINTS_UNKNOWN
    assert out.v_cmd_mps < 0.14  # decelerating toward the filter's stop


def test_brake_along_keeps_the_previous_arc_at_the_braking_limit():
    v, w = brake_along((1.7, 0.55), 0.05, JACKAL)
    assert v == pytest.approx(1.7 - JACKAL.decel_max_mps2 * 0.05)
    assert w / v == pytest.approx(0.55 / 1.7)  # same curvature
    assert reachable(v, w, (1.7, 0.55), 0.05, JACKAL)
    assert not reachable(0.6, 0.2, (1.7, 0.55), 0.05, JACKAL)  # more braking than the base has
    back = brake_along((-0.5, 0.3), 0.05, JACKAL)
    assert back[0] == pytest.approx(-0.5 + 0.15) and back[1] / back[0] == pytest.approx(-0.6)
    # A straight line or a turn in place: a zero command keeps the arc.
    assert brake_along((1.7, 0.0), 0.05, JACKAL) == (0.0, 0.0)
    assert brake_along((0.0, 1.5), 0.05, JACKAL) == (0.0, 0.0)
