"""The Dynamic Window Approach filter (DESIGN 6, issue 10 item 3).

Safety is checked independently of the filter's closed-form contact angles: with the pipeline's
sampled footprint sweep (``safety.sweep_min_clearance``) over the same stopping model.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from egc_common.footprint import Footprint, mitre_factor, mitred_outline, signed_distance
from egc_common.kinematics import signed_distance_to_rectangle
from egc_common.profiles import HUSKY, JACKAL, PIONEER3DX, RobotProfile
from egc_robot.filters.dwa import (
    DwaCase,
    DwaParams,
    contact_angles,
    disc_contact_angles,
    dwa_filter,
    dynamic_window,
    polygon_contact_angles,
    polygon_straight_free,
    stopping_times,
)
from egc_robot.safety import (
    SweepParams,
    footprint_clearance,
    stopping_time_s,
    sweep_min_clearance,
)
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.shapes import DISC, L_SHAPE, PENTAGON

FAR = np.array([[30.0, 30.0]])  # one point far away: a scan that sees, and sees nothing near


def wall_x(x_m: float, half_span_m: float = 2.0, n: int = 201) -> np.ndarray:
    """A wall across the path at x (x < 0: behind)."""
    return np.column_stack((np.full(n, x_m), np.linspace(-half_span_m, half_span_m, n)))


def wall_y(y_m: float, half_span_m: float = 2.0, n: int = 201) -> np.ndarray:
    """A wall along the path at y (> 0: on the left)."""
    return np.column_stack((np.linspace(-half_span_m, half_span_m, n), np.full(n, y_m)))


def swept_clearance(v: float, w: float, pts: np.ndarray, profile: RobotProfile, p: DwaParams):
    """The footprint's smallest clearance while holding (v, w) for the latency, then braking."""
    sweep = SweepParams(margin_m=p.margin_m, period_s=p.latency_s, step_m=0.002, step_rad=0.005)
    t = stopping_time_s(v, w, profile, sweep)
    return sweep_min_clearance(v, w, t, pts, profile, sweep)


# -- free space -------------------------------------------------------------------------------


@pytest.mark.parametrize("profile", [PIONEER3DX, JACKAL], ids=lambda p: p.name)
@pytest.mark.parametrize("frac", [(1.0, 0.0), (0.5, 0.3), (0.2, -1.0), (0.0, 0.5), (-0.5, 0.2)])
def test_free_space_without_goal_passes_a_reachable_command(profile, frac):
    v = frac[0] * profile.v_max_mps
    w = frac[1] * profile.w_max_radps
    res = dwa_filter(v, w, FAR, v, w, None, profile, DwaParams.from_profile(profile))
    assert res.case is DwaCase.CHOSEN and not res.stopped
    assert (res.v_mps, res.w_radps) == (v, w) and not res.modified
    assert res.heading == 1.0 and res.clearance == 1.0


def test_free_space_unreachable_command_gives_the_closest_in_the_window():
    p = DwaParams.from_profile(PIONEER3DX)
    res = dwa_filter(0.14, 0.5, FAR, 0.0, 0.0, None, PIONEER3DX, p)
    v_reach = PIONEER3DX.accel_max_mps2 * p.period_s
    w_reach = PIONEER3DX.angular_accel_max_radps2 * p.period_s
    assert res.v_mps == pytest.approx(v_reach) and res.w_radps == pytest.approx(w_reach)
    assert res.modified and not res.stopped


def test_reverse_only_when_the_operator_asks_for_it():
    p = DwaParams.from_profile(PIONEER3DX)
    fwd = dwa_filter(0.0, 0.3, FAR, 0.0, 0.0, None, PIONEER3DX, p)
    assert fwd.window[0] >= 0.0 and fwd.v_mps >= 0.0
    rev = dwa_filter(-0.1, 0.0, FAR, -0.1, 0.0, None, PIONEER3DX, p)
    assert rev.window[1] <= 0.0 and (rev.v_mps, rev.w_radps) == (-0.1, 0.0)


