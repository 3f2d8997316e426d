"""Latency governor (DESIGN 9): the formula, its limits, and the controller applying it."""

from __future__ import annotations

import math

import pytest
from egc_robot.latency_governor import govern, latency_speed_limit, latency_turn_limit
from egc_robot.link_stats import LinkStats

from tests.robot.test_controller import MS, PROFILE, driving_rig

V_MAX, A_DEC = PROFILE.v_max_mps, PROFILE.decel_max_mps2
W_MAX, ALPHA = PROFILE.w_max_radps, PROFILE.angular_accel_max_radps2


def test_formula_covers_distance_during_tau_plus_braking_exactly_D():
    for tau in (0.0, 0.1, 0.75, 1.35, 3.0):
        for blind in (0.5, 1.0):
            v = latency_speed_limit(tau, V_MAX, A_DEC, blind)
            assert v * tau + v * v / (2 * A_DEC) == pytest.approx(V_MAX * blind, rel=1e-12)


def test_design_examples_for_the_pioneer_in_a_filtered_mode():
    # DESIGN 9: no cap at tau 0.75 s (200 ms links), about 0.7 v_max at tau 1.35 s.
    assert latency_speed_limit(0.75, V_MAX, A_DEC, 1.0) > V_MAX
    assert latency_speed_limit(1.35, V_MAX, A_DEC, 1.0) / V_MAX == pytest.approx(0.69, abs=0.02)


def test_tau_to_zero_leaves_only_the_braking_distance():
    assert latency_speed_limit(0.0, V_MAX, A_DEC, 1.0) == pytest.approx(
        math.sqrt(2 * A_DEC * V_MAX * 1.0)
    )
    assert latency_speed_limit(1e-9, V_MAX, A_DEC, 1.0) > V_MAX  # nothing changes on loopback


def test_cap_falls_monotonically_with_tau_and_tends_to_D_over_tau():
    caps = [latency_speed_limit(t, V_MAX, A_DEC, 1.0) for t in (0.1, 0.5, 1.0, 2.0, 10.0)]
    assert caps == sorted(caps, reverse=True)
    assert latency_speed_limit(1000.0, V_MAX, A_DEC, 1.0) == pytest.approx(V_MAX / 1000, rel=1e-3)


def test_stronger_brakes_allow_more_speed_and_direct_mode_is_stricter():
    assert latency_speed_limit(1.0, V_MAX, 2 * A_DEC, 1.0) > latency_speed_limit(
        1.0, V_MAX, A_DEC, 1.0
    )
    assert latency_speed_limit(1.0, V_MAX, A_DEC, 0.5) < latency_speed_limit(1.0, V_MAX, A_DEC, 1.0)


@pytest.mark.parametrize(
    "args", [(-0.1, V_MAX, A_DEC, 1.0), (math.nan, V_MAX, A_DEC, 1.0), (0.5, V_MAX, 0.0, 1.0)]
)
def test_bad_arguments_raise(args):
    with pytest.raises(ValueError):
        latency_speed_limit(*args)


def test_govern_scales_the_command_as_a_whole():
    v, w, acted = govern(0.14, 0.4, 0.07)
    assert acted and v == pytest.approx(0.07) and w == pytest.approx(0.2)
    assert w / v == pytest.approx(0.4 / 0.14)  # same curvature
    v, w, acted = govern(-0.14, 0.4, 0.07)
    assert acted and v == pytest.approx(-0.07) and w == pytest.approx(0.2)
    assert govern(0.05, 0.5, 0.07) == (0.05, 0.5, False)


def test_unknown_parts_count_as_command_timeout():
    stats = LinkStats(reaction_time_s=0.25, unknown_part_s=0.25)
    assert stats.figures(0).loop_delay_s == pytest.approx(0.75)
    stats.on_arrival(1, 0)
    stats.on_accepted(None, 300, 0)  # unsynchronised operator, view age known
    assert stats.figures(MS).loop_delay_s == pytest.approx(0.25 + 0.3 + 0.25)


def test_controller_caps_direct_mode_at_the_formula_of_its_own_tau():
    rig = driving_rig()
    for _ in range(60):  # direct mode, commands 280 ms old, the view 300 ms old
        rig.send(x=1.0, delay_ms=280, mode="direct", view_age_ms=300)
        out = rig.cycle()
    t = out.telemetry
    tau = t.loop_delay_ms / 1e3
    assert tau == pytest.approx(0.28 + 0.3 + 0.25, abs=0.005)
    v_lim = latency_speed_limit(tau, V_MAX, A_DEC, 0.5)
    assert t.v_lim_latency == pytest.approx(v_lim)
    assert t.limiter == "latency" and out.base.linear_mps == pytest.approx(v_lim)
    assert v_lim < 0.6 * V_MAX


