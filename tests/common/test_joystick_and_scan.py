"""Eq. 4 mapping, deadzone and calibration (DESIGN 4); scans to points (DESIGN 3)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from egc_common.joystick import (
    JoystickMapping,
    apply_deadzone,
    clamp_unit,
    deflection_to_velocity,
    normalise_axis,
)
from egc_common.profiles import JACKAL, PIONEER3DX, get_profile
from egc_common.scan import Scan, obstacle_points, ranges_to_points
from hypothesis import given
from hypothesis import strategies as st


def test_pinned_profiles_match_design_3():
    p = get_profile("pioneer3dx")
    assert (p.length_m, p.width_m, p.v_max_mps, p.w_max_radps) == (0.455, 0.381, 0.14, 0.5)
    assert (p.r_min_m, p.r_max_m) == pytest.approx((0.455, 0.595))
    assert p.horizon_s == pytest.approx(0.595 / 0.14)
    j = get_profile("jackal")
    assert (j.length_m, j.width_m, j.v_max_mps, j.w_max_radps) == (0.508, 0.430, 2.0, 2.0)
    assert (j.r_min_m, j.r_max_m) == pytest.approx((0.508, 2.508))
    with pytest.raises(ValueError, match="known: husky, jackal, pioneer3dx, turtlebot4"):
        get_profile("roomba")
    with pytest.raises(ValueError, match="v_max_mps"):
        PIONEER3DX.with_overrides(v_max_mps=math.nan)


def test_eq4_mapping_with_scale_factors():
    m = JoystickMapping(gamma_v=0.5, gamma_w=1.0)
    assert deflection_to_velocity(1.0, -1.0, 0.14, 0.5, m) == pytest.approx((0.07, -0.5))
    assert deflection_to_velocity(-0.5, 0.5, 2.0, 2.0, JoystickMapping()) == (-1.0, 1.0)
    assert deflection_to_velocity(math.nan, 5.0, 2.0, 2.0, JoystickMapping()) == (0.0, 2.0)
    with pytest.raises(ValueError):
        JoystickMapping(gamma_v=1.5)


@given(st.floats(-1, 1), st.floats(0, 0.5))
def test_deadzone_rescales_and_keeps_range(x, dz):
    y = apply_deadzone(x, dz)
    assert -1.0 <= y <= 1.0
    if abs(x) <= dz:
        assert y == 0.0
    else:
        assert math.copysign(1, y) == math.copysign(1, x)
        assert abs(y) == pytest.approx((abs(x) - dz) / (1 - dz))
    assert apply_deadzone(1.0, dz) == 1.0 and apply_deadzone(-1.0, dz) == -1.0


def test_axis_calibration_from_absinfo():
    assert normalise_axis(0, -32768, 32767, 0) == 0.0
    assert normalise_axis(32767, -32768, 32767, 0) == 1.0
    assert normalise_axis(-32768, -32768, 32767, 0) == -1.0
    assert normalise_axis(128, 0, 255) == pytest.approx(0.5 / 127.5)
    assert normalise_axis(300, 0, 255) == 1.0  # clamped
    assert normalise_axis(10, 0, 255, 10) == 0.0  # off-centre rest reads 0
    with pytest.raises(ValueError):
        normalise_axis(0, 5, 5)
    assert clamp_unit(math.inf) == 1.0 and clamp_unit(-math.inf) == -1.0


def test_scan_invalid_readings_are_dropped():
    ranges = np.array([1.0, np.nan, np.inf, 0.01, 30.0, 10.0, 2.0])
    angles = np.linspace(0, math.pi, ranges.size)
    scan = Scan(angles, ranges, range_min_m=0.05, range_max_m=10.0)
    pts = scan.points()
    assert pts.shape == (3, 2)  # 1.0, 10.0 (= range_max, valid), 2.0
    np.testing.assert_allclose(pts[0], [1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(np.hypot(pts[:, 0], pts[:, 1]), [1.0, 10.0, 2.0])
    assert scan.valid_mask.sum() == 3


def test_scan_uniform_layout_and_mount_offset():
    scan = Scan.uniform([1.0, 1.0], -math.pi / 2, math.pi / 2, 0.1, 5.0, mount_x_m=0.2)
    np.testing.assert_allclose(scan.points(), [[0.2, -1.0], [1.2, 0.0]], atol=1e-12)
    with pytest.raises(ValueError):
        Scan(np.zeros(2), np.zeros(3), 0.1, 5.0)
    with pytest.raises(ValueError):
        Scan(np.zeros(2), np.zeros(2), 5.0, 1.0)
    assert ranges_to_points(np.array([]), np.array([]), 0.1, 1.0).shape == (0, 2)


def test_jackal_radii_scale_with_speed():
    assert JACKAL.d_safe_m == pytest.approx(JACKAL.v_max_mps * 1.0)


def test_obstacle_points_drop_invalid_rows_and_keep_layout():
    pts = [[1.0, 2.0], [np.nan, 0.0], [np.inf, 1.0], [3.0, -2e6], [-0.5, 0.25]]
    obs = obstacle_points(pts)
    assert obs.xy.tolist() == [[1.0, 2.0], [-0.5, 0.25]]
    assert obs.x.tolist() == [1.0, -0.5] and obs.y.tolist() == [2.0, 0.25]
    assert obs.r2.tolist() == pytest.approx([5.0, 0.3125])
    assert obs.xy.flags.c_contiguous and obs.x.flags.c_contiguous and len(obs) == 2
    assert obstacle_points(obs) is obs
    assert obstacle_points([]).xy.shape == (0, 2)
    with pytest.raises(ValueError, match=r"\(N, 2\)"):
        obstacle_points([1.0, 2.0, 3.0])


def test_scan_points_are_prepared_once_and_read_only():
    scan = Scan.uniform([1.0, np.nan, 2.0], 0.0, math.pi / 2, 0.05, 10.0)
    first = scan.obstacles()
    assert scan.obstacles() is first and scan.points() is first.xy
    np.testing.assert_allclose(first.xy, [[1.0, 0.0], [-2.0, 0.0]], atol=1e-12)
    with pytest.raises(ValueError):
        first.xy[0, 0] = 5.0


def test_minus_inf_beams_of_an_absurd_range_min_stay_a_few_places_each():
    # An outside check: 20 -inf beams with range_min 9999 m (a broken message) sampled every
    # 2 cm asked for 10 million places and 1.4 GB. At most 64 places a beam now, the nearest
    # (where the beam leaves the footprint) always among them.
    from egc_common.scan import too_close_points

    angles = np.linspace(-0.2, 0.2, 20)
    half = (PIONEER3DX.length_m / 2, PIONEER3DX.width_m / 2)
    pts = too_close_points(angles, 9999.0, 0.0, 0.0, half)
    assert 0 < len(pts) <= 20 * 64
    assert np.all(np.isfinite(pts))
    near = too_close_points(angles, 0.5, 0.0, 0.0, half)  # an ordinary range_min
    assert pts[:, 0].min() == pytest.approx(near[:, 0].min(), abs=1e-3)  # the front edge
