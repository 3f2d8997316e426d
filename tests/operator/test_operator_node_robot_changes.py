"""The operator node over a slow link and across robot restarts (outside check of the view).

- The map query gave up after 1 s, in the clock-sync thread: at 400 ms one way and more the
  operator never got the robot's map (issue 12 drives at 500 ms +- 100 ms).
- A robot that went away (liveliness withdrawn) or came back kept its old state and figures on
  the status line: 'DRIVING ... in control' of the old robot for ~0.4 s after a restart, its
  rtt and command ages for 0.6 s after it was killed.
"""

from __future__ import annotations

import threading
import time
from typing import Any

import numpy as np
import zenoh
from egc_common import keys
from egc_common.messages import MapMessage, OperatorCommand, StateMessage, encode_clock_reply
from egc_operator.operator_node import OperatorNode
from egc_operator.status_line import format_status, situation

from tests.operator.test_operator_node import HOUR, RecordingView, Stick, robot_clock, wait_for
from tests.view.conftest import telemetry

ROBOT = "changes"
MAP_DELAY_S = 1.3  # a 500 ms +- 100 ms each-way link's round trip, and then some


class MapView(RecordingView):
    def __init__(self) -> None:
        super().__init__()
        self.maps: list[tuple[Any, ...]] = []

    def set_world(self, occupancy: Any, resolution_m: float, origin: Any, goal: Any = None) -> None:
        with self.lock:
            self.maps.append((np.asarray(occupancy).shape, resolution_m, origin, goal))


def _clock_queryable(session: zenoh.Session) -> Any:
    def on_clock(query: zenoh.Query) -> None:
        query.reply(keys.clock(ROBOT), encode_clock_reply(robot_clock()))

    return session.declare_queryable(keys.clock(ROBOT), on_clock)


def test_the_map_arrives_over_a_slow_round_trip(session: zenoh.Session) -> None:
    world = MapMessage(1, 0.05, -1.0, -2.0, np.eye(40, dtype=bool), goal=(3.0, 1.0))
    replies: list[threading.Timer] = []
    published: list[int] = []  # the node's command count when asked and when answered

    def on_map(query: zenoh.Query) -> None:
        published.append(node.published)

        # answer as a slow link would: after a 1.3 s round trip (the query is kept till then)
        def answer(q: zenoh.Query = query) -> None:
            published.append(node.published)
            q.reply(keys.world_map(ROBOT), world.encode())
            q.drop()

        timer = threading.Timer(MAP_DELAY_S, answer)
        replies.append(timer)
        timer.start()

    entities = [
        _clock_queryable(session),
        session.declare_queryable(keys.world_map(ROBOT), on_map),
        session.liveliness().declare_token(keys.alive_robot(ROBOT)),
    ]
    view = MapView()
    node = OperatorNode(session, ROBOT, "op1", Stick(), view=view)
    stop = threading.Event()
    runner = threading.Thread(target=node.run, args=(stop,))
    started = time.monotonic()
    runner.start()
    try:
        wait_for(lambda: bool(view.maps), 10.0)
        took = time.monotonic() - started
    finally:
        stop.set()
        runner.join(timeout=10)
        node.close()
        for timer in replies:
            timer.cancel()
        for entity in entities:
            entity.undeclare()
    assert view.maps == [((40, 40), 0.05, (-1.0, -2.0), (3.0, 1.0))]
    # the first query's answer, not a second query's: that would come after the node's map
    # timeout (6 s) and another round trip
    assert MAP_DELAY_S <= took < MAP_DELAY_S + 4.0
    # the commands went on while the query was pending (65 at 50 Hz): it blocks neither. A node
    # that waited for the answer sends none meanwhile; one starved by a busy machine still sends
    # some (8 in CI run 35, at load 10), so the bar is a few, not a rate.
    asked, answered = published[:2]
    assert answered - asked >= 4, published


