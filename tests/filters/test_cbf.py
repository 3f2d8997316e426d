"""The control barrier function filter ``cbf`` (DESIGN 13).

The barriers are checked against ``barrier_rows``, a plain per-point re-statement of the module
docstring's definitions (footprint distance, approach rate, the margins at the current and at
the commanded speed), and the answer's optimality against brute-force sampling of the feasible
polygon, so that neither check relies on the filter's own vectorised geometry or closed-form QP.
"""

from __future__ import annotations

import itertools
import math
from unittest import mock

import numpy as np
import pytest
from egc_common.footprint import Footprint, signed_distance
from egc_common.profiles import JACKAL, PIONEER3DX, TURTLEBOT4, RobotProfile
from egc_common.scan import obstacle_points
from egc_robot.filters import cbf as cbf_module
from egc_robot.filters.cbf import (
    CREEP_BELOW,
    CREEP_PER_S,
    PATH_POWER,
    CbfCase,
    CbfParams,
    _checks,
    _first_projection,
    _nearest_in,
    _project,
    _stop_and_turn,
    cbf_filter,
)
from egc_robot.filters.egc import EgcParams
from egc_robot.filters.family import FilterInput, FilterSettings, RobotState, run_filter
from hypothesis import assume, given, settings
from hypothesis import strategies as st

TOL = 1e-7  # m/s: a constraint counts as met when short of it by no more than this
# Output change (share of v_max, w_max) below which no jump is judged: the solver's answer is
# exact to its rounding, which a row beside the flank (|b| of a few mm) amplifies to a few
# 1e-7 of w_max (a Pioneer found 4.4e-7). A jump this test exists for is of the output's own
# size (the creep's flip: none to full turn).
SOLVER_SLACK = 1e-6


def barrier_rows(
    points: np.ndarray,
    v_ref: float,
    w_ref: float,
    v_now: float,
    w_now: float,
    tau: float,
    profile: RobotProfile,
    params: CbfParams,
) -> list[tuple[float, float, float]]:
    """(a, b, c) of every constraint a v + b w >= c, one point at a time (module docstring)."""
    hl, hw = profile.half_size_m
    a_dec, al_dec = profile.decel_max_mps2, profile.angular_accel_max_radps2
    t_now = max(abs(v_now) / a_dec, abs(w_now) / al_dec)
    k_now = tau + params.period_s + 0.5 * t_now
    k_cmd = tau + params.period_s + 0.5 * max(t_now, abs(v_ref) / a_dec, abs(w_ref) / al_dec)
    rows = []
    for x, y in points:
        qx, qy = min(max(x, -hl), hl), min(max(y, -hw), hw)
        d = math.hypot(x - qx, y - qy)
        if d > 0.0:
            nx, ny, sd = (x - qx) / d, (y - qy) / d, d
        else:  # inside: the nearest edge
            edges = [
                (hl - x, 1.0, 0.0),
                (x + hl, -1.0, 0.0),
                (hw - y, 0.0, 1.0),
                (y + hw, 0.0, -1.0),
            ]
            depth, nx, ny = min(edges, key=lambda e: e[0])
            sd = -depth
            qx = nx * hl if nx else x
            qy = ny * hw if ny else y
        b = nx * qy - ny * qx

        def approach(v: float, w: float, nx=nx, b=b) -> float:
            return nx * v - b * w

        def omega(v: float, w: float, nx=nx, ny=ny, qx=qx, qy=qy) -> float:
            gx, gy = v - w * qy, w * qx
            speed = math.hypot(gx, gy)
            u = nx * gx + ny * gy
            if speed <= 0.0 or u <= 0.0:
                return 0.0
            return min(u / speed, 1.0) ** PATH_POWER

        room = sd - params.margin_m
        u_now = max(approach(v_now, w_now), 0.0)
        m_state = omega(v_now, w_now) * k_now * u_now
        reach_u = abs(nx) * profile.v_max_mps + abs(b) * profile.w_max_radps
        creep = CREEP_PER_S * max(1.0 - reach_u / (CREEP_BELOW * profile.v_max_mps), 0.0)
        creep *= max(sd, 0.0)
        rows.append((-nx, b, -max(params.alpha_per_s * (room - m_state), creep)))  # (S)
        gain = 1.0 + params.alpha_per_s * k_cmd * omega(v_ref, w_ref)
        rows.append((-gain * nx, gain * b, -max(params.alpha_per_s * room, creep)))  # (C)
    return rows


