"""Which robot a fleet operator drives (DESIGN 15): typed commands, the listing, the cycle,
the fleet rows, and the shared source's switch buttons, release and gate (pure parts)."""

from __future__ import annotations

import pytest
from egc_common.joystick_file import RELEASED, JoystickSample, JoystickTrack, parse_joystick_csv
from egc_common.messages import StateMessage
from egc_common.robot_info import RobotInfo
from egc_operator.command_source import TrackSource
from egc_operator.fleet_choice import (
    Help,
    ListRobots,
    Pick,
    Step,
    TypedError,
    cycled,
    listing,
    parse_typed,
    resolve,
)
from egc_operator.fleet_source import FleetSource
from egc_operator.fleet_table import fleet_markdown, fleet_rows, on_shared_map, others_text

MS = 1_000_000
S = 1_000_000_000


@pytest.mark.parametrize(
    ("line", "parsed"),
    [
        ("robot r2\n", Pick("r2")),
        ("robot 2", Pick("2")),
        ("  r3 ", Pick("r3")),
        ("3", Pick("3")),
        ("next", Step(+1)),
        ("N", Step(+1)),
        ("prev", Step(-1)),
        ("previous", Step(-1)),
        ("list", ListRobots()),
        ("?", Help()),
        ("", None),
        ("   \n", None),
    ],
)
def test_typed_lines(line: str, parsed: object) -> None:
    assert parse_typed(line) == parsed


@pytest.mark.parametrize("line", ["robot", "robot a b", "go to r2"])
def test_typed_nonsense_says_what_is_accepted(line: str) -> None:
    result = parse_typed(line)
    assert isinstance(result, TypedError) and "robot" in result.text


def test_resolve_by_name_or_listing_number() -> None:
    robots = ["ra", "rb", "rc"]
    assert resolve(robots, "rb") == "rb"
    assert resolve(robots, "3") == "rc"
    for bad, why in (("4", "1 to 3"), ("0", "1 to 3"), ("rz", "robots: ra, rb, rc")):
        result = resolve(robots, bad)
        assert isinstance(result, TypedError) and why in result.text, result
    assert isinstance(resolve([], "1"), TypedError)


def test_cycling_wraps_and_counts_a_departed_robot_where_it_would_sort() -> None:
    robots = ["rc", "ra", "rb"]  # any order in, sorted ids out
    assert cycled(robots, "ra", +1) == "rb"
    assert cycled(robots, "rc", +1) == "ra"
    assert cycled(robots, "ra", -1) == "rc"
    assert cycled(robots, None, +1) == "ra" and cycled(robots, None, -1) == "rc"
    assert cycled(["ra", "rc"], "rb", +1) == "rc"  # rb left the listing
    assert cycled(["ra", "rc"], "rb", -1) == "ra"
    assert cycled(["ra"], "ra", +1) is None  # nowhere else to go
    assert cycled([], "ra", +1) is None


def info(robot: str, state: str = "IDLE", map_id: str | None = "grid:1") -> RobotInfo:
    return RobotInfo(robot, state, "sim", "pioneer3dx", "egc", "none", "0.1", map=map_id)


def test_listing_numbers_and_marks_the_driven_robot() -> None:
    lines = listing([("ra", info("ra")), ("rb", None)], "ra", {"ra": "DRIVING"})
    assert lines[0].startswith("*1) ra  DRIVING  pioneer3dx")  # the state message wins
    assert lines[1] == " 2) rb  ?  (no info reply yet)"


