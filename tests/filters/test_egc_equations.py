"""One test per equation of the EGC paper (eqs. 5-16), on hand-computed cases."""

from __future__ import annotations

import math

import numpy as np
import pytest
from egc_robot.filters.egc import (
    EgcCase,
    EgcParams,
    Region,
    Side,
    circle_intersections,
    command_from_point,
    egc_filter,
    predicted_position,
    region_of,
    safety_index,
)

# The paper's Pioneer 3-DX: r_min 0.455 m, r_max 0.595 m, v_max 0.14 m/s -> kT = 4.25 s.
P3DX = EgcParams(r_min_m=0.455, r_max_m=0.595, horizon_s=0.595 / 0.14)


def test_eq6_predicted_position_straight_and_turning():
    assert predicted_position(0.14, 0.0, 4.25) == pytest.approx((0.595, 0.0), abs=1e-12)
    # v kT = 1, w kT / 2 = pi / 6  ->  (cos 30 deg, sin 30 deg)
    x, y = predicted_position(0.5, math.pi / 6, 2.0)
    assert (x, y) == pytest.approx((math.sqrt(3) / 2, 0.5), abs=1e-12)
    # reverse: the point lies behind, mirrored through the origin
    assert predicted_position(-0.5, math.pi / 6, 2.0) == pytest.approx((-math.sqrt(3) / 2, -0.5))


def test_eq7_reachable_radius_is_distance_of_predicted_point():
    res = egc_filter(0.1, 0.3, np.array([[0.3, 0.1]]), P3DX)
    assert res.r_rc_m == pytest.approx(math.hypot(*res.p_igc), abs=1e-15)
    assert res.r_rc_m == pytest.approx(0.1 * P3DX.horizon_s, abs=1e-12)  # |chord| = v kT here


def test_eq8_eq9_initial_gc_radius_nearest_point_and_clamp():
    # P_IGC = (0.595, 0); nearest of three points is (0.595, 0.3) at 0.3 m
    pts = np.array([[0.595, 0.3], [2.0, 0.0], [0.595, -0.5]])
    res = egc_filter(0.14, 0.0, pts, P3DX)
    assert res.r_igc_m == pytest.approx(0.3, abs=1e-12)
    # a point exactly r_max away passes unchanged with r_IGC clamped to r_max (Table 1, 4-6)
    res = egc_filter(0.14, 0.0, np.array([[0.595 + 0.595, 0.0]]), P3DX)
    assert res.case is EgcCase.CLEAR and res.r_igc_m == 0.595
    assert (res.v_mps, res.w_radps, res.w_si, res.modified) == (0.14, 0.0, 1.0, False)


def test_intersection_points_of_reachable_circle_and_initial_gc():
    # r_RC = 1, r_IGC = 1 along +x: the circles meet at (1/2, +-sqrt(3)/2)
    left, right = circle_intersections((1.0, 0.0), 1.0, 1.0)
    assert left == pytest.approx((0.5, math.sqrt(3) / 2), abs=1e-12)
    assert right == pytest.approx((0.5, -math.sqrt(3) / 2), abs=1e-12)
    for p in (left, right):
        assert math.hypot(*p) == pytest.approx(1.0)
        assert math.hypot(p[0] - 1.0, p[1]) == pytest.approx(1.0)
    assert circle_intersections((0.2, 0.0), 0.2, 0.5) is None  # r_IGC > 2 r_RC


def test_eq10_eq11_auxiliary_gc_on_the_chosen_side():
    # Obstacle right of the reference line -> P_AGC = P_CL (left)
    pts = np.array([[0.595, -0.3]])
    res = egc_filter(0.14, 0.0, pts, P3DX)
    assert res.side is Side.LEFT
    left, _ = circle_intersections(res.p_igc, res.r_rc_m, res.r_igc_m)
    assert res.p_agc == pytest.approx(left)
    d = math.hypot(res.p_agc[0] - 0.595, res.p_agc[1] + 0.3)
    assert res.r_agc_m == pytest.approx(min(d, 0.595))


def test_eq12_expanded_centre_is_radius_weighted():
    pts = np.array([[0.595, -0.3]])
    res = egc_filter(0.14, 0.0, pts, P3DX)
    a, b = res.r_igc_m, res.r_agc_m
    expected = (
        (a * res.p_igc[0] + b * res.p_agc[0]) / (a + b),
        (a * res.p_igc[1] + b * res.p_agc[1]) / (a + b),
    )
    assert res.p_egc == pytest.approx(expected, abs=1e-15)


