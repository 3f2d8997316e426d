"""Scripted operators: forward, the naive goal operator and joystick-file replay."""

from __future__ import annotations

import math

import pytest
from egc_common.joystick_file import JoystickFileError
from egc_sim.operators import ForwardOperator, GoalOperator, ReplayOperator, Stick, make_operator


def test_forward_holds_the_stick_forward():
    assert ForwardOperator().command(12.0, (1.0, 2.0, 3.0)) == Stick(1.0, 0.0, True, "shared")
    assert ForwardOperator("direct", 0.5).command(0.0, (0.0, 0.0, 0.0)) == Stick(
        0.5, 0.0, True, "direct"
    )


@pytest.mark.parametrize(
    ("yaw", "x_o", "y_o"),
    [
        (0.0, 1.0, 0.0),  # goal straight ahead
        (-math.pi / 4, math.cos(math.pi / 4), 0.5),  # goal 45 deg to the left: half stick left
        (-math.pi / 2, 0.0, 1.0),  # goal abeam on the left: full turn, no forward
        (math.pi / 2, 0.0, -1.0),  # abeam on the right
        (math.pi, 0.0, 1.0),  # behind (error +pi): turn in place
    ],
)
def test_goal_operator_steers_at_the_goal(yaw, x_o, y_o):
    stick = GoalOperator((5.0, 0.0), "direct").command(0.0, (0.0, 0.0, yaw))
    assert (stick.x_o, stick.y_o) == pytest.approx((x_o, y_o), abs=1e-12)
    assert stick.deadman and stick.mode == "direct" and not stick.estop


def test_replay_plays_the_file_with_zero_order_hold(tmp_path):
    path = tmp_path / "drive.csv"
    path.write_text(
        "# a recorded session\nt_s,x,y,deadman,mode,estop\n"
        "0.0,0.0,0.0,1,shared,0\n0.5,1.0,0.2,1,direct,0\n2.0,0.3,-0.4,0,shared,1\n"
    )
    op = make_operator(str(path), None, "shared")
    assert isinstance(op, ReplayOperator)
    pose = (0.0, 0.0, 0.0)
    assert op.command(0.2, pose) == Stick(0.0, 0.0, True, "shared", False)
    assert op.command(1.9, pose) == Stick(1.0, 0.2, True, "direct", False)
    assert op.command(2.0, pose) == Stick(0.3, -0.4, False, "shared", True)
    assert op.command(2.1, pose) == Stick(0.0, 0.0, False, "shared", False)  # after the end


def test_make_operator_errors(tmp_path):
    assert isinstance(make_operator("goal", (1.0, 1.0), "shared"), GoalOperator)
    with pytest.raises(ValueError, match="needs a goal"):
        make_operator("goal", None, "shared")
    with pytest.raises(JoystickFileError, match="neither forward, goal nor a joystick file"):
        make_operator(str(tmp_path / "missing.csv"), None, "shared")
    with pytest.raises(ValueError, match="mode"):
        ForwardOperator("auto")