def test_reverse_asked_while_driving_forward_fast_brakes_as_hard_as_it_can():
    p = DwaParams.from_profile(JACKAL)
    res = dwa_filter(-1.0, 0.0, FAR, 2.0, 0.0, None, JACKAL, p)
    v_lo = 2.0 - JACKAL.decel_max_mps2 * p.period_s
    assert res.window[:2] == pytest.approx((v_lo, v_lo)) and res.v_mps == pytest.approx(v_lo)


# -- obstacles --------------------------------------------------------------------------------


@pytest.mark.parametrize("profile", [PIONEER3DX, JACKAL], ids=lambda p: p.name)
@pytest.mark.parametrize("gap_m", [0.005, 0.02, 0.1, 0.3, 0.6])
def test_wall_ahead_chosen_velocity_stops_before_contact(profile, gap_m):
    p = DwaParams.from_profile(profile)
    pts = wall_x(0.5 * profile.length_m + gap_m)
    v = profile.v_max_mps
    res = dwa_filter(v, 0.0, pts, v, 0.0, None, profile, p)
    if not res.stopped:
        clearance = swept_clearance(res.v_mps, res.w_radps, pts, profile, p)
        assert clearance >= min(p.margin_m, gap_m) - 1e-6
    # Full speed cannot stop in so short a gap: something was changed.
    t_full = stopping_time_s(v, 0.0, profile, SweepParams(period_s=p.latency_s))
    if v * t_full > gap_m - p.margin_m:
        assert res.modified


def test_wall_ahead_straight_speed_meets_v_le_sqrt_2_dist_a_dec():
    """The paper's bound, with no latency: straight on at the largest admissible v."""
    prof = JACKAL
    p = DwaParams.from_profile(prof, latency_s=0.0, margin_m=0.0, v_samples=201, w_samples=3)
    dist = 0.4
    pts = wall_x(0.5 * prof.length_m + dist)
    res = dwa_filter(2.0, 0.0, pts, 1.5, 0.0, None, prof, p)
    assert res.w_radps == 0.0 and res.v_mps > 0.0
    bound = math.sqrt(2.0 * dist * prof.decel_max_mps2)
    assert res.v_mps <= bound + 1e-9
    assert res.v_mps >= bound - (res.window[1] - res.window[0]) / 200 - 1e-9  # grid resolution


def test_driving_along_a_wall_inside_the_margin_is_allowed():
    """DESIGN 5.10: closer than the margin, motion that keeps the clearance is fine."""
    p = DwaParams.from_profile(PIONEER3DX)
    pts = wall_y(0.5 * PIONEER3DX.width_m + 0.01)
    res = dwa_filter(0.14, 0.0, pts, 0.14, 0.0, None, PIONEER3DX, p)
    assert (res.v_mps, res.w_radps) == (0.14, 0.0) and not res.stopped


def test_backing_away_from_a_wall_ahead_is_allowed():
    p = DwaParams.from_profile(PIONEER3DX)
    pts = wall_x(0.5 * PIONEER3DX.length_m + 0.005)
    res = dwa_filter(-0.1, 0.0, pts, 0.0, 0.0, None, PIONEER3DX, p)
    assert res.v_mps < 0.0 and not res.stopped


def test_reverse_checks_the_arc_behind():
    prof = PIONEER3DX
    p = DwaParams.from_profile(prof)
    pts = wall_x(-(0.5 * prof.length_m + 0.01))
    res = dwa_filter(-0.14, 0.0, pts, -0.14, 0.0, None, prof, p)
    assert res.modified
    if not res.stopped:
        assert res.v_mps <= 0.0
        assert swept_clearance(res.v_mps, res.w_radps, pts, prof, p) >= 0.01 - 1e-6


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_goal_to_one_side_in_free_space_turns_that_way(side):
    p = DwaParams.from_profile(PIONEER3DX)
    res = dwa_filter(0.1, 0.0, FAR, 0.1, 0.0, (0.5, side * 2.0), PIONEER3DX, p)
    assert res.goal_mode and not res.stopped
    assert side * res.w_radps > 0.0
    assert res.w_radps == pytest.approx(res.window[3] if side > 0 else res.window[2])


