"""The operator node's view_age_ms (DESIGN 7, 9) and the command history it gives the view.

The node runs against one in-process Zenoh session (no network): the test answers the clock
queries with a robot clock an hour ahead of the node's, publishes telemetry and records the
commands the node sends.
"""

from __future__ import annotations

import contextlib
import math
import threading
import time
from collections.abc import Iterator
from typing import Any

import numpy.typing as npt
import zenoh
from egc_common import keys
from egc_common.joystick_file import JoystickSample
from egc_common.messages import (
    MAX_VIEW_AGE_MS,
    OperatorCommand,
    StateMessage,
    Telemetry,
    decode_command,
    encode_clock_reply,
)
from egc_common.transport import payload_bytes
from egc_operator.operator_node import OperatorNode, view_age_ms
from egc_operator.prediction import CommandHistory

MS = 1_000_000
HOUR = 3600 * 1000 * MS
ROBOT = "nodetest"


def test_view_age_is_the_robot_clock_age_of_the_newest_telemetry() -> None:
    assert view_age_ms(HOUR + 230 * MS, True, HOUR) == 230
    assert view_age_ms(HOUR + 230 * MS + 999_999, True, HOUR) == 230  # whole milliseconds


def test_view_age_is_unknown_before_sync_or_telemetry() -> None:
    assert view_age_ms(HOUR, False, HOUR - 5 * MS) is None
    assert view_age_ms(0, True, HOUR) is None  # robot_now's "unsynchronised"
    assert view_age_ms(HOUR, True, None) is None


def test_view_age_is_clamped_to_the_wire_range() -> None:
    assert view_age_ms(HOUR, True, HOUR + 3 * MS) == 0  # clock-sync error: "from the future"
    assert view_age_ms(3 * HOUR, True, 1) == MAX_VIEW_AGE_MS
    # the clamped value is what the wire accepts
    OperatorCommand(1, HOUR, 0.0, 0.0, "shared", True, False, False, "op", MAX_VIEW_AGE_MS)


class Stick:
    """A command source: half stick forward, a little left, deadman held, forever."""

    finished = False

    def sample(self, t_s: float) -> JoystickSample:
        return JoystickSample(t_s, 0.5, 0.25, deadman=True, mode="shared")

    def close(self) -> None:
        pass


class RecordingView:
    def __init__(self) -> None:
        self.telemetry: list[tuple[Telemetry, int | None]] = []
        self.commands: list[tuple[int, int, int]] = []  # (robot_now, len, newest stamp)
        self.routes: list[tuple[tuple[tuple[float, float], ...], str]] = []
        self.rtts_ms: list[float] = []  # the clock samples' round trips (on_link)
        self.lock = threading.Lock()

    def on_telemetry(self, t: Telemetry, received_ns: int | None = None) -> None:
        with self.lock:
            self.telemetry.append((t, received_ns))

    def on_commands(self, history: CommandHistory, robot_now_ns: int) -> None:
        newest = history.newest
        assert newest is not None
        with self.lock:
            self.commands.append((robot_now_ns, len(history), newest.stamp_ns))

    def on_state(self, s: StateMessage) -> None:
        pass

    def on_text(self, level: str, text: str) -> None:
        pass

    def on_link(self, rtt_ms: float, offset_ns: int) -> None:
        with self.lock:
            self.rtts_ms.append(rtt_ms)

    def clock_error_ns(self) -> int:
        """The clock sync's own error bar: an estimate from a sample with round trip rtt is off
        by at most rtt / 2 (clock_sync.py); the largest over the samples it reported covers
        whichever was in use (+1 us for the float milliseconds)."""
        with self.lock:
            assert self.rtts_ms, "no clock sample reported"
            return math.ceil(max(self.rtts_ms) * 1e6 / 2) + 1000

    def close(self) -> None:
        pass

    def set_world(
        self,
        occupancy: npt.ArrayLike,
        resolution_m: float,
        origin_xy_m: tuple[float, float],
        goal_xy_m: tuple[float, float] | None = None,
    ) -> None:
        pass

    def on_route(self, points: tuple[tuple[float, float], ...], frame: str) -> None:
        with self.lock:
            self.routes.append((points, frame))


def robot_clock() -> int:
    return time.monotonic_ns() + HOUR