def worst_violation(rows: list[tuple[float, float, float]], v: float, w: float) -> float:
    """How far (v, w) falls short of the tightest row (<= 0: every row met)."""
    return max((c - (a * v + b * w) for a, b, c in rows), default=-math.inf)


PROFILES = [JACKAL, PIONEER3DX]
points_st = st.lists(
    st.tuples(st.floats(-3.0, 3.0), st.floats(-3.0, 3.0)), min_size=1, max_size=40
).map(lambda p: np.array(p, dtype=np.float64))
near_st = st.lists(
    st.tuples(st.floats(-1.2, 1.2), st.floats(-1.2, 1.2)), min_size=1, max_size=30
).map(lambda p: np.array(p, dtype=np.float64))


def outside(points: np.ndarray, profile: RobotProfile, by_m: float = 0.005) -> np.ndarray:
    hl, hw = profile.half_size_m
    dx = np.maximum(np.abs(points[:, 0]) - hl, 0.0)
    dy = np.maximum(np.abs(points[:, 1]) - hw, 0.0)
    return points[np.hypot(dx, dy) > by_m]


def command_st(profile: RobotProfile):
    return st.tuples(
        st.floats(-1.0, 1.0).map(lambda f: f * profile.v_max_mps),
        st.floats(-1.0, 1.0).map(lambda f: f * profile.w_max_radps),
    )


# -- the properties of DESIGN 13 -------------------------------------------------------------


@pytest.mark.parametrize("profile", PROFILES, ids=lambda p: p.name)
@settings(max_examples=300)
@given(data=st.data(), pts=points_st, tau=st.floats(0.0, 1.5))
def test_a_command_that_keeps_every_barrier_comes_back_bit_for_bit(profile, data, pts, tau):
    params = CbfParams.from_profile(profile)
    v, w = data.draw(command_st(profile))
    v_now, w_now = data.draw(command_st(profile))
    rows = barrier_rows(pts, v, w, v_now, w_now, tau, profile, params)
    res = cbf_filter(v, w, pts, v_now, w_now, tau, profile, params)
    if worst_violation(rows, v, w) <= 0.0:
        assert res.v_mps is v and res.w_radps is w  # the very objects: unchanged to the bit
        assert not res.modified and res.case is CbfCase.CLEAR
    elif worst_violation(rows, v, w) > 1e-6:
        assert res.modified


@pytest.mark.parametrize("profile", PROFILES, ids=lambda p: p.name)
@settings(max_examples=300)
@given(data=st.data(), pts=points_st, tau=st.floats(0.0, 1.5))
def test_the_output_satisfies_every_constraint_and_the_box(profile, data, pts, tau):
    params = CbfParams.from_profile(profile)
    v, w = data.draw(command_st(profile))
    v_now, w_now = data.draw(command_st(profile))
    res = cbf_filter(v, w, pts, v_now, w_now, tau, profile, params)
    rows = barrier_rows(pts, v, w, v_now, w_now, tau, profile, params)
    assert worst_violation(rows, res.v_mps, res.w_radps) <= TOL
    assert abs(res.v_mps) <= profile.v_max_mps + 1e-12
    assert abs(res.w_radps) <= profile.w_max_radps + 1e-12