def test_no_admissible_velocity_stops():
    """Boxed in 5 mm all round, moving: nothing but stopping is admissible."""
    prof = PIONEER3DX
    hl, hw = 0.5 * prof.length_m + 0.005, 0.5 * prof.width_m + 0.005
    ring = np.concatenate(
        [
            np.column_stack((np.full(50, hl), np.linspace(-hw, hw, 50))),
            np.column_stack((np.full(50, -hl), np.linspace(-hw, hw, 50))),
            np.column_stack((np.linspace(-hl, hl, 50), np.full(50, hw))),
            np.column_stack((np.linspace(-hl, hl, 50), np.full(50, -hw))),
        ]
    )
    res = dwa_filter(0.14, 0.3, ring, 0.14, 0.3, None, prof, DwaParams.from_profile(prof))
    assert res.stopped and res.case is DwaCase.NO_ADMISSIBLE
    assert (res.v_mps, res.w_radps) == (0.0, 0.0) and res.modified


def test_point_inside_the_footprint_stops():
    res = dwa_filter(
        0.1, 0.0, np.array([[0.1, 0.0], [5, 5]]), 0.0, 0.0, None, PIONEER3DX, DwaParams()
    )
    assert res.stopped and (res.v_mps, res.w_radps) == (0.0, 0.0)


# -- undefined inputs -------------------------------------------------------------------------


@pytest.mark.parametrize(
    "pts", [np.empty((0, 2)), np.array([[math.nan, math.nan], [math.inf, 0.0]])]
)
def test_no_points_is_unknown_and_stops(pts):
    res = dwa_filter(0.1, 0.2, pts, 0.1, 0.2, None, PIONEER3DX, DwaParams())
    assert res.case is DwaCase.NO_POINTS_UNKNOWN and res.stopped
    assert (res.v_mps, res.w_radps) == (0.0, 0.0)


def test_no_points_declared_free_passes():
    p = DwaParams.from_profile(PIONEER3DX, no_return_is_free=True)
    res = dwa_filter(0.1, 0.2, np.empty((0, 2)), 0.1, 0.2, None, PIONEER3DX, p)
    assert res.case is DwaCase.NO_POINTS_FREE and (res.v_mps, res.w_radps) == (0.1, 0.2)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, 1e300])
@pytest.mark.parametrize("where", range(6))
def test_invalid_numbers_stop(bad, where):
    args = [0.1, 0.2, 0.1, 0.2, 1.0, 1.0]
    args[where] = bad
    v, w, vn, wn, gx, gy = args
    res = dwa_filter(v, w, FAR, vn, wn, (gx, gy), PIONEER3DX, DwaParams())
    assert res.case is DwaCase.INVALID_INPUT and res.stopped
    assert (res.v_mps, res.w_radps) == (0.0, 0.0)


# -- window and properties --------------------------------------------------------------------

profiles = st.sampled_from([PIONEER3DX, JACKAL, HUSKY, DISC, PENTAGON, L_SHAPE])
fractions = st.floats(-1.0, 1.0, allow_nan=False)
coords = st.floats(-3.0, 3.0, allow_nan=False)
clouds = st.lists(st.tuples(coords, coords), min_size=1, max_size=30)