def test_fleet_rows_texts_and_the_shared_map() -> None:
    now = 100 * S
    states = {
        "ra": (StateMessage(1, "DRIVING", "fresh", "me", map_pose=(1.0, 2.0, 0.0)), now - 1),
        "rb": (StateMessage(1, "HOLD", "deadman released", "bob", map_pose=(3.0, 4.0, 0.0)), now),
        "rc": (StateMessage(1, "IDLE", "no operator", None, map_pose=(5.0, 6.0, 0.0)), now),
        "rd": (StateMessage(1, "IDLE", "no operator", None, map_pose=(7.0, 8.0, 0.0)), 90 * S),
    }
    infos = {
        "ra": info("ra"),
        "rb": info("rb"),
        "rc": info("rc", map_id="grid:2"),  # another world
        "rd": info("rd"),
    }
    rows = fleet_rows(["ra", "rb", "rc", "rd"], infos, states, {"rb": 2.5}, "ra", now)
    assert [r.driven for r in rows] == [True, False, False, False]
    assert rows[1].rtt_ms == 2.5 and rows[0].rtt_ms is None
    assert rows[3].stale  # its state is 10 s old
    assert others_text(rows, "me") == "rb HOLD (bob), rc IDLE, rd IDLE? (silent 10 s)"
    # the driven robot and those in its map frame with a current pose; not rc (another map)
    # and not rd (its pose is 10 s old)
    assert [r.robot for r in on_shared_map(rows)] == ["ra", "rb"]
    table = fleet_markdown(rows, "me")
    assert "**ra (driven)**" in table and "this operator" in table and "| bob |" in table
    assert "2.5 ms" in table
    # a driven robot in no known map frame draws nobody as if they shared one
    unknown = fleet_rows(["ra", "rb"], {"ra": info("ra", map_id=None)}, states, {}, "ra", now)
    assert on_shared_map(unknown) == []
    assert others_text(fleet_rows(["ra"], {}, {}, {}, "ra", now), "me") == "no other robot"


# -- the shared source ---------------------------------------------------------------------------


class Clock:
    def __init__(self) -> None:
        self.now = 1000 * S

    def __call__(self) -> int:
        return self.now


def track(text: str) -> TrackSource:
    return TrackSource(JoystickTrack(parse_joystick_csv(text)))


def test_one_time_line_across_nodes_and_the_press_edge_releases_the_old_node() -> None:
    clock = Clock()
    presses: list[tuple[int, int]] = []
    fleet = FleetSource(
        track("t_s,x,y,robot_next,robot_prev\n0,0.5,0,0,0\n1,0.5,0,1,0\n1.2,0.5,0,0,0\n"
              "2,0.5,0,0,1\n2.1,0.5,0,0,0\n9,0,0,0,0\n"),
        clock,
        lambda step, press: presses.append((step, press)) or True,
    )  # fmt: skip
    first = fleet.node_source()
    assert first.sample(0.0).x == 0.5  # the session's time 0
    clock.now += 1050 * MS  # sampled 50 ms after the press row
    s = first.sample(123.0)  # the node's own time is ignored
    assert s == RELEASED  # the press's own sample lets go
    assert presses == [(+1, 1000 * S + 1000 * MS)]  # at the row's time, exactly
    clock.now += 20 * MS
    assert first.sample(0.0) == RELEASED  # released for good
    second = fleet.node_source()
    assert second.sample(0.0).x == 0.5  # the button still held: no second press
    clock.now = 1000 * S + 2050 * MS
    assert second.sample(0.0) == RELEASED and presses[-1] == (-1, 1000 * S + 2000 * MS)


def test_a_press_with_nowhere_to_go_keeps_driving() -> None:
    clock = Clock()
    fleet = FleetSource(track("t_s,x,y,robot_next\n0,0.5,0,1\n"), clock, lambda *_: False)
    node = fleet.node_source()
    s = node.sample(0.0)
    assert s.deadman and s.x == 0.5 and not node.released


def test_the_gate_keeps_a_new_node_released_and_the_time_line_waits_for_it() -> None:
    clock = Clock()
    open_ = [False]
    fleet = FleetSource(track("t_s,x,y\n0,0.2,0\n1,0.4,0\n"), clock)
    node = fleet.node_source(gate=lambda: open_[0])
    assert node.holding_back()  # its node sends nothing meanwhile
    assert node.sample(0.0) == RELEASED and not fleet.started
    clock.now += 5 * S
    open_[0] = True
    assert not node.holding_back()
    assert node.sample(0.0).x == 0.2  # time 0 is the first sample let through
    node.release()
    assert node.sample(0.0) == RELEASED and not node.holding_back()  # the release is sent


def test_a_file_columns_robot_next_and_robot_prev() -> None:
    samples = parse_joystick_csv("t_s,x,y,robot_next,robot_prev\n0,0,0,1,0\n1,0,0,0,1\n")
    assert [(s.robot_next, s.robot_prev) for s in samples] == [(True, False), (False, True)]
    assert JoystickSample(0.0, 0.0, 0.0).robot_next is False
    with pytest.raises(ValueError, match="robot_next"):
        parse_joystick_csv("t_s,x,y,robot_next\n0,0,0,maybe\n")
