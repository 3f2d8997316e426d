"""`ek-egc` (DESIGN 6), one test per step on hand-computed cases, and every undefined case."""

from __future__ import annotations

import math

import numpy as np
import pytest
from egc_robot.filters import ek_egc_filter, ek_transform
from egc_robot.filters.egc import EgcCase, EgcParams, Region, Side, circle_intersections
from egc_robot.filters.ek_egc import ek_command_from_point, ek_command_point

from tests.filters.reference_ek_egc import reference_ek_egc, reference_ek_point

# The paper's Pioneer 3-DX: r_min 0.455 m, r_max 0.595 m, v_max 0.14 m/s -> kT = 4.25 s;
# w_max 0.5 rad/s -> L = v_max / w_max = 0.28 m.
P3DX = EgcParams(r_min_m=0.455, r_max_m=0.595, horizon_s=0.595 / 0.14)
L = 0.14 / 0.5
S2 = math.sqrt(2.0) / 2.0


# --- step 1: the EK transform -------------------------------------------------------------


@pytest.mark.parametrize(
    ("point", "l_m", "expected"),
    [
        ((1.0, 0.0), 1.0, (1.0, 0.0)),  # straight ahead: y = 0, d = x, theta = 0
        ((2.5, 0.0), 0.28, (2.5, 0.0)),
        # left: R = 1, g = pi/2, d = pi/2, theta = pi/2 - atan(1) = pi/4
        ((1.0, 1.0), 1.0, (math.pi / 2 * S2, math.pi / 2 * S2)),
        ((1.0, -1.0), 1.0, (math.pi / 2 * S2, -math.pi / 2 * S2)),  # right: R = -1
        # L = 0.5: theta = pi/2 - atan(2); cos = 2/sqrt(5), sin = 1/sqrt(5)
        ((1.0, 1.0), 0.5, (math.pi / 2 * 2 / math.sqrt(5), math.pi / 2 / math.sqrt(5))),
        # on the y axis: R = 1, g = atan2(0, 1 - 2) = pi (half a turn), d = pi, theta = pi/4
        ((0.0, 2.0), 1.0, (math.pi * S2, math.pi * S2)),
        ((0.0, -2.0), 1.0, (math.pi * S2, -math.pi * S2)),
        # behind, left: R = 1, g = atan2(-1, 0) = -pi/2 -> 3 pi/2, d = 3 pi/2
        ((-1.0, 1.0), 1.0, (1.5 * math.pi * S2, 1.5 * math.pi * S2)),
        ((-1.0, -1.0), 1.0, (1.5 * math.pi * S2, -1.5 * math.pi * S2)),
    ],
)
def test_step1_transform_hand_computed(point, l_m, expected):
    ek, kept = ek_transform(np.array([point]), l_m)
    assert kept.tolist() == [True]
    assert ek.shape == (1, 2)
    assert tuple(ek[0]) == pytest.approx(expected, abs=1e-12)
    assert tuple(ek[0]) == pytest.approx(reference_ek_point(*point, l_m), abs=1e-12)


def test_step1_y_zero_behind_or_at_origin_is_dropped_and_order_kept():
    pts = np.array([[-1.0, 0.0], [1.0, 1.0], [0.0, 0.0], [-0.0, 0.0], [2.0, 0.0], [-3.0, -0.0]])
    ek, kept = ek_transform(pts, 1.0)
    assert kept.tolist() == [False, True, False, False, True, False]
    assert ek == pytest.approx(np.array([[math.pi / 2 * S2, math.pi / 2 * S2], [2.0, 0.0]]))


def test_step1_embedding_norm_is_arc_length_and_angle_theta():
    # a point 90 degrees round a circle of radius 0.5 on the right: d = 0.5 pi / 2
    ek, _ = ek_transform(np.array([[0.5, -0.5]]), L)
    assert math.hypot(*ek[0]) == pytest.approx(0.25 * math.pi, abs=1e-12)
    assert math.atan2(ek[0][1], ek[0][0]) == pytest.approx(-(math.pi / 2 - math.atan(0.5 / L)))


def test_step1_nearly_straight_points_tend_to_the_y_zero_rule():
    ek, kept = ek_transform(np.array([[2.0, 1e-12], [2.0, -1e-300], [2.0, 5e-324]]), L)
    assert kept.all()
    assert ek == pytest.approx(np.array([[2.0, 0.0]] * 3), abs=1e-9)
    # just off the axis behind: the arc goes almost all the way round, d ~ 2 pi |R|
    ek, kept = ek_transform(np.array([[-1.0, 1e-3], [-1.0, 1e-300], [-1.0, 5e-324]]), L)
    assert kept.tolist() == [True, True, False]  # the last one's arc length overflows
    assert tuple(ek[0]) == pytest.approx(reference_ek_point(-1.0, 1e-3, L), rel=1e-9)
    assert math.hypot(*ek[0]) > 3000.0
    assert math.hypot(*ek[1]) == pytest.approx(math.pi * 1e300, rel=1e-12)