def test_a_robot_that_goes_and_comes_back_leaves_none_of_its_old_state(
    session: zenoh.Session,
) -> None:
    entities = [_clock_queryable(session)]
    token = session.liveliness().declare_token(keys.alive_robot(ROBOT))
    node = OperatorNode(session, ROBOT, "op1", Stick())
    stop = threading.Event()
    runner = threading.Thread(target=node.run, args=(stop,))
    runner.start()
    command = OperatorCommand(1, HOUR, 0.5, 0.25, "shared", True, False, False, "op1")
    try:
        wait_for(lambda: node._robot_alive)
        session.put(
            keys.state(ROBOT),
            StateMessage(robot_clock(), "DRIVING", "fresh centred command", "op1", 0).encode(),
        )
        session.put(
            keys.telemetry(ROBOT),
            telemetry(
                1,
                stamp_ns=robot_clock(),
                state="DRIVING",
                operator="op1",
                cmd_age_p50_ms=150.0,
                cmd_gap_max_ms=30.0,
            ).encode(),
        )
        wait_for(lambda: node._status_of(command).robot_state == "DRIVING")
        wait_for(lambda: node._status_of(command).rtt_ms is not None)
        assert "in control" in format_status(node._status_of(command))
        token.undeclare()  # the robot is killed
        wait_for(lambda: not node._robot_alive, 5.0)
        gone = node._status_of(command)  # at once, not once its telemetry is 0.5 s old
        assert situation(gone).startswith("NO TELEMETRY for 0.")
        assert "robot gone" in situation(gone)
        line = format_status(gone)
        assert "cmd age" not in line and "rtt" not in line and "in control" not in line
        token = session.liveliness().declare_token(keys.alive_robot(ROBOT))  # restarted
        wait_for(lambda: node._robot_alive, 5.0)
        back = node._status_of(command)
        assert back.robot_state is None and "DRIVING" not in format_status(back)
    finally:
        stop.set()
        runner.join(timeout=10)
        node.close()
        token.undeclare()
        for entity in entities:
            entity.undeclare()


def test_a_restarted_robot_s_map_replaces_the_old_one(session: zenoh.Session) -> None:
    """Outside check: after a robot restart the view kept the old robot's map (the map thread
    ended after the first map)."""
    maps = {"served": MapMessage(1, 0.05, -1.0, -2.0, np.eye(40, dtype=bool), goal=(3.0, 1.0))}

    def on_map(query: zenoh.Query) -> None:
        query.reply(keys.world_map(ROBOT), maps["served"].encode())

    entities = [
        _clock_queryable(session),
        session.declare_queryable(keys.world_map(ROBOT), on_map),
    ]
    token = session.liveliness().declare_token(keys.alive_robot(ROBOT))
    view = MapView()
    node = OperatorNode(session, ROBOT, "op1", Stick(), view=view)
    stop = threading.Event()
    runner = threading.Thread(target=node.run, args=(stop,))
    runner.start()
    try:
        wait_for(lambda: len(view.maps) == 1, 10.0)
        token.undeclare()  # the robot is killed ...
        wait_for(lambda: not node._robot_alive, 5.0)
        # ... and restarted on another map
        maps["served"] = MapMessage(1, 0.1, 0.0, 0.0, np.zeros((30, 50), dtype=bool), goal=None)
        token = session.liveliness().declare_token(keys.alive_robot(ROBOT))
        wait_for(lambda: len(view.maps) == 2, 10.0)
        assert view.maps[-1] == ((30, 50), 0.1, (0.0, 0.0), None)
        time.sleep(1.5)  # asked once per appearance, not over and over
        assert len(view.maps) == 2
    finally:
        stop.set()
        runner.join(timeout=10)
        node.close()
        token.undeclare()
        for entity in entities:
            entity.undeclare()


def test_a_restarted_robot_shows_no_round_trip_of_the_old_one(session: zenoh.Session) -> None:
    """Outside check: after a restart the first lines for the new robot repeated the killed
    robot's rtt for 1-2 s (the clock sync was kept across the restart)."""
    clock = _clock_queryable(session)
    token = session.liveliness().declare_token(keys.alive_robot(ROBOT))
    node = OperatorNode(session, ROBOT, "op1", Stick())
    stop = threading.Event()
    runner = threading.Thread(target=node.run, args=(stop,))
    runner.start()
    command = OperatorCommand(1, HOUR, 0.5, 0.25, "shared", True, False, False, "op1")
    try:
        wait_for(lambda: node._status_of(command).rtt_ms is not None)
        token.undeclare()
        clock.undeclare()  # the robot is killed: no more clock replies ...
        wait_for(lambda: not node._robot_alive, 5.0)
        token = session.liveliness().declare_token(keys.alive_robot(ROBOT))  # ... restarted
        wait_for(lambda: node._robot_alive, 5.0)
        back = node._status_of(command)
        assert back.rtt_ms is None and not back.synchronised
        assert "rtt" not in format_status(back)
        clock = _clock_queryable(session)  # the new robot answers: its own round trip
        wait_for(lambda: node._status_of(command).rtt_ms is not None, 5.0)
    finally:
        stop.set()
        runner.join(timeout=10)
        node.close()
        token.undeclare()
        clock.undeclare()