@settings(max_examples=150, deadline=None)
@given(profiles, fractions, fractions, fractions, fractions)
def test_window_respects_acceleration_and_profile_limits(prof, fv, fw, fvn, fwn):
    p = DwaParams.from_profile(prof)
    v_ref, w_ref = fv * prof.v_max_mps, fw * prof.w_max_radps
    v_now, w_now = fvn * prof.v_max_mps, fwn * prof.w_max_radps
    res = dwa_filter(v_ref, w_ref, FAR, v_now, w_now, None, prof, p)
    assert not res.stopped
    dt = p.period_s
    up, down = prof.accel_max_mps2 * dt, prof.decel_max_mps2 * dt
    dv = res.v_mps - v_now
    # Through zero the window brakes at the deceleration limit. Signs, not the product: a
    # product underflows to -0.0 (v_now -5e-324 times 0.375 passed as the same sign).
    speeding_up = abs(res.v_mps) > abs(v_now) and (res.v_mps >= 0.0) == (v_now >= 0.0)
    assert abs(dv) <= (up if speeding_up else down) + 1e-12
    assert abs(res.w_radps - w_now) <= prof.angular_accel_max_radps2 * dt + 1e-12
    assert abs(res.v_mps) <= prof.v_max_mps and abs(res.w_radps) <= prof.w_max_radps
    assert res.window == dynamic_window(v_now, w_now, v_ref, prof, p)


@settings(max_examples=200, deadline=None)
@given(profiles, fractions, fractions, fractions, fractions, clouds, st.booleans())
def test_chosen_velocity_is_never_admissible_violating(prof, fv, fw, fvn, fwn, cloud, goal):
    """Whatever is chosen, the footprint's sampled sweep over the stop keeps the margin (or, if
    closer already, does not get closer): g = min(margin, clearance now), a polygon other than
    the centred rectangle g / mitre_factor along its edges (module docstring: its mitred outline
    reaches g at the corners; the pentagon's right-angled rear, g / sqrt 2)."""
    p = DwaParams.from_profile(prof)
    pts = np.array(cloud, dtype=float)
    v_now, w_now = fvn * prof.v_max_mps, fwn * prof.w_max_radps
    goal_xy = (2.0, 1.0) if goal else None
    res = dwa_filter(
        fv * prof.v_max_mps, fw * prof.w_max_radps, pts, v_now, w_now, goal_xy, prof, p
    )
    if res.stopped:
        assert (res.v_mps, res.w_radps) == (0.0, 0.0)
        return
    now = footprint_clearance(pts, prof)
    assert now > 0.0
    grow = min(p.margin_m, now)
    fp = prof.footprint
    if fp.centred_box is None and not fp.is_disc:
        grow /= mitre_factor(fp)
    required = grow - 1e-6
    assert swept_clearance(res.v_mps, res.w_radps, pts, prof, p) >= required


def test_stopping_times_is_the_sweeps_model():
    v = np.array([0.0, 0.1, -2.0, 1.0])
    w = np.array([0.5, 0.0, 1.0, -6.0])
    got = stopping_times(v, w, JACKAL, 0.05)
    want = [
        stopping_time_s(a, b, JACKAL, SweepParams(period_s=0.05)) for a, b in zip(v, w, strict=True)
    ]
    assert got == pytest.approx(want, abs=1e-15)


@settings(max_examples=200, deadline=None)
@given(
    st.one_of(st.just(0.0), st.floats(0.0, 0.5), st.floats(0.5, 50.0)),
    coords,
    coords,
)
def test_contact_angle_matches_a_fine_brute_force_orbit(radius, x, y):
    hl, hw = 0.25, 0.2
    if signed_distance_to_rectangle(x, y, hl, hw) <= 1e-3:
        return
    got = contact_angles(
        np.array([[radius]]), np.array([[x]]), np.array([[y]]), np.array([[hl]]), np.array([[hw]])
    )[0]
    want = _orbit_first_inside(
        radius, x, y, lambda px, py: signed_distance_to_rectangle(px, py, hl, hw)
    )
    if want == math.inf:
        assert got == math.inf or got > 2.0 * math.pi - 1e-3
    else:
        assert got == pytest.approx(want, abs=1e-4)