def test_step1_rejects_bad_length():
    for bad in (0.0, -1.0, math.nan, math.inf):
        with pytest.raises(ValueError):
            ek_transform(np.array([[1.0, 1.0]]), bad)
        with pytest.raises(ValueError):
            ek_egc_filter(0.1, 0.0, np.array([[1.0, 1.0]]), P3DX, bad)


# --- step 2: the command's EK point --------------------------------------------------------


def test_step2_command_point_straight_and_turning():
    assert ek_command_point(0.5, 0.0, 2.0, 1.0) == pytest.approx((1.0, 0.0), abs=1e-15)
    # theta_c = atan(L w / v) = atan(1) = pi / 4, at the arc length v kT = 1
    assert ek_command_point(0.5, 0.5, 2.0, 1.0) == pytest.approx((S2, S2), abs=1e-15)
    assert ek_command_point(0.5, -0.5, 2.0, 1.0) == pytest.approx((S2, -S2), abs=1e-15)
    assert ek_command_point(0.0, 1.0, 2.0, 1.0) == (0.0, 0.0)  # v = 0: NO_TRANSLATION
    res = ek_egc_filter(0.14, 0.3, np.array([[0.2, 0.9]]), P3DX, L)
    kT = P3DX.horizon_s
    th = math.atan(L * 0.3 / 0.14)
    assert res.p_igc == pytest.approx((0.14 * kT * math.cos(th), 0.14 * kT * math.sin(th)))
    assert res.r_rc_m == pytest.approx(0.14 * kT, abs=1e-15)


# --- step 4: back to a command -------------------------------------------------------------


def test_step4_back_conversion():
    kT = 2.0
    # P = (cos 45, sin 45): v = |P| / kT = 0.5, w = v tan(pi/4) / L = 0.5
    assert ek_command_from_point((S2, S2), 1.0, kT, 1.0) == pytest.approx((0.5, 0.5))
    assert ek_command_from_point((S2, S2), 0.5, kT, 1.0) == pytest.approx((0.25, 0.25))
    assert ek_command_from_point((S2, -S2), 1.0, kT, 0.5) == pytest.approx((0.5, -1.0))
    # x <= 0: no translation, w = w_SI (2 / kT)(pi / 2) sign(y)
    assert ek_command_from_point((0.0, 0.3), 1.0, kT, 1.0) == pytest.approx((0.0, math.pi / 2))
    assert ek_command_from_point((-0.1, -0.2), 0.5, kT, 1.0) == pytest.approx((0.0, -math.pi / 4))
    assert ek_command_from_point((0.0, 0.0), 1.0, kT, 1.0) == (0.0, 0.0)


# --- the whole chain ------------------------------------------------------------------------


def test_full_chain_hand_computed_frontal_obstacle():
    """A point 1 m ahead, slightly right: every intermediate from DESIGN 6 by hand."""
    x, y = 1.0, -0.05
    R = (x * x + y * y) / (2 * y)  # < 0: on the right
    g = math.atan2(x, abs(R) - abs(y))
    d, th = abs(R) * g, -(math.pi / 2 - math.atan(abs(R) / L))
    m = (d * math.cos(th), d * math.sin(th))
    kT = P3DX.horizon_s
    igc = (0.14 * kT, 0.0)  # straight: theta_c = 0
    r_rc = 0.14 * kT
    r_igc = math.hypot(m[0] - igc[0], m[1] - igc[1])
    ell = r_rc - r_igc**2 / (2 * r_rc)
    h = math.sqrt(r_rc**2 - ell**2)
    agc = (ell, h)  # s = x_IGC * y_m < 0 -> left
    r_agc = min(math.hypot(agc[0] - m[0], agc[1] - m[1]), 0.595)
    egc = ((r_igc * igc[0] + r_agc * agc[0]) / (r_igc + r_agc), r_agc * agc[1] / (r_igc + r_agc))
    r_egc = min(math.hypot(egc[0] - m[0], egc[1] - m[1]), 0.595)
    w_si = r_egc / 0.595 if r_egc > 0.455 else 0.0
    v_out = w_si * math.hypot(*egc) / kT
    w_out = v_out * math.tan(math.atan2(egc[1], egc[0])) / L

    res = ek_egc_filter(0.14, 0.0, np.array([[x, y]]), P3DX, L)
    assert res.case is EgcCase.EXPANDED and res.side is Side.LEFT and res.modified
    assert res.igc == pytest.approx((*igc, r_igc), abs=1e-12)
    assert res.agc == pytest.approx((*agc, r_agc), abs=1e-12)
    assert res.egc == pytest.approx((*egc, r_egc), abs=1e-12)
    assert res.w_si == pytest.approx(w_si, abs=1e-12)
    assert (res.v_mps, res.w_radps) == pytest.approx((v_out, w_out), abs=1e-12)
    assert res.w_radps > 0.0  # turns left, away from the obstacle on the right
    assert res.region is Region.CONDITIONAL