@pytest.mark.parametrize("profile", PROFILES, ids=lambda p: p.name)
@settings(max_examples=200)
@given(data=st.data(), pts=near_st, tau=st.floats(0.0, 1.5))
def test_the_output_is_the_closest_command_that_keeps_the_barriers(profile, data, pts, tau):
    """Optimality, by brute force: no sampled feasible command is closer (weighted)."""
    params = CbfParams.from_profile(profile)
    v, w = data.draw(command_st(profile))
    v_now, w_now = data.draw(command_st(profile))
    res = cbf_filter(v, w, pts, v_now, w_now, tau, profile, params)
    if res.case is not CbfCase.SOLVED:
        return  # unchanged (the bit-for-bit test) or a rule's stop
    rows = np.array(barrier_rows(pts, v, w, v_now, w_now, tau, profile, params))
    rng = np.random.default_rng(0)
    vs = rng.uniform(-profile.v_max_mps, profile.v_max_mps, 20_000)
    ws = rng.uniform(-profile.w_max_radps, profile.w_max_radps, 20_000)
    ok = (rows[:, 0, None] * vs + rows[:, 1, None] * ws >= rows[:, 2, None]).all(axis=0)

    def cost(vv, ww):
        return ((vv - v) / profile.v_max_mps) ** 2 + ((ww - w) / profile.w_max_radps) ** 2

    assert cost(res.v_mps, res.w_radps) <= cost(vs[ok], ws[ok]).min(initial=math.inf) + 1e-9


@pytest.mark.parametrize("profile", PROFILES, ids=lambda p: p.name)
@settings(max_examples=300)
@given(data=st.data(), pts=near_st, tau=st.floats(0.0, 1.5))
def test_motion_away_from_every_obstacle_is_never_refused(profile, data, pts, tau):
    """A command under which the footprint approaches no point passes unchanged, however close
    the points are (inside the margin, or touching: no dead-lock). The scan is cut down to the
    points the drawn command moves away from (or keeps its distance to)."""
    params = CbfParams.from_profile(profile)
    v, w = data.draw(command_st(profile))
    v_now, w_now = data.draw(command_st(profile))
    rows = barrier_rows(pts, v, w, v_now, w_now, tau, profile, params)
    # (S) rows' (a, b) are the approach's negatives: a v + b w >= 0 is "not approaching".
    away = np.array([a * v + b * w >= 0.0 for a, b, _ in rows[::2]])
    assume(away.any())
    res = cbf_filter(v, w, pts[away], v_now, w_now, tau, profile, params)
    assert (res.v_mps, res.w_radps) == (v, w)


@pytest.mark.parametrize(
    ("pts", "v", "w"),
    [
        (np.array([[0.28, 0.0], [0.28, 0.1], [0.28, -0.1]]), -0.5, 0.0),  # back off a wall
        (np.array([[0.0, 0.23], [0.1, 0.23], [-0.1, 0.23]]), 0.5, 0.0),  # along a wall at 1.5 cm
        (np.array([[0.0, 0.23], [0.1, 0.23], [-0.1, 0.23]]), -0.5, 0.0),
        (np.array([[0.0, 0.23], [0.1, 0.23], [-0.1, 0.23]]), 0.0, 0.0),
        (np.array([[0.2, 0.0]]), -0.3, 0.0),  # touching (inside the footprint): back away
    ],
)
def test_a_robot_inside_its_margin_may_leave_or_keep_its_distance(pts, v, w):
    res = cbf_filter(v, w, pts, v, w, None, JACKAL, CbfParams.from_profile(JACKAL))
    assert (res.v_mps, res.w_radps) == (v, w)


