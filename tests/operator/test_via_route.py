"""The operator's via points, pure (``egc_operator.via_route``), and their CLI options."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from egc_common.cli_args import CliArgumentParser
from egc_common.messages import MAX_GOAL_POINTS, GoalMessage, decode_goal
from egc_operator import cli
from egc_operator.via_route import (
    REPUBLISH_NS,
    Route,
    RouteError,
    RoutePlanner,
    active_index,
    after_clear,
    after_next,
    load_route_file,
    parse_goals,
    parse_point,
    parse_route_text,
    route_from_options,
)

S = 1_000_000_000


def parse(*argv: str):
    parser = CliArgumentParser(prog="egc-teleop operator")
    cli.configure(parser)
    return parser.parse_args(["--script", "demo", *argv])


# -- parsing ---------------------------------------------------------------------------------


def test_points_with_negative_numbers_and_spaces():
    assert parse_point("-2,3") == (-2.0, 3.0)
    assert parse_point(" -1.5e0 , -.5 ") == (-1.5, -0.5)
    assert parse_point("4 -1", spaces=True) == (4.0, -1.0)
    assert parse_point("4,\t-1", spaces=True) == (4.0, -1.0)
    for bad in ("1", "1,2,3", "a,1", "1,", "nan,0", "inf,1", "1e9,0"):
        with pytest.raises(ValueError):
            parse_point(bad)


def test_goal_options_keep_their_order_and_negative_values_parse():
    args = parse("--goal", "-2,3", "--goal", "4.5,-1", "--goal", "-0.5,-0.5")
    assert args.goal == ["-2,3", "4.5,-1", "-0.5,-0.5"]
    assert args.goal_frame == "odom"
    route = route_from_options(args.goal, args.route, args.goal_frame)
    assert route == Route("odom", ((-2.0, 3.0), (4.5, -1.0), (-0.5, -0.5)))
    assert parse("--goal-frame", "map").goal_frame == "map"


def test_a_bad_goal_is_one_line_naming_the_option():
    with pytest.raises(RouteError, match=r"^--goal: expected two numbers, got '1,x'$"):
        parse_goals(["1,2", "1,x"])


def test_route_file_comments_blank_lines_and_both_separators(tmp_path: Path):
    path = tmp_path / "route.txt"
    path.write_text("# office route\n\n1,2\n  -3.5 4   # the door\n5.0, -6\n")
    assert load_route_file(path) == ((1.0, 2.0), (-3.5, 4.0), (5.0, -6.0))


def test_route_file_errors_name_file_and_line(tmp_path: Path):
    with pytest.raises(RouteError, match=r"^r.txt:3: expected 'x,y' or 'x y', got '1,2,3'$"):
        parse_route_text("1,2\n# ok\n1,2,3\n", "r.txt")
    with pytest.raises(RouteError, match=r"^r.txt:2: expected two numbers"):
        parse_route_text("1 2\nleft 3\n", "r.txt")
    with pytest.raises(RouteError, match="no via points"):
        parse_route_text("# nothing\n\n", "r.txt")
    too_many = "\n".join(f"{i},0" for i in range(MAX_GOAL_POINTS + 1))
    with pytest.raises(RouteError, match=rf"r.txt:{MAX_GOAL_POINTS + 1}: more than 64"):
        parse_route_text(too_many, "r.txt")
    assert len(parse_route_text("\n".join(f"{i},0" for i in range(MAX_GOAL_POINTS)))) == 64
    with pytest.raises(RouteError, match="route file not found"):
        load_route_file(tmp_path / "missing.txt")


def test_goal_and_route_together_are_refused_and_frame_is_checked(tmp_path: Path):
    path = tmp_path / "r.txt"
    path.write_text("1,1\n")
    with pytest.raises(RouteError, match="not both"):
        route_from_options(["1,2"], str(path), "odom")
    with pytest.raises(RouteError, match="frame must be one of odom, map"):
        Route("base_link", ())
    with pytest.raises(RouteError, match="at most 64"):
        route_from_options([f"{i},0" for i in range(65)], None, "odom")
    assert route_from_options([], None, "odom") == Route()


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--goal", "1;2"], "--goal: expected X,Y, got '1;2'"),
        (["--route", "missing-route.txt"], "route file not found: missing-route.txt"),
        (["--filter", "none"], "--filter none: 'none' is direct mode"),
        (["--goal-frame", "world"], "invalid choice: 'world'"),
        (["--filter", "EGC"], "invalid choice: 'EGC'"),
    ],
)
def test_bad_values_exit_2_with_one_line(tmp_path: Path, argv: list[str], message: str):
    result = subprocess.run(
        [sys.executable, "-m", "egc_app.cli", "operator", "--script", "demo", "--no-view", *argv],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=60,
    )
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], result.stderr


# -- next / clear ------------------------------------------------------------------------------

ROUTE = Route("odom", ((1.0, 0.0), (2.0, 0.0), (3.0, 1.0)))


def test_the_active_point_is_found_from_the_robots_echo():
    assert active_index(ROUTE, (1.0, 0.0), "odom", 2) == 0
    assert active_index(ROUTE, (2.0, 0.0), "odom", 1) == 1
    assert active_index(ROUTE, (3.0, 1.0), "odom", 0) == 2
    assert active_index(ROUTE, None, None, 0) is None  # done, or not accepted yet
    assert active_index(ROUTE, (2.0, 0.0), "map", 1) is None  # another frame
    assert active_index(ROUTE, (2.0, 0.0), "odom", 2) is None  # not this route's echo
    assert active_index(ROUTE, (9.0, 9.0), "odom", 7) is None


def test_next_drops_the_active_point_and_those_before_it():
    assert after_next(ROUTE, (1.0, 0.0), "odom", 2).points == ((2.0, 0.0), (3.0, 1.0))
    assert after_next(ROUTE, (2.0, 0.0), "odom", 1).points == ((3.0, 1.0),)
    assert after_next(ROUTE, (3.0, 1.0), "odom", 0) == Route("odom", ())
    # nothing active: nothing to skip (a changed route would start again at its first point)
    assert after_next(ROUTE, None, None, 0) is ROUTE
    assert after_clear(ROUTE) == Route("odom", ())
    assert after_clear(Route("map", ((1.0, 1.0),))).frame == "map"


# -- the planner: when to send, and seq ----------------------------------------------------------


def test_planner_sends_when_the_robot_is_seen_then_every_second():
    planner = RoutePlanner(ROUTE)
    assert not planner.due(0, robot_present=False)
    assert planner.due(5, robot_present=True)
    first = planner.message("op1", 123, 5)
    assert isinstance(decode_goal(first.encode()), GoalMessage)
    assert (first.seq, first.op, first.frame, first.points) == (1, "op1", "odom", ROUTE.points)
    assert not planner.due(5 + REPUBLISH_NS - 1, True)
    assert planner.due(5 + REPUBLISH_NS, True)
    second = planner.message("op1", 124, 5 + REPUBLISH_NS)
    assert second.seq == 2 and second.points == first.points  # the same route: progress kept


def test_planner_sends_at_once_after_next_and_clear_with_increasing_seq():
    planner = RoutePlanner(ROUTE)
    seqs = [planner.message("op", 0, 0).seq]
    assert not planner.next(None, None, 0)  # nothing active: nothing changes, nothing due
    assert not planner.due(1, True)
    assert planner.next((1.0, 0.0), "odom", 2)
    assert planner.due(1, True)
    msg = planner.message("op", 0, 1)
    seqs.append(msg.seq)
    assert msg.points == ((2.0, 0.0), (3.0, 1.0))
    planner.clear()
    assert planner.due(2, True)
    msg = planner.message("op", 0, 2)
    seqs.append(msg.seq)
    assert msg.points == () and isinstance(decode_goal(msg.encode()), GoalMessage)
    assert seqs == [1, 2, 3]


def test_taking_control_sends_at_once():
    planner = RoutePlanner(ROUTE)
    planner.message("op", 0, 0)
    assert not planner.due(REPUBLISH_NS // 2, True)
    planner.resend()
    assert planner.due(REPUBLISH_NS // 2, True)
    assert not RoutePlanner().due(0, True)  # no route: still nothing to send


def test_an_operator_without_a_route_sends_nothing_until_it_acts():
    planner = RoutePlanner()
    assert not planner.engaged and not planner.due(10 * S, True)
    planner.clear()  # clearing the robot's via points is an act
    assert planner.due(10 * S, True)
    assert planner.message("op", 0, 10 * S).points == ()