def _first_inside(samples: np.ndarray, step_m: float, at, sd_fn) -> float:
    """The first of ``samples`` (a fine grid of a path) at which the point is inside the shape
    (``sd_fn`` <= 0), as if every sample were tested, with ``sd_fn`` (a signed distance: it
    changes by no more than the point moves) evaluated on every 64th sample and then only in
    the blocks that start close enough to hold an inside sample: a block whose first sample is
    farther than the path's length over the block (``step_m`` per sample) has none. ``at``
    maps samples to the point's (x, y)."""
    block = 64
    heads = samples[::block]
    sd = sd_fn(*at(heads))
    near = np.flatnonzero(sd <= block * step_m * (1.0 + 1e-6) + 1e-9)
    if not len(near):
        return math.inf
    index = (near[:, None] * block + np.arange(block)).ravel()
    index = index[index < len(samples)]
    inside = sd_fn(*at(samples[index])) <= 0.0
    return float(samples[index[np.argmax(inside)]]) if inside.any() else math.inf


_ORBIT = np.linspace(0.0, 2.0 * math.pi, 200_001)


def _orbit_first_inside(radius: float, x: float, y: float, sd_fn) -> float:
    """The first clockwise angle about (0, R) at which the point is inside (brute force over
    200,000 steps of the turn, ``_first_inside``'s screening)."""

    def at(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        px = np.cos(t) * x + np.sin(t) * (y - radius)
        py = -np.sin(t) * x + np.cos(t) * (y - radius) + radius
        return px, py

    step_m = math.hypot(x, y - radius) * (_ORBIT[1] - _ORBIT[0])  # the arc over one step
    return _first_inside(_ORBIT, step_m, at, sd_fn)


_OUTLINES = {
    "pentagon": PENTAGON.footprint.vertices,
    "l-shape": L_SHAPE.footprint.vertices,
    "l-shape mirrored": L_SHAPE.footprint.vertices * np.array([-1.0, 1.0]),
}


@pytest.mark.parametrize("shape", sorted(_OUTLINES))
@settings(max_examples=80, deadline=None)
@given(
    st.one_of(st.just(0.0), st.floats(0.0, 0.5), st.floats(0.5, 50.0)),
    coords,
    coords,
)
def test_polygon_contact_angle_matches_a_fine_brute_force_orbit(shape, radius, x, y):
    outline = _OUTLINES[shape]
    fp = Footprint.polygon(outline.tolist())
    if signed_distance(fp, x, y) <= 1e-3:
        return
    got = polygon_contact_angles(np.array([[radius]]), np.array([[x]]), np.array([[y]]), outline)[0]
    want = _orbit_first_inside(radius, x, y, lambda px, py: signed_distance(fp, px, py))
    if got < want - 1e-4:  # only a graze of a corner, which sampling steps over, comes first
        px = math.cos(got) * x + math.sin(got) * (y - radius)
        py = -math.sin(got) * x + math.cos(got) * (y - radius) + radius
        assert abs(float(signed_distance(fp, px, py))) <= 1e-9
    elif want == math.inf:
        assert got == math.inf or got > 2.0 * math.pi - 1e-3
    else:
        assert got == pytest.approx(want, abs=1e-4)


@settings(max_examples=150, deadline=None)
@given(st.one_of(st.just(0.0), st.floats(0.0, 0.5), st.floats(0.5, 50.0)), coords, coords)
def test_disc_contact_angle_matches_a_fine_brute_force_orbit(radius, x, y):
    r = 0.171
    if math.hypot(x, y) - r <= 1e-3:
        return
    got = disc_contact_angles(np.array([[radius]]), np.array([[x]]), np.array([[y]]), r)[0]
    want = _orbit_first_inside(radius, x, y, lambda px, py: np.hypot(px, py) - r)
    if want == math.inf:
        assert got == math.inf or got > 2.0 * math.pi - 1e-3
    else:
        assert got == pytest.approx(want, abs=1e-4)


@settings(max_examples=150, deadline=None)
@given(st.one_of(st.just(0.0), st.floats(0.0, 0.5), st.floats(0.5, 50.0)), coords, coords)
def test_polygon_contact_angle_on_a_rectangle_is_the_closed_form(radius, x, y):
    hl, hw = 0.25, 0.2
    if signed_distance_to_rectangle(x, y, hl, hw) <= 1e-3:
        return
    rect = Footprint.rectangle(2 * hl, 2 * hw).vertices
    args = np.array([[radius]]), np.array([[x]]), np.array([[y]])
    want = contact_angles(*args, np.array([[hl]]), np.array([[hw]]))[0]
    got = polygon_contact_angles(*args, rect)[0]
    assert got == pytest.approx(want, abs=1e-9) or (got > 6.28 and want > 6.28)


@settings(max_examples=80, deadline=None)
@given(coords, coords)
def test_polygon_straight_free_is_the_distance_to_the_first_touch(x, y):
    outline = L_SHAPE.footprint.vertices
    fp = L_SHAPE.footprint
    if signed_distance(fp, x, y) <= 1e-3 or np.abs(outline[:, 1] - y).min() < 1e-9:
        return  # touching now, or grazing a corner at the height of a vertex
    got = polygon_straight_free(np.array([x]), np.array([y]), outline)
    s = np.linspace(0.0, 7.0, 70_001)  # the robot moves +x: the point moves -x
    want = _first_inside(
        s,
        s[1] - s[0],
        lambda d: (x - d, np.full_like(d, y)),
        lambda px, py: signed_distance(fp, px, py),
    )
    assert got == pytest.approx(want, abs=2e-4) or (got == math.inf and want == math.inf)


def test_l_shape_drives_past_an_obstacle_in_its_notch():
    """A post in the L's notch (inside the bounding box, outside the robot) does not stop it
    backing away or turning left out of it; driving ahead into the notch's back wall does."""
    p = DwaParams.from_profile(L_SHAPE)
    post = np.array([[0.15, -0.15]])
    assert signed_distance(L_SHAPE.footprint, 0.15, -0.15) == pytest.approx(0.15)
    back = dwa_filter(-0.3, 0.0, post, 0.0, 0.0, None, L_SHAPE, p)
    assert back.v_mps < 0.0 and not back.stopped
    # Straight ahead the post stays in the notch until the notch's inner edge (x = 0) is
    # 0.15 m on: the free distance, not zero and not unlimited.
    outline = mitred_outline(L_SHAPE.footprint, 0.0)
    assert polygon_straight_free(post[:, 0], post[:, 1], outline) == pytest.approx(0.15)


# -- parameters -------------------------------------------------------------------------------


def test_params_from_profile_and_mapping():
    p = DwaParams.from_profile(JACKAL)
    assert p.lookahead_m == JACKAL.r_max_m
    q = DwaParams.from_mapping({"period_s": 1, "v_samples": 5.0, "alpha": 1.5}, JACKAL)
    assert (q.period_s, q.v_samples, q.alpha, q.lookahead_m) == (1.0, 5, 1.5, JACKAL.r_max_m)
    assert isinstance(q.period_s, float)
    assert set(DwaParams.keys()) >= {"period_s", "v_samples", "w_samples", "alpha", "beta"}


@pytest.mark.parametrize(
    "table",
    [
        {"perod_s": 0.2},
        {"period_s": 0.0},
        {"period_s": "fast"},
        {"v_samples": 1},
        {"w_samples": 2.5},
        {"alpha": -1.0},
        {"alpha": 0.0, "beta": 0.0, "gamma": 0.0},
        {"lookahead_m": math.inf},
        {"no_return_is_free": 1},
        {"margin_m": True},
        {"margin_m": 0.02},  # below the sweep's margin: DWA would stall against the sweep
        {"latency_s": 0.0},
    ],
)
def test_params_mapping_rejects_bad_values(table):
    with pytest.raises(ValueError, match="dwa"):
        DwaParams.from_mapping(table)