@pytest.mark.parametrize("profile", PROFILES, ids=lambda p: p.name)
@settings(max_examples=60)
@given(
    data=st.data(),
    bearing=st.floats(-math.pi, math.pi),
    offset=st.floats(-0.6, 0.6),
    tau=st.floats(0.0, 1.0),
)
def test_the_output_is_continuous_as_an_obstacle_approaches(profile, data, bearing, offset, tau):
    """A wall piece moving in from 3 m along a straight line, 5 mm a step, up to 1 cm from the
    footprint. The five largest changes between steps are bisected 20 times, following the
    larger change: a continuous output's change shrinks with the interval (a million-fold for
    a uniform slope, still a thousand-fold where two nearly parallel barriers make it 1000x
    steeper locally), a jump keeps its size."""
    params = CbfParams.from_profile(profile)
    v, w = data.draw(command_st(profile))
    v_now, w_now = data.draw(command_st(profile))
    c, s = math.cos(bearing), math.sin(bearing)
    piece = np.array([[0.0, offset - 0.1], [0.0, offset], [0.0, offset + 0.1]])
    piece = piece @ np.array([[c, s], [-s, c]])  # the piece, turned to face the robot
    heading = np.array([c, s])
    scale = np.array([profile.v_max_mps, profile.w_max_radps])

    def output(r: float) -> np.ndarray:
        res = cbf_filter(v, w, piece + r * heading, v_now, w_now, tau, profile, params)
        return np.array([res.v_mps, res.w_radps]) / scale

    radii = list(  # until the piece comes within 1 cm of the footprint
        itertools.takewhile(
            lambda r: len(outside(piece + r * heading, profile, 0.01)) == 3,
            np.arange(3.0, 0.0, -0.005),
        )
    )
    outs = [output(r) for r in radii]
    changes = [float(np.abs(b - a).max()) for a, b in itertools.pairwise(outs)]
    for i in np.argsort(changes)[::-1][:5]:
        change = changes[i]
        if change <= 1e-6:
            break
        lo, hi, f_lo, f_hi = radii[i + 1], radii[i], outs[i + 1], outs[i]
        for _ in range(20):
            mid = 0.5 * (lo + hi)
            f_mid = output(mid)
            if np.abs(f_mid - f_lo).max() >= np.abs(f_hi - f_mid).max():
                hi, f_hi = mid, f_mid
            else:
                lo, f_lo = mid, f_mid
        jump = np.abs(f_hi - f_lo).max()
        assert jump <= max(change / 1000.0, SOLVER_SLACK), (radii[i], change, f_lo, f_hi)


@pytest.mark.parametrize("profile", PROFILES, ids=lambda p: p.name)
@settings(max_examples=100)
@given(
    pts=points_st, frac=st.floats(0.05, 1.0), taus=st.tuples(st.floats(0, 1.5), st.floats(0, 1.5))
)
def test_the_margin_grows_with_tau(profile, pts, frac, taus):
    """A longer loop delay never allows a faster approach: the margin straight ahead grows,
    and the speed let through towards what lies ahead does not."""
    params = CbfParams.from_profile(profile)
    lo, hi = sorted(taus)
    v = frac * profile.v_max_mps
    a = cbf_filter(v, 0.0, pts, v, 0.0, lo, profile, params)
    b = cbf_filter(v, 0.0, pts, v, 0.0, hi, profile, params)
    assert b.margin_ahead_m >= a.margin_ahead_m
    assert b.braking_s >= a.braking_s
    wall = np.column_stack((np.full(41, 0.8), np.linspace(-1, 1, 41)))
    slow = cbf_filter(v, 0.0, wall, v, 0.0, hi, profile, params)
    fast = cbf_filter(v, 0.0, wall, v, 0.0, lo, profile, params)
    assert slow.v_mps <= fast.v_mps + 1e-12


def test_the_margin_ahead_is_the_delay_and_braking_distance():
    p = CbfParams.from_profile(JACKAL)
    res = cbf_filter(0.8, 0.0, np.array([[5.0, 5.0]]), 0.8, 0.0, 0.4, JACKAL, p)
    # 0.12 m + 0.8 m/s x (0.4 s + one 0.05 s period) + 0.8^2 / (2 x 3 m/s^2)
    assert res.margin_ahead_m == pytest.approx(0.12 + 0.8 * 0.45 + 0.64 / 6.0)


# -- driving at things -----------------------------------------------------------------------


def wall_ahead(distance_m: float, profile: RobotProfile = JACKAL) -> np.ndarray:
    """A wall across the path, ``distance_m`` ahead of the footprint's front."""
    x = 0.5 * profile.length_m + distance_m
    return np.column_stack((np.full(81, x), np.linspace(-2, 2, 81)))