def test_left_and_right_expansion_are_mirror_images():
    right_obstacle = ek_egc_filter(0.14, 0.0, np.array([[1.0, -0.05]]), P3DX, L)
    left_obstacle = ek_egc_filter(0.14, 0.0, np.array([[1.0, 0.05]]), P3DX, L)
    assert right_obstacle.side is Side.LEFT and left_obstacle.side is Side.RIGHT
    assert right_obstacle.w_radps > 0.0 > left_obstacle.w_radps
    assert left_obstacle.v_mps == pytest.approx(right_obstacle.v_mps, abs=1e-15)
    assert left_obstacle.w_radps == pytest.approx(-right_obstacle.w_radps, abs=1e-15)
    assert left_obstacle.p_agc == pytest.approx((right_obstacle.p_agc[0], -right_obstacle.p_agc[1]))
    # the auxiliary centre is the intersection on the chosen side (DESIGN 5.4 in EK space)
    _, right = circle_intersections(
        left_obstacle.p_igc, left_obstacle.r_rc_m, left_obstacle.r_igc_m
    )
    assert left_obstacle.p_agc == pytest.approx(right)


def test_turning_command_with_an_obstacle_on_its_arc():
    v, w = 0.14, 0.3
    R = v / w
    phi = 1.2  # 0.56 m along the arc, then 5 cm outside it
    pts = np.array([[(R + 0.05) * math.sin(phi), R - (R + 0.05) * math.cos(phi)]])
    res = ek_egc_filter(v, w, pts, P3DX, L)
    ref = reference_ek_egc(v, w, pts.tolist(), 0.455, 0.595, P3DX.horizon_s, L)
    assert res.case is EgcCase.EXPANDED
    assert math.atan2(res.p_igc[1], res.p_igc[0]) == pytest.approx(math.atan(L * w / v))
    assert (res.v_mps, res.w_radps) == pytest.approx((ref["v"], ref["w"]), abs=1e-12)
    assert res.egc == pytest.approx(ref["egc"], abs=1e-12)
    assert res.side.value == ref["side"]
    assert res.v_mps < v


def test_reverse_is_the_mirrored_forward_problem_negated():
    pts = np.array([[-1.0, -0.05], [-0.4, 0.7], [0.5, 0.3]])
    mirrored = pts * np.array([-1.0, 1.0])
    for w in (0.0, 0.2, -0.35):
        back = ek_egc_filter(-0.14, w, pts, P3DX, L)
        fwd = ek_egc_filter(0.14, -w, mirrored, P3DX, L)
        assert (back.v_mps, back.w_radps) == (-fwd.v_mps, -fwd.w_radps)
        assert back.case is fwd.case and back.side is fwd.side and back.w_si == fwd.w_si
        assert (back.igc, back.agc, back.egc) == (fwd.igc, fwd.agc, fwd.egc)
    # backing towards a box behind-right: slowed and steered (away to the left, y grows)
    res = ek_egc_filter(-0.14, 0.0, np.array([[-1.0, -0.05]]), P3DX, L)
    assert res.case is EgcCase.EXPANDED and -0.14 < res.v_mps < 0.0 and res.w_radps < 0.0
    # a box ahead does not matter when backing away from it, nor one behind when going forward
    assert ek_egc_filter(-0.14, 0.0, np.array([[1.0, -0.05]]), P3DX, L).case is EgcCase.CLEAR
    assert ek_egc_filter(0.14, 0.0, np.array([[-1.0, -0.05]]), P3DX, L).case is EgcCase.CLEAR


def test_dropped_points_only_matter_in_the_direction_they_are_reachable():
    behind = np.array([[-1.0, 0.0], [-0.3, 0.0], [0.0, 0.0]])  # all y = 0, x <= 0
    res = ek_egc_filter(0.14, 0.05, behind, P3DX, L)
    assert res.case is EgcCase.CLEAR and (res.v_mps, res.w_radps) == (0.14, 0.05)
    # backing up, (-0.3, 0) is straight behind at 0.3 m: mirrored to EK (0.3, 0)
    res = ek_egc_filter(-0.14, 0.0, behind, P3DX, L)
    assert res.case is EgcCase.EXPANDED and res.nearest_m == pytest.approx(0.595 - 0.3)
    assert abs(res.v_mps) < 0.14


