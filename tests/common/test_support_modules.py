"""Kinematics, key expressions, TOML config and the joystick file format."""

from __future__ import annotations

import math

import pytest
from egc_common import keys
from egc_common.config import ConfigError, load, merge, section
from egc_common.joystick_file import (
    JoystickFileError,
    JoystickTrack,
    load_joystick_file,
    parse_joystick_csv,
)
from egc_common.kinematics import body_twist, integrate_arc, wheel_speeds, wrap_angle
from hypothesis import example, given
from hypothesis import strategies as st
from scipy.integrate import solve_ivp


def unicycle_by_ode(pose, v, w, t):
    """An independent reference: the unicycle ODE integrated to a tight tolerance."""
    sol = solve_ivp(
        lambda _, q: (v * math.cos(q[2]), v * math.sin(q[2]), w),
        (0.0, t),
        pose,
        rtol=1e-12,
        atol=1e-12,
    )
    return sol.y[0, -1], sol.y[1, -1]


@given(st.floats(-2, 2), st.floats(-3, 3), st.floats(0, 5))
@example(1.0, 1e-9, 1.0)  # found by hypothesis: the closed form is ill-conditioned here
@example(1.0, 0.0, 5.0)
@example(-2.0, 1e-3, 5.0)
def test_arc_integration_matches_closed_form(v, w, t):
    x, y, th = integrate_arc((1.0, -2.0, 0.3), v, w, t)
    if abs(w) >= 1e-3:
        r = v / w
        ex = 1.0 + r * (math.sin(0.3 + w * t) - math.sin(0.3))
        ey = -2.0 - r * (math.cos(0.3 + w * t) - math.cos(0.3))
        tol = 1e-9
    else:  # the closed form divides by w and cancels catastrophically as w -> 0
        ex, ey = unicycle_by_ode((1.0, -2.0, 0.3), v, w, t)
        tol = 1e-8
    assert (x, y) == pytest.approx((ex, ey), abs=tol)
    assert math.isclose(wrap_angle(th - 0.3 - w * t), 0.0, abs_tol=1e-9)


def test_wheel_speeds_invert_body_twist():
    left, right = wheel_speeds(0.3, 1.0, 0.4)
    assert (left, right) == pytest.approx((0.1, 0.5))
    assert body_twist(left, right, 0.4) == pytest.approx((0.3, 1.0))


def test_key_expressions_are_pinned():
    assert keys.cmd("sim") == "egc/sim/cmd"
    assert keys.telemetry("r1") == "egc/r1/telemetry"
    assert keys.state("r1") == "egc/r1/state"
    assert keys.clock("r1") == "egc/r1/clock"
    assert keys.scan("r1") == "egc/r1/scan"
    assert keys.base_cmd("r1") == "egc/r1/base/cmd"
    assert keys.base_odom("r1") == "egc/r1/base/odom"
    assert keys.alive_robot("r1") == "egc/r1/alive/robot"
    assert keys.alive_operator("r1", "op-7") == "egc/r1/alive/operator/op-7"
    assert keys.operator_id_from_alive_key("egc/r1/alive/operator/op-7") == "op-7"
    assert keys.operator_id_from_alive_key("egc/r1/alive/robot") is None
    for bad in ("a/b", "*", "", "x y", "a" * 65):
        with pytest.raises(ValueError):
            keys.cmd(bad)


def test_config_toml_with_overrides(tmp_path):
    path = tmp_path / "robot.toml"
    path.write_text('[robot]\nrate_hz = 20\nprofile = "jackal"\n')
    cfg = load(path, ["robot.rate_hz=50", "robot.filter=none", "pipeline.horizon_s=2.5"])
    assert cfg["robot"] == {"rate_hz": 50, "profile": "jackal", "filter": "none"}
    assert cfg["pipeline"]["horizon_s"] == 2.5
    with pytest.raises(ConfigError, match="unknown keys: bogus"):
        section({"robot": {"bogus": 1}}, "robot", ["rate_hz"])
    with pytest.raises(ConfigError, match="not found"):
        load(tmp_path / "missing.toml")
    (tmp_path / "bad.toml").write_text("[robot\n")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load(tmp_path / "bad.toml")
    with pytest.raises(ConfigError, match="key=value"):
        merge({}, ["novalue"])


def test_joystick_file_parse_and_hold(tmp_path):
    text = "# demo\nt_s,x,y,deadman,mode,estop\n0.0,0,0,1,shared,0\n0.5,1.0,0.2,1,direct,0\n2.0,0,0,0,shared,1\n"
    track = JoystickTrack(parse_joystick_csv(text))
    assert track.at(0.7).x == 1.0 and track.at(0.7).mode == "direct"
    assert track.at(2.0).estop and not track.at(2.0).deadman
    assert not track.at(5.0).deadman and track.at(5.0).x == 0.0  # released after the end
    minimal = parse_joystick_csv("t_s,x,y\n0,0.1,0.2\n")
    assert minimal[0].deadman and minimal[0].mode == "shared" and not minimal[0].estop
    path = tmp_path / "j.csv"
    path.write_text(text)
    assert len(load_joystick_file(path)) == 3


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", "empty"),
        ("x,y\n0,0\n", "t_s"),
        ("t_s,x,y\n0,2,0\n", "outside"),
        ("t_s,x,y\n1,0,0\n0,0,0\n", "backwards"),
        ("t_s,x,y,mode\n0,0,0,auto\n", "mode"),
        ("t_s,x,y,deadman\n0,0,0,maybe\n", "0 or 1"),
        ("t_s,x,y\n0,nan,0\n", "outside"),
        ("t_s,x,y\n0,0\n", "fields"),
    ],
)
def test_joystick_file_errors_are_clear(text, message):
    with pytest.raises(JoystickFileError, match=message):
        parse_joystick_csv(text)


def test_missing_joystick_file(tmp_path):
    with pytest.raises(JoystickFileError, match="not found"):
        load_joystick_file(tmp_path / "nope.csv")