@pytest.mark.parametrize("v", [0.3, 0.5, 0.8, 1.5, 2.0])
def test_a_wall_ahead_is_kept_at_the_margin_plus_delay_and_braking(v):
    p = CbfParams.from_profile(JACKAL)
    tau = 0.25
    stop_m = p.margin_m + v * (tau + p.period_s) + v * v / (2 * JACKAL.decel_max_mps2)
    near = cbf_filter(v, 0.0, wall_ahead(stop_m - 0.01), v, 0.0, tau, JACKAL, p)
    assert near.v_mps <= 0.0 and near.case is CbfCase.SOLVED  # held
    assert near.active and all(c.a < 0.0 for c in near.active)  # by points ahead
    far = cbf_filter(v, 0.0, wall_ahead(stop_m + v / p.alpha_per_s + 0.01), v, 0.0, tau, JACKAL, p)
    assert far.v_mps is not None and far.case is CbfCase.CLEAR


def test_a_wall_beside_the_path_at_the_careful_distance_is_passed():
    """DESIGN 13's careful drives: 0.2 m from a wall at 0.8 m/s, on a perfect link."""
    hw = 0.5 * JACKAL.width_m
    wall = np.column_stack((np.linspace(-3, 3, 301), np.full(301, hw + 0.2)))
    res = cbf_filter(0.8, 0.0, wall, 0.8, 0.0, None, JACKAL, CbfParams.from_profile(JACKAL))
    assert res.case is CbfCase.CLEAR


def test_a_turn_towards_a_close_wall_is_cut_and_a_turn_away_is_not():
    hw = 0.5 * JACKAL.width_m
    wall = np.column_stack((np.linspace(-1, 1, 81), np.full(81, hw + 0.05)))  # inside the margin
    p = CbfParams.from_profile(JACKAL)
    towards = cbf_filter(0.3, 1.0, wall, 0.3, 1.0, None, JACKAL, p)
    assert towards.modified and towards.w_radps < 1.0
    # Turning right swings the rear-left corner towards the wall too: a turn in place is cut,
    # but driving forward while turning right keeps the front corner's gain.
    away = cbf_filter(0.0, -1.0, wall, 0.0, -1.0, None, JACKAL, p)
    assert away.modified  # the rear corner would touch the wall (it is 5 cm away)


def test_what_the_laser_did_not_see_counts_as_an_obstacle_at_its_edge():
    p = CbfParams.from_profile(JACKAL)
    far = [[5.0, 5.0]]
    blind_behind = obstacle_points(far, seen_ahead_m=10.0, seen_behind_m=0.0)
    back = cbf_filter(-0.5, 0.0, blind_behind, -0.5, 0.0, None, JACKAL, p)
    assert back.v_mps >= 0.0 and back.active and back.active[0].unseen
    assert cbf_filter(0.5, 0.0, blind_behind, 0.5, 0.0, None, JACKAL, p).case is CbfCase.CLEAR
    short = obstacle_points(far, seen_ahead_m=0.6, seen_behind_m=0.6)  # a 0.6 m laser
    ahead = cbf_filter(2.0, 0.0, short, 2.0, 0.0, None, JACKAL, p)
    assert 0.0 <= ahead.v_mps < 0.5  # it can stop within what it sees, no faster


def test_no_points_is_unknown_unless_the_sensor_says_free():
    p = CbfParams.from_profile(JACKAL)
    res = cbf_filter(0.5, 0.2, np.empty((0, 2)), 0.5, 0.2, None, JACKAL, p)
    assert (res.v_mps, res.w_radps, res.case) == (0.0, 0.0, CbfCase.NO_POINTS_UNKNOWN)
    free = CbfParams.from_profile(JACKAL, no_return_is_free=True)
    res = cbf_filter(0.5, 0.2, np.empty((0, 2)), 0.5, 0.2, None, JACKAL, free)
    assert (res.v_mps, res.w_radps, res.case) == (0.5, 0.2, CbfCase.NO_POINTS_FREE)


