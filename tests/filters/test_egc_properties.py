"""Properties of the EGC filter (issue 2, item 6) and agreement with the plain reference."""

from __future__ import annotations

import math

import numpy as np
from egc_robot.filters.egc import (
    EgcCase,
    EgcParams,
    command_from_point,
    egc_filter,
    predicted_position,
)
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from tests.filters.reference_egc import reference_egc

P3DX = EgcParams(r_min_m=0.455, r_max_m=0.595, horizon_s=0.595 / 0.14)
JACKAL = EgcParams(r_min_m=0.508, r_max_m=2.508, horizon_s=2.508 / 2.0)

speeds = st.floats(-0.14, 0.14, allow_nan=False)
turns = st.floats(-0.5, 0.5, allow_nan=False)
coords = st.floats(-3.0, 3.0, allow_nan=False)
point_lists = st.lists(st.tuples(coords, coords), min_size=1, max_size=40)


@given(speeds, turns)
def test_eqs_14_15_invert_eq_6_forward_and_reverse(v, w):
    """With P_EGC = P_IGC and w_SI = 1, eqs. 14-15 give back the command (DESIGN 5.7)."""
    assume(abs(v) > 1e-9)
    p = predicted_position(v, w, P3DX.horizon_s)
    v2, w2 = command_from_point(p, 1.0, P3DX.horizon_s)
    assert math.isclose(v2, v, rel_tol=1e-9, abs_tol=1e-12)
    assert math.isclose(w2, w, rel_tol=1e-9, abs_tol=1e-12)


@given(speeds, turns, point_lists)
def test_speed_never_increases(v, w, pts):
    res = egc_filter(v, w, np.array(pts), P3DX)
    assert abs(res.v_mps) <= abs(v) + 1e-12


@given(speeds, turns, point_lists)
def test_passes_unchanged_when_nearest_point_is_r_max_away(v, w, pts):
    p = predicted_position(v, w, P3DX.horizon_s)
    d = min(math.hypot(x - p[0], y - p[1]) for x, y in pts)
    res = egc_filter(v, w, np.array(pts), P3DX)
    if d >= P3DX.r_max_m:
        assert (res.v_mps, res.w_radps, res.modified, res.w_si) == (v, w, False, 1.0)
    else:
        assert res.case is not EgcCase.CLEAR


@given(speeds, turns, point_lists)
def test_zero_safety_index_means_no_translation(v, w, pts):
    res = egc_filter(v, w, np.array(pts), P3DX)
    if res.w_si == 0.0:
        assert res.v_mps == 0.0


@given(
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(allow_nan=True, allow_infinity=True),
    st.lists(st.tuples(st.floats(), st.floats()), max_size=20),
)
@settings(max_examples=300)
def test_output_is_finite_for_any_input(v, w, pts):
    res = egc_filter(v, w, np.array(pts, dtype=float).reshape(-1, 2), P3DX)
    assert math.isfinite(res.v_mps) and math.isfinite(res.w_radps) and 0.0 <= res.w_si <= 1.0
    if not (math.isfinite(v) and math.isfinite(w)):
        assert (res.v_mps, res.w_radps) == (0.0, 0.0)


@given(
    st.floats(-2.0, 2.0),
    st.floats(-2.0, 2.0),
    st.lists(st.tuples(st.floats(-6, 6), st.floats(-6, 6)), min_size=1, max_size=60),
)
@settings(max_examples=300)
def test_agrees_with_plain_reference(v, w, pts):
    for params in (P3DX, JACKAL):
        res = egc_filter(v, w, np.array(pts), params)
        ref = reference_egc(v, w, pts, params.r_min_m, params.r_max_m, params.horizon_s)
        if ref is None:  # an undefined case of DESIGN 5.9, tested on its own
            assert res.case not in (EgcCase.CLEAR, EgcCase.EXPANDED)
            continue
        assert res.case in (EgcCase.CLEAR, EgcCase.EXPANDED)
        assert math.isclose(res.v_mps, ref["v"], abs_tol=1e-9)
        assert math.isclose(res.w_radps, ref["w"], abs_tol=1e-9)
        assert math.isclose(res.w_si, ref["w_si"], abs_tol=1e-9)
        assert res.region.value == ref["region"]
        assert (res.side.value if res.side else None) == ref["side"]
