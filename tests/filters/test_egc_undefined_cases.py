"""The cases the paper leaves undefined (DESIGN 5.9): each rule never less safe than stopping."""

from __future__ import annotations

import math

import numpy as np
import pytest
from egc_robot.filters.egc import EgcCase, EgcParams, Region, egc_filter

P3DX = EgcParams(r_min_m=0.455, r_max_m=0.595, horizon_s=0.595 / 0.14)
WALL_AHEAD = np.array([[0.3, y] for y in np.linspace(-1, 1, 41)])


@pytest.mark.parametrize("v", [math.nan, math.inf, -math.inf, 1e300])
def test_invalid_command_stops(v):
    for args in ((v, 0.0), (0.1, v)):
        res = egc_filter(*args, WALL_AHEAD, P3DX)
        assert res.case is EgcCase.INVALID_INPUT
        assert (res.v_mps, res.w_radps, res.w_si) == (0.0, 0.0, 0.0)


def test_invalid_points_are_ignored():
    pts = np.array([[math.nan, 0.0], [math.inf, 1.0], [0.6, 1e300], [5.0, 5.0]])
    res = egc_filter(0.14, 0.0, pts, P3DX)
    assert res.case is EgcCase.CLEAR and res.v_mps == 0.14


def test_empty_scan_is_unknown_and_stops():
    for pts in (np.empty((0, 2)), np.array([[math.nan, math.nan]])):
        res = egc_filter(0.14, 0.2, pts, P3DX)
        assert res.case is EgcCase.NO_POINTS_UNKNOWN
        assert (res.v_mps, res.w_radps, res.w_si, res.region) == (0.0, 0.0, 0.0, Region.UNSAFE)


def test_empty_scan_declared_free_passes():
    params = EgcParams(P3DX.r_min_m, P3DX.r_max_m, P3DX.horizon_s, no_return_is_free=True)
    res = egc_filter(0.14, 0.2, np.empty((0, 2)), params)
    assert res.case is EgcCase.NO_POINTS_FREE and (res.v_mps, res.w_radps) == (0.14, 0.2)


def test_turning_in_place_next_to_a_wall_is_passed_to_the_footprint_check():
    res = egc_filter(0.0, 0.5, WALL_AHEAD, P3DX)
    assert res.case is EgcCase.NO_TRANSLATION
    assert (res.v_mps, res.w_radps) == (0.0, 0.5)  # not scaled by w_SI: no dead-lock
    assert res.w_si == 0.0 and res.region is Region.UNSAFE  # reported for the view


def test_zero_command_stays_zero():
    res = egc_filter(0.0, 0.0, WALL_AHEAD, P3DX)
    assert (res.v_mps, res.w_radps, res.modified) == (0.0, 0.0, False)


def test_non_intersecting_circles_regulate_without_expansion():
    # a tiny forward command, a point 0.5 m away: r_IGC ~ 0.49 > 2 r_RC ~ 0.04
    pts = np.array([[0.0, 0.5]])
    res = egc_filter(0.005, 0.0, pts, P3DX)
    assert res.case is EgcCase.NO_INTERSECTION
    assert res.r_igc_m > 2 * res.r_rc_m
    assert res.w_si == pytest.approx(res.r_igc_m / 0.595)
    assert res.v_mps == pytest.approx(0.005 * res.w_si) and res.p_egc == res.p_igc
    assert abs(res.v_mps) <= 0.005


def test_point_on_both_centres_stops():
    # the only point sits exactly on P_IGC: r_IGC = 0, so P_AGC = P_IGC and r_AGC = 0
    pts = np.array([[0.595, 0.0]])
    res = egc_filter(0.14, 0.0, pts, P3DX)
    assert res.case is EgcCase.ZERO_WEIGHTS
    assert (res.v_mps, res.w_radps, res.w_si) == (0.0, 0.0, 0.0)