def test_controller_does_not_cap_a_filtered_mode_on_a_200_ms_link():
    rig = driving_rig()
    for _ in range(60):
        rig.send(x=1.0, delay_ms=250, view_age_ms=250)
        out = rig.cycle()
    assert out.telemetry.limiter == "none"
    assert out.base.linear_mps == pytest.approx(V_MAX)
    assert out.telemetry.w_lim_latency is None  # the turn cap lies above w_max: not reported


def test_controller_caps_a_filtered_mode_on_a_500_ms_link():
    rig = driving_rig()
    for _ in range(60):
        rig.send(x=1.0, delay_ms=600, view_age_ms=600)
        out = rig.cycle()
    assert out.telemetry.limiter == "latency"
    assert 0.5 * V_MAX < out.base.linear_mps < 0.75 * V_MAX


def test_link_aware_off_has_no_governor():
    rig = driving_rig(link_aware=False)
    for _ in range(30):
        rig.send(x=1.0, delay_ms=280, mode="direct", view_age_ms=2000)
        out = rig.cycle()
    assert out.telemetry.v_lim_latency is None
    assert out.base.linear_mps == pytest.approx(V_MAX)


def test_turn_limit_covers_the_angle_turned_during_tau_plus_stopping_exactly_theta():
    for tau in (0.0, 0.1, 0.75, 1.35, 3.0):
        for blind in (0.5, 1.0):
            w = latency_turn_limit(tau, W_MAX, ALPHA, blind)
            assert w * tau + w * w / (2 * ALPHA) == pytest.approx(W_MAX * blind, rel=1e-12)


@pytest.mark.parametrize("blind", [0.5, 1.0])
def test_a_cap_is_off_exactly_when_blind_time_covers_tau_plus_half_the_stopping_time(blind):
    # v_lim >= v_max  <=>  blind_time >= tau + v_max / (2 a_dec); the same for the turn rate.
    for rate, decel, limit in (
        (V_MAX, A_DEC, latency_speed_limit),
        (W_MAX, ALPHA, latency_turn_limit),
    ):
        edge = blind - rate / (2 * decel)
        assert limit(edge - 0.01, rate, decel, blind) > rate
        assert limit(edge + 0.01, rate, decel, blind) < rate


def test_turn_cap_keeps_design_9_examples_for_the_pioneer_in_a_filtered_mode():
    assert latency_turn_limit(0.75, W_MAX, ALPHA, 1.0) > W_MAX  # no cap on 200 ms links
    assert 0.6 < latency_turn_limit(1.35, W_MAX, ALPHA, 1.0) / W_MAX < 0.75


@pytest.mark.parametrize(
    "args", [(-0.1, W_MAX, ALPHA, 1.0), (0.5, math.inf, ALPHA, 1.0), (0.5, W_MAX, 0.0, 1.0)]
)
def test_bad_turn_arguments_raise_naming_them(args):
    with pytest.raises(ValueError, match=r"tau_s|w_max_radps|alpha_dec_radps2"):
        latency_turn_limit(*args)


def test_govern_scales_by_the_tighter_cap_and_keeps_the_curvature():
    v, w, acted = govern(0.14, 0.5, 0.10, 0.25)  # speed wants 0.71, turn 0.5: turn wins
    assert acted and w == pytest.approx(0.25) and v == pytest.approx(0.07)
    v, w, acted = govern(0.14, -0.1, 0.07, 0.25)  # speed wins
    assert acted and v == pytest.approx(0.07) and w == pytest.approx(-0.05)
    v, w, acted = govern(0.0, -0.5, 0.07, 0.25)  # a turn in place: only the turn cap acts
    assert acted and (v, w) == (0.0, pytest.approx(-0.25))
    assert govern(0.05, 0.2, 0.07, 0.25) == (0.05, 0.2, False)


def test_controller_caps_a_turn_in_place_in_direct_mode_at_its_own_tau():
    rig = driving_rig()
    for _ in range(60):
        rig.send(x=0.0, y=1.0, delay_ms=280, mode="direct", view_age_ms=300)
        out = rig.cycle()
    t = out.telemetry
    tau = t.loop_delay_ms / 1e3
    w_lim = latency_turn_limit(tau, W_MAX, ALPHA, 0.5)
    assert t.w_lim_latency == pytest.approx(w_lim) and w_lim < 0.6 * W_MAX
    assert t.limiter == "latency"
    assert out.base.linear_mps == 0.0 and out.base.angular_radps == pytest.approx(w_lim)


def test_latency_turn_cap_off_leaves_the_turn_rate_alone():
    rig = driving_rig(latency_turn_cap=False)
    for _ in range(60):
        rig.send(x=0.0, y=1.0, delay_ms=280, mode="direct", view_age_ms=300)
        out = rig.cycle()
    assert out.telemetry.w_lim_latency is None and out.telemetry.v_lim_latency is not None
    assert out.base.angular_radps == pytest.approx(W_MAX)