def test_eq13_expanded_radius_is_clamped_nearest_distance():
    pts = np.array([[0.595, -0.3], [0.2, 0.9]])
    res = egc_filter(0.14, 0.0, pts, P3DX)
    d = min(math.hypot(res.p_egc[0] - x, res.p_egc[1] - y) for x, y in pts)
    assert res.r_egc_m == pytest.approx(min(d, 0.595), abs=1e-15)


@pytest.mark.parametrize(
    ("r_c", "w_si", "region"),
    [
        (0.7, 1.0, Region.SAFE),
        (0.595, 1.0, Region.CONDITIONAL),  # r_c = r_max: r_max / r_max, conditionally safe
        (0.5, 0.5 / 0.595, Region.CONDITIONAL),
        (0.455, 0.0, Region.UNSAFE),  # at r_min: unsafe
        (0.1, 0.0, Region.UNSAFE),
    ],
)
def test_eq5_eq16_safety_index_and_regions(r_c, w_si, region):
    assert safety_index(r_c, 0.455, 0.595) == pytest.approx(w_si)
    assert region_of(r_c, 0.455, 0.595) is region


def test_eq14_eq15_command_from_point():
    kT = 2.0
    # P = (cos 30, sin 30): v = |P| / kT = 0.5, w = (2/kT) atan(tan 30 deg) = pi / 6
    v, w = command_from_point((math.sqrt(3) / 2, 0.5), 1.0, kT)
    assert (v, w) == pytest.approx((0.5, math.pi / 6), abs=1e-12)
    v, w = command_from_point((math.sqrt(3) / 2, 0.5), 0.5, kT)  # scaled by w_SI
    assert (v, w) == pytest.approx((0.25, math.pi / 12), abs=1e-12)
    v, w = command_from_point((-math.sqrt(3) / 2, -0.5), 1.0, kT)  # reverse
    assert (v, w) == pytest.approx((-0.5, math.pi / 6), abs=1e-12)
    # x = 0: atan limit, no translation
    assert command_from_point((0.0, 0.3), 1.0, kT) == pytest.approx((0.0, math.pi / 2))
    assert command_from_point((0.0, -0.3), 0.5, kT) == pytest.approx((0.0, -math.pi / 4))
    assert command_from_point((0.0, 0.0), 1.0, kT) == (0.0, 0.0)


def test_full_chain_hand_computed_frontal_obstacle():
    """A point 1 m ahead, slightly right: every intermediate by hand (DESIGN 5.1-5.7)."""
    pts = np.array([[1.0, -0.05]])
    res = egc_filter(0.14, 0.0, pts, P3DX)
    r_igc = math.hypot(1.0 - 0.595, -0.05)
    ell = 0.595 - r_igc**2 / (2 * 0.595)
    h = math.sqrt(0.595**2 - ell**2)
    agc = (ell, h)  # s = 0.595 * (-0.05) < 0 -> left
    r_agc = min(math.hypot(agc[0] - 1.0, agc[1] + 0.05), 0.595)
    egc = ((r_igc * 0.595 + r_agc * agc[0]) / (r_igc + r_agc), (r_agc * agc[1]) / (r_igc + r_agc))
    r_egc = min(math.hypot(egc[0] - 1.0, egc[1] + 0.05), 0.595)
    w_si = r_egc / 0.595 if r_egc > 0.455 else 0.0
    kT = P3DX.horizon_s
    assert res.side is Side.LEFT
    assert res.igc == pytest.approx((0.595, 0.0, r_igc), abs=1e-12)
    assert res.agc == pytest.approx((*agc, r_agc), abs=1e-12)
    assert res.egc == pytest.approx((*egc, r_egc), abs=1e-12)
    assert res.w_si == pytest.approx(w_si, abs=1e-12)
    assert res.v_mps == pytest.approx(w_si * math.hypot(*egc) / kT, abs=1e-12)
    assert res.w_radps == pytest.approx(w_si * 2 / kT * math.atan(egc[1] / egc[0]), abs=1e-12)
    assert res.w_radps > 0  # turns left, away from the obstacle on the right