def wait_for(condition: Any, timeout_s: float = 10.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError("timed out")
        time.sleep(0.01)


@contextlib.contextmanager
def running(node: OperatorNode, entities: list[Any]) -> Iterator[None]:
    """``node.run`` in a thread of its own; then the node stops and closes, and the test's
    ``entities`` (subscribers, queryables, tokens) go."""
    stop = threading.Event()
    runner = threading.Thread(target=node.run, args=(stop,))
    runner.start()
    try:
        yield
    finally:
        stop.set()
        runner.join(timeout=10)
        node.close()
        for entity in entities:
            entity.undeclare()


def test_commands_carry_view_age_and_the_view_gets_the_history(session: zenoh.Session) -> None:
    sent: list[tuple[OperatorCommand, int]] = []

    def on_cmd(sample: zenoh.Sample) -> None:
        cmd = decode_command(payload_bytes(sample))
        assert isinstance(cmd, OperatorCommand)
        sent.append((cmd, robot_clock()))

    def on_clock(query: zenoh.Query) -> None:
        query.reply(keys.clock(ROBOT), encode_clock_reply(robot_clock()))

    entities = [
        session.declare_subscriber(keys.cmd(ROBOT), on_cmd),
        session.declare_queryable(keys.clock(ROBOT), on_clock),
        session.liveliness().declare_token(keys.alive_robot(ROBOT)),  # the robot is present
    ]
    view = RecordingView()
    node = OperatorNode(session, ROBOT, "op1", Stick(), rate_hz=50.0, view=view)
    with running(node, entities):
        wait_for(lambda: any(c.stamp_ns and c.deadman for c, _ in sent))  # synchronised, driving
        assert all(c.view_age_ms is None for c, _ in sent)  # no telemetry yet: key left out
        stamp = robot_clock() - 150 * MS  # telemetry that spent 150 ms on the way
        telemetry = Telemetry(
            seq=1,
            stamp_ns=stamp,
            state="DRIVING",
            mode="shared",
            v_ref=0.07,
            w_ref=0.125,
            v_cmd=0.07,
            w_cmd=0.125,
            w_si=1.0,
            pose=(0.0, 0.0, 0.0),
            profile="pioneer3dx",
        )
        published_at = robot_clock()
        session.put(keys.telemetry(ROBOT), telemetry.encode())
        wait_for(lambda: len(view.telemetry) == 1)
        shown_at = robot_clock()  # the view has had it by now
        n = len(sent)
        wait_for(lambda: len(sent) >= n + 10)
    ((shown, received),) = view.telemetry
    assert shown.stamp_ns == stamp
    # ``received`` is the node's estimate of the robot's clock at arrival: between the true
    # clock when the test published and when the view was handed it, give or take the error
    # the clock sync itself reports (issue 32: 149.8 ms measured against a bound of 150 ms).
    err = view.clock_error_ns()
    assert received is not None
    assert published_at - err <= received <= shown_at + err, (received - stamp, err)
    ages = [(c.view_age_ms, c.stamp_ns, at) for c, at in sent if c.view_age_ms is not None]
    assert len(ages) >= 10
    for i, (age, stamped, arrived) in enumerate(ages):
        # stamped with the robot's clock when sent: before it arrived, and (but the first,
        # whose clock may have been read just before the telemetry came) after the telemetry
        assert stamped <= arrived + err, (stamped - arrived, err)
        assert i == 0 or published_at - err <= stamped, (stamped - published_at, err)
        # the telemetry's age on the robot's clock when the command is sent (DESIGN 7), in
        # whole milliseconds: it grows with the send time
        assert abs(age - (stamped - stamp) // MS) <= 1, (age, stamped - stamp)
    # every synchronised command went into the history handed to the view, newest last
    # (the one command after the stop releases the deadman; it is not for the predictive view)
    synced = [c for c, _ in sent if c.stamp_ns and c.deadman]
    assert sent[-1][0].deadman is False and sent[-2][0].deadman is True
    handed = [newest for _, _, newest in view.commands]
    assert handed[: len(synced)] == [c.stamp_ns for c in synced]  # the last may be in flight
    # The node's history is the newest of them: all on an idle machine; on a busy one the run
    # can outlast the history's 4 s, or a better clock sample can move the stamps back (the
    # history then starts over, prediction.CommandHistory)
    kept = [c.stamp_ns for c in node.history.since(0)]
    assert kept and kept == handed[-len(kept) :]
    assert all(now == newest for now, _, newest in view.commands)
    command = node.history.newest
    assert command is not None and (command.x, command.y, command.mode) == (0.5, 0.25, "shared")


class HeldBack(Stick):
    """A fleet node's source before its clock sync converges (``NodeSource.holding_back``)."""

    def __init__(self) -> None:
        self.open = threading.Event()

    def holding_back(self) -> bool:
        return not self.open.is_set()


def test_a_source_holding_back_sends_nothing_until_it_opens(session: zenoh.Session) -> None:
    """Its released commands reached the robot before it held control and were refused as
    not in control: the README's delayed-link demo counted 21 such rejections."""
    sent: list[OperatorCommand] = []

    def on_cmd(sample: zenoh.Sample) -> None:
        cmd = decode_command(payload_bytes(sample))
        assert isinstance(cmd, OperatorCommand)
        sent.append(cmd)

    entities = [
        session.declare_subscriber(keys.cmd(ROBOT), on_cmd),
        session.liveliness().declare_token(keys.alive_robot(ROBOT)),  # the robot is present
    ]
    source = HeldBack()
    node = OperatorNode(session, ROBOT, "op1", source, rate_hz=50.0)
    with running(node, entities):
        time.sleep(0.5)  # 25 periods
        assert sent == [] and node.published == 0
        source.open.set()
        wait_for(lambda: len(sent) >= 5)
    first = sent[0]
    assert first.seq == 1 and first.deadman  # the first command of its session