@pytest.mark.parametrize(
    "args",
    [(math.nan, 0.0, 0.0, 0.0, None), (0.1, math.inf, 0.0, 0.0, None), (0.1, 0.0, 0, 1e9, None),
     (0.1, 0.0, 0.0, 0.0, -1.0), (0.1, 0.0, 0.0, 0.0, math.nan)],
)  # fmt: skip
def test_invalid_input_stops(args):
    v, w, v_now, w_now, tau = args
    res = cbf_filter(v, w, [[1.0, 0.0]], v_now, w_now, tau, JACKAL, CbfParams.from_profile(JACKAL))
    assert (res.v_mps, res.w_radps, res.case) == (0.0, 0.0, CbfCase.INVALID_INPUT)


# -- the solver's pieces -----------------------------------------------------------------------


def test_stop_and_turn_keeps_the_rotation_every_row_allows():
    b = np.array([0.2, -0.1, 0.0])
    c = np.array([-0.1, -0.05, 0.0])
    # 0.2 w >= -0.1 -> w >= -0.5; -0.1 w >= -0.05 -> w <= 0.5
    assert _stop_and_turn(b, c, 1.5, JACKAL) == (0.0, 0.5)
    assert _stop_and_turn(b, c, -1.5, JACKAL) == (0.0, -0.5)
    assert _stop_and_turn(b, c, 0.3, JACKAL) == (0.0, 0.3)


@settings(max_examples=200)
@given(
    rows=st.lists(
        st.tuples(st.floats(-2, 2), st.floats(-2, 2), st.floats(-1, 0)), min_size=1, max_size=6
    ),
    cmd=st.tuples(st.floats(-2, 2), st.floats(-2, 2)),
)
def test_the_closed_form_projection_is_the_weighted_nearest_feasible_point(rows, cmd):
    a, b, c = (np.array(col, dtype=np.float64) for col in zip(*rows, strict=True))
    sv, sw = 1.0 / JACKAL.v_max_mps, 1.0 / JACKAL.w_max_radps
    found = _project(a.tolist(), b.tolist(), c.tolist(), *cmd, sv, sw, JACKAL)
    assert found is not None  # c <= 0: the origin is always feasible
    v, w = found
    assert (a * v + b * w - c >= -1e-7).all()
    rng = np.random.default_rng(1)
    vs, ws = rng.uniform(-2, 2, 50_000), rng.uniform(-2, 2, 50_000)
    ok = (a[:, None] * vs + b[:, None] * ws >= c[:, None]).all(axis=0)
    best = (((vs[ok] - cmd[0]) * sv) ** 2 + ((ws[ok] - cmd[1]) * sw) ** 2).min(initial=math.inf)
    assert ((v - cmd[0]) * sv) ** 2 + ((w - cmd[1]) * sw) ** 2 <= best + 1e-9


# -- parameters and the family -----------------------------------------------------------------


def test_defaults_per_profile_and_the_config_table():
    assert CbfParams.from_profile(JACKAL).margin_m == pytest.approx(0.12)
    assert CbfParams.from_profile(PIONEER3DX).margin_m == pytest.approx(0.0363)
    p = CbfParams.from_mapping({"alpha_per_s": 4, "points_considered": 6.0}, JACKAL)
    assert (p.alpha_per_s, p.points_considered, p.margin_m) == (4.0, 6, pytest.approx(0.12))
    with pytest.raises(ValueError, match="unknown keys: alpha"):
        CbfParams.from_mapping({"alpha": 4})
    for bad in ({"alpha_per_s": 0}, {"margin_m": -0.1}, {"weight_w": "1"}, {"points_considered": 0},
                {"tau_s": math.inf}, {"points_considered": 1.5}):  # fmt: skip
        with pytest.raises(ValueError, match="cbf"):
            CbfParams.from_mapping(bad)