# --- the undefined cases of DESIGN 5.9, with EGC's rules ------------------------------------

WALL_AHEAD = np.array([[0.3, y] for y in np.linspace(-1, 1, 41)])


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, 1e300])
def test_invalid_command_stops(bad):
    for v, w in ((bad, 0.0), (0.1, bad), (-0.1, bad)):
        res = ek_egc_filter(v, w, WALL_AHEAD, P3DX, L)
        assert res.case is EgcCase.INVALID_INPUT
        assert (res.v_mps, res.w_radps, res.w_si, res.region) == (0.0, 0.0, 0.0, Region.UNSAFE)


def test_invalid_points_are_ignored():
    pts = np.array([[math.nan, 0.0], [math.inf, 1.0], [0.6, 1e300], [5.0, 5.0]])
    res = ek_egc_filter(0.14, 0.0, pts, P3DX, L)
    assert res.case is EgcCase.CLEAR and (res.v_mps, res.w_radps) == (0.14, 0.0)


def test_empty_scan_is_unknown_and_stops_forward_and_reverse():
    for pts in (np.empty((0, 2)), np.array([[math.nan, math.nan]])):
        for v in (0.14, -0.14, 0.0):
            res = ek_egc_filter(v, 0.2, pts, P3DX, L)
            assert res.case is EgcCase.NO_POINTS_UNKNOWN
            assert (res.v_mps, res.w_radps, res.w_si) == (0.0, 0.0, 0.0)


def test_empty_scan_declared_free_passes():
    params = EgcParams(P3DX.r_min_m, P3DX.r_max_m, P3DX.horizon_s, no_return_is_free=True)
    for v, w in ((0.14, 0.2), (-0.1, -0.3)):
        res = ek_egc_filter(v, w, np.empty((0, 2)), params, L)
        assert res.case is EgcCase.NO_POINTS_FREE and (res.v_mps, res.w_radps) == (v, w)


def test_turning_in_place_next_to_a_wall_is_no_translation():
    res = ek_egc_filter(0.0, 0.5, WALL_AHEAD, P3DX, L)
    assert res.case is EgcCase.NO_TRANSLATION and res.p_igc == (0.0, 0.0)
    assert (res.v_mps, res.w_radps) == (0.0, 0.5)  # not scaled by w_SI: no dead-lock
    assert res.r_igc_m == pytest.approx(0.3) and res.w_si == 0.0  # nearest arc length, 0.3 m
    assert res.region is Region.UNSAFE


def test_turning_in_place_with_nothing_near_passes():
    res = ek_egc_filter(0.0, -0.4, np.array([[3.0, 0.0]]), P3DX, L)
    assert res.case is EgcCase.CLEAR and (res.v_mps, res.w_radps) == (0.0, -0.4)


def test_zero_command_stays_zero():
    res = ek_egc_filter(0.0, 0.0, WALL_AHEAD, P3DX, L)
    assert (res.v_mps, res.w_radps, res.modified) == (0.0, 0.0, False)


def test_non_intersecting_circles_regulate_without_expansion():
    # a tiny forward command, a point 0.5 m ahead: r_IGC ~ 0.479 > 2 r_RC ~ 0.04
    res = ek_egc_filter(0.005, 0.0, np.array([[0.5, 0.0]]), P3DX, L)
    assert res.case is EgcCase.NO_INTERSECTION and res.r_igc_m > 2 * res.r_rc_m
    assert res.w_si == pytest.approx(res.r_igc_m / 0.595)
    assert res.v_mps == pytest.approx(0.005 * res.w_si) and res.p_egc == res.p_igc
    res = ek_egc_filter(-0.005, 0.01, np.array([[-0.5, 0.0]]), P3DX, L)  # reverse
    assert res.case is EgcCase.NO_INTERSECTION
    assert (res.v_mps, res.w_radps) == pytest.approx((-0.005 * res.w_si, 0.01 * res.w_si))


def test_point_on_both_centres_stops():
    # the only point maps exactly onto P_IGC = (v kT, 0): r_IGC = 0, P_AGC = P_IGC, r_AGC = 0
    res = ek_egc_filter(0.14, 0.0, np.array([[0.595, 0.0]]), P3DX, L)
    assert res.case is EgcCase.ZERO_WEIGHTS
    assert (res.v_mps, res.w_radps, res.w_si) == (0.0, 0.0, 0.0)
