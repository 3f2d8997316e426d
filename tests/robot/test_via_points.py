"""Via points on the robot (DESIGN 7 goal, issue 11): the pure route and the controller's rules."""

from __future__ import annotations

import math

import msgpack
import pytest
from egc_common.messages import GoalMessage, Odometry, decode_goal
from egc_robot.via_points import NO_ROUTE, ViaPoints, advance, to_robot_frame

from tests.robot.test_controller import Rig


def goal_payload(seq: int, points: list[list[float]], op: str = "alice", **kw: object) -> bytes:
    msg = {"v": 1, "seq": seq, "stamp_ns": 0, "op": op, "frame": "odom", "points": points}
    msg |= kw
    return msgpack.packb(msg)


def odom(rig: Rig, x: float, y: float, theta: float = 0.0, map_pose: bool = False) -> None:
    rig.c.on_odometry(
        Odometry(rig.now, x, y, theta, 0.0, 0.0, map_pose=(x, y, theta) if map_pose else None)
    )


def in_control(rig: Rig) -> None:
    rig.send(0.0, 0.0)
    rig.cycle()
    assert rig.c.operator == "alice"


# -- the pure route ---------------------------------------------------------------------------


def test_to_robot_frame_rotates_and_translates() -> None:
    assert to_robot_frame((1.0, 0.0), (0.0, 0.0, 0.0)) == pytest.approx((1.0, 0.0))
    # robot at (1, 1) facing +y: a point at (1, 3) is 2 m ahead, (0, 1) is 1 m to its left
    assert to_robot_frame((1.0, 3.0), (1.0, 1.0, math.pi / 2)) == pytest.approx((2.0, 0.0))
    assert to_robot_frame((0.0, 1.0), (1.0, 1.0, math.pi / 2)) == pytest.approx((0.0, 1.0))


def test_advance_moves_past_reached_points_in_order_only() -> None:
    route = ViaPoints("odom", ((1.0, 0.0), (2.0, 0.0), (5.0, 0.0)))
    assert advance(route, (0.0, 0.0, 0.0), 0.3) is route
    # at the second point but the first is not reached: order is the operator's
    assert advance(route, (2.0, 0.0, 0.0), 0.3).index == 0
    after = advance(route, (1.1, 0.0, 0.0), 0.3)
    assert after.index == 1 and after.active == (2.0, 0.0) and after.remaining_after_active == 1
    done = advance(ViaPoints("odom", ((1.0, 0.0),)), (1.0, 0.1, 0.0), 0.3)
    assert done.active is None and done.remaining_after_active == 0
    assert advance(route, None, 0.3) is route


# -- the wire ---------------------------------------------------------------------------------


def test_goal_message_round_trip_and_rejections() -> None:
    msg = GoalMessage(3, 10, "alice", "map", ((1.0, -2.5), (3.0, 4.0)))
    decoded = decode_goal(msg.encode())
    assert decoded == msg
    for bad in (
        goal_payload(1, [[1.0]]),  # not [x, y]
        goal_payload(1, [[1.0, float("nan")]]),
        goal_payload(1, [[1.0, 2.0]] * 65),  # too many
        goal_payload(1, [[1.0, 2.0]], frame="gps"),
        goal_payload(1, "1,2"),  # type: ignore[arg-type]
        b"\xc1garbage",
    ):
        assert not isinstance(decode_goal(bad), GoalMessage)


# -- the controller ---------------------------------------------------------------------------


def test_goal_from_operator_in_control_becomes_active_in_robot_frame() -> None:
    rig = Rig()
    in_control(rig)
    odom(rig, 1.0, 1.0, math.pi / 2)
    assert rig.c.on_goal(goal_payload(1, [[1.0, 3.0], [4.0, 4.0]]), rig.now) is None
    assert rig.c.route.active == (1.0, 3.0)
    assert rig.c._goal_in_robot_frame() == pytest.approx((2.0, 0.0))
    tel = rig.cycle().telemetry
    assert tel.goal == (1.0, 3.0) and tel.goal_frame == "odom" and tel.goals_left == 1


def test_robot_advances_to_the_next_via_point_and_ends_without_one() -> None:
    rig = Rig()
    in_control(rig)
    odom(rig, 0.0, 0.0)
    rig.c.on_goal(goal_payload(1, [[1.0, 0.0], [2.0, 0.0]]), rig.now)
    odom(rig, 0.85, 0.0)
    assert rig.c.route.active == (2.0, 0.0)
    odom(rig, 1.9, 0.05)
    tel = rig.cycle().telemetry
    assert tel.goal is None and tel.goals_left == 0


def test_goal_from_an_operator_not_in_control_is_rejected_and_counted() -> None:
    rig = Rig()
    in_control(rig)
    odom(rig, 0.0, 0.0)
    before = rig.c.counters.rejected_total
    rejection = rig.c.on_goal(goal_payload(1, [[1.0, 0.0]], op="mallory"), rig.now)
    assert rejection is not None and rejection.reason.value == "not_in_control"
    assert rig.c.route is NO_ROUTE
    assert rig.c.counters.rejected_total == before + 1
    # nobody in control: nobody may set via points
    fresh = Rig()
    assert fresh.c.on_goal(goal_payload(1, [[1.0, 0.0]]), fresh.now) is not None


def test_malformed_goal_is_rejected_counted_and_never_raises() -> None:
    rig = Rig()
    in_control(rig)
    odom(rig, 0.0, 0.0)
    for payload in (b"", b"\x00" * 5000, goal_payload(1, [[1e9, 0.0]]), 42, None):
        assert rig.c.on_goal(payload, rig.now) is not None
    assert rig.c.counters.rejected["goal_too_large"] == 1
    assert rig.c.route is NO_ROUTE


def test_seq_must_increase_but_a_repeated_route_keeps_its_progress() -> None:
    rig = Rig()
    in_control(rig)
    odom(rig, 0.0, 0.0)
    route = [[1.0, 0.0], [2.0, 0.0]]
    rig.c.on_goal(goal_payload(5, route), rig.now)
    assert rig.c.on_goal(goal_payload(5, [[9.0, 9.0]]), rig.now) is not None  # same seq
    odom(rig, 1.0, 0.0)
    assert rig.c.route.index == 1
    assert rig.c.on_goal(goal_payload(6, route), rig.now) is None  # the 1 Hz repeat
    assert rig.c.route.index == 1
    rig.c.on_goal(goal_payload(7, []), rig.now)  # an empty list clears
    assert rig.c.route.active is None and rig.c.route.points == ()


def test_map_frame_needs_a_map_pose_from_the_driver() -> None:
    rig = Rig()
    in_control(rig)
    odom(rig, 0.0, 0.0)  # odometry only
    rejection = rig.c.on_goal(goal_payload(1, [[1.0, 0.0]], frame="map"), rig.now)
    assert rejection is not None and "map" in rejection.detail
    odom(rig, 0.0, 0.0, map_pose=True)
    assert rig.c.on_goal(goal_payload(2, [[1.0, 0.0]], frame="map"), rig.now) is None


def test_losing_the_operator_clears_its_via_points() -> None:
    rig = Rig()
    rig.c.on_operator_alive("alice", True)
    in_control(rig)
    odom(rig, 0.0, 0.0)
    rig.c.on_goal(goal_payload(1, [[3.0, 0.0]]), rig.now)
    rig.c.on_operator_alive("alice", False)
    assert rig.c.route is NO_ROUTE