def test_the_family_runs_cbf_with_the_robot_state_and_the_loop_delay():
    settings_ = FilterSettings(JACKAL, EgcParams.from_profile(0.5, 2.5, 2.0))
    pts = obstacle_points(wall_ahead(1.0))
    v, w = 0.8, 0.0
    quiet = run_filter("cbf", FilterInput(v, w, pts, RobotState(0.0, 0.0)), settings_)
    assert quiet.v_mps is v and not quiet.modified and quiet.reason == "clear"
    fast = run_filter("cbf", FilterInput(v, w, pts, RobotState(2.0, 0.0)), settings_)
    assert fast.modified and fast.v_mps < v  # the braking distance at the current speed
    slow_link = run_filter("cbf", FilterInput(v, w, pts, loop_delay_s=1.0), settings_)
    assert slow_link.modified and slow_link.v_mps < v
    assert not fast.stopped_near_obstacle  # cbf lets motion away through itself


# -- footprints other than rectangles (DESIGN 14) ------------------------------------------------


def _shapes() -> list[RobotProfile]:
    nose = [[0.4, 0.0], [0.1, 0.3], [-0.3, 0.3], [-0.3, -0.3], [0.1, -0.3]]
    return [TURTLEBOT4, JACKAL.with_overrides(name="pentagon", footprint=Footprint.polygon(nose))]


def approach_fd(fp: Footprint, pts: np.ndarray, v: float, w: float, dt: float = 1e-6):
    """How fast the footprint closes on each point under (v, w), by finite differences of the
    footprint's own signed distance (``egc_common.footprint``), independent of the filter's
    normals and levers."""
    dx, dy, dth = v * dt, 0.0, w * dt  # first order over dt
    c, s = math.cos(dth), math.sin(dth)
    px, py = pts[:, 0] - dx, pts[:, 1] - dy
    moved = np.column_stack((c * px + s * py, -s * px + c * py))
    before = signed_distance(fp, pts[:, 0], pts[:, 1])
    after = signed_distance(fp, moved[:, 0], moved[:, 1])
    return (before - after) / dt, before


@pytest.mark.parametrize("profile", _shapes(), ids=lambda p: p.name)
@settings(max_examples=150)
@given(data=st.data(), pts=near_st, tau=st.floats(0.0, 1.0))
def test_any_footprint_is_never_approached_faster_than_its_barrier_allows(profile, data, pts, tau):
    """The weakest of the rows, approach <= max(alpha max(sd - margin, 0), kappa sd) (the
    creep kappa of points no command can approach fast: module docstring), checked with the
    footprint's own distance function: a disc (turtlebot4) and a pentagon nose first."""
    params = CbfParams.from_profile(profile)
    pts = pts[signed_distance(profile.footprint, pts[:, 0], pts[:, 1]) > 0.01]  # no contact
    assume(len(pts))
    v, w = data.draw(command_st(profile))
    v_now, w_now = data.draw(command_st(profile))
    res = cbf_filter(v, w, pts, v_now, w_now, tau, profile, params)
    u, sd = approach_fd(profile.footprint, pts, res.v_mps, res.w_radps)
    # The fastest approach any command in the box makes (u is linear in (v, w): a corner's).
    v_max, w_max = profile.v_max_mps, profile.w_max_radps
    reach = np.max(
        [approach_fd(profile.footprint, pts, sv * v_max, sw * w_max)[0]
         for sv, sw in itertools.product((-1.0, 1.0), repeat=2)],
        axis=0,
    )  # fmt: skip
    creep = CREEP_PER_S * np.maximum(1.0 - reach / (CREEP_BELOW * v_max), 0.0) * sd
    allowed = np.maximum(params.alpha_per_s * np.maximum(sd - params.margin_m, 0.0), creep)
    assert (u <= allowed + 1e-4).all()
    if (approach_fd(profile.footprint, pts, v, w)[0] <= 0.0).all():
        assert (res.v_mps, res.w_radps) == (v, w)  # moving away from everything: untouched


def test_a_disc_robot_turns_in_place_next_to_a_wall():
    """Turning never moves a disc about its centre towards anything: always allowed."""
    r = TURTLEBOT4.footprint.radius_m
    wall = np.column_stack((np.full(41, r + 0.01), np.linspace(-1, 1, 41)))
    p = CbfParams.from_profile(TURTLEBOT4)
    res = cbf_filter(0.0, 1.5, wall, 0.0, 1.5, None, TURTLEBOT4, p)
    assert (res.v_mps, res.w_radps, res.case) == (0.0, 1.5, CbfCase.CLEAR)
    ahead = cbf_filter(0.3, 0.0, wall, 0.3, 0.0, None, TURTLEBOT4, p)
    assert ahead.v_mps <= 0.0


# -- the shortcuts equal the general path ------------------------------------------------------


@settings(max_examples=300)
@given(
    rows=st.lists(
        st.tuples(
            st.one_of(st.just(0.0), st.floats(-2, 2)),
            st.one_of(st.just(0.0), st.floats(-2, 2)),
            st.floats(-1, 0),
        ),
        min_size=1,
        max_size=8,
    ),
    cmd=st.tuples(st.floats(-2, 2), st.floats(-2, 2)),
)
def test_the_first_projection_is_the_small_qps_answer_when_it_gives_one(rows, cmd):
    """``_first_projection`` (the solver's common case, without building the rows) against
    ``_nearest_in`` on the rows ``_checks`` builds: the same point, to the bit."""
    a, b, c = (list(col) for col in zip(*rows, strict=True))
    sv, sw = 1.0 / JACKAL.v_max_mps, 1.0 / JACKAL.w_max_radps
    isv, isw, z0x, z0y = 1.0 / sv, 1.0 / sw, sv * cmd[0], sw * cmd[1]
    fast = _first_projection(a, b, c, isv, isw, z0x, z0y)
    if fast is not None:
        assert fast == _nearest_in(*_checks(a, b, c, isv, isw, z0x, z0y), z0x, z0y)


def scene_st(profile: RobotProfile):
    """Points near the footprint, a command, a current velocity (often the command) and tau."""
    return st.tuples(near_st, command_st(profile), command_st(profile), st.booleans(),
                     st.floats(0.0, 1.0))  # fmt: skip


def results_equal(a, b) -> bool:
    if (a.v_mps, a.w_radps, a.case, a.considered, a.rounds) != (
        b.v_mps,
        b.w_radps,
        b.case,
        b.considered,
        b.rounds,
    ):
        return False
    ta, tb = a.tight, b.tight
    if (ta is None) != (tb is None):
        return False
    return ta is None or all(
        np.array_equal(getattr(ta, f), getattr(tb, f)) for f in ("x_m", "y_m", "a", "b", "c")
    )


@pytest.mark.parametrize("profile", PROFILES + _shapes(), ids=lambda p: p.name)
@settings(max_examples=150)
@given(data=st.data())
def test_the_clear_test_and_the_creep_bound_change_no_answer(profile, data):
    """The CLEAR test before the rows (``_Scene.rows``' clear_test) and the distance beyond
    which the creep is skipped (``_Scene._creep_bound``): every answer equals the one computed
    without them, to the bit."""
    pts, cmd, now, steady, tau = data.draw(scene_st(profile))
    v_now, w_now = cmd if steady else now
    params = CbfParams.from_profile(profile)
    fast = cbf_filter(*cmd, pts, v_now, w_now, tau, profile, params)
    rows = cbf_module._Scene.rows
    with (
        mock.patch.object(cbf_module._Scene, "rows", lambda s, *a, clear_test=False: rows(s, *a)),
        mock.patch.object(cbf_module._Scene, "_creep_bound", lambda s: math.inf),
    ):
        plain = cbf_filter(*cmd, pts, v_now, w_now, tau, profile, params)
    assert results_equal(fast, plain)
    if fast.case is CbfCase.CLEAR:
        assert fast.v_mps is cmd[0] and fast.w_radps is cmd[1]
