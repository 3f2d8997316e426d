"""A robot (or a peer on its keys) that sends the operator bad messages: each is refused with a
counted, logged reason (DESIGN 7), the log stays readable, and the status line says so.

Outside checks against the operator:
- the status line stayed "DRIVING ... in control" while 100 % of the telemetry was rejected
  (not msgpack, NaN, wrong types, 10 MB, odd scan shapes); rejected telemetry was neither
  counted nor logged at INFO (only DEBUG, where a 5 kHz garbage flood gave 49,532 lines in
  10 s);
- one state message followed by no valid telemetry still showed "DRIVING ... in control" 9 s
  later ("NO TELEMETRY" only fired after some telemetry was accepted);
- telemetry stamped 2**63 - 1 made the operator report view_age_ms 0 to the robot.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import replace

import msgpack
import zenoh
from egc_common import keys
from egc_common.event_log import EventLog
from egc_common.messages import OperatorCommand, StateMessage, Telemetry, encode_clock_reply
from egc_operator.operator_node import OperatorNode, view_age_ms
from egc_operator.status_line import (
    Episode,
    RecentRejections,
    Rejections,
    format_status,
    situation,
    status_of,
)

from tests.operator.test_operator_node import RecordingView, Stick, wait_for

MS = 1_000_000
S = 1_000 * MS
HOUR = 3600 * S
ROBOT = "hostile"
COMMAND = OperatorCommand(1, 1, 1.0, 0.0, "shared", True, False, False, "op", 0)
STATE = StateMessage(1, "DRIVING", "driving", "op", 0)


def telemetry(stamp_ns: int = 2 * S, **extra: object) -> Telemetry:
    values: dict[str, object] = {"reason": "driving", "operator": "op"}
    values.update(extra)
    return Telemetry(1, stamp_ns, "DRIVING", "shared", 0.3, 0.0, 0.3, 0.0, 1.0, **values)  # type: ignore[arg-type]


# -- counting ------------------------------------------------------------------------------------


def test_rejections_are_counted_by_reason_and_said_while_they_last() -> None:
    r = Rejections()
    assert r.recent(0) is None
    for k in range(30):
        r.add("telemetry", "not_msgpack", "not msgpack: FormatError", k * 10 * MS)
    r.add("state", "wrong_type", "'stamp_ns' must be an integer", 300 * MS)
    recent = r.recent(400 * MS)
    assert recent is not None
    assert (recent.count, recent.telemetry, recent.total) == (31, 30, 31)
    assert recent.what == "telemetry not_msgpack: not msgpack: FormatError"
    assert r.by_reason[("telemetry", "not_msgpack")] == 30
    assert r.recent(1_500 * MS) is not None  # the period before still counts
    assert r.recent(2_100 * MS) is None  # two periods on: none lately
    assert r.total == 31  # the total stays


def test_the_log_says_each_kind_once_a_second_with_the_count_held_back() -> None:
    events = EventLog()
    allowed = [events.allow("telemetry not_msgpack", k * MS // 5) for k in range(5 * 10_000)]
    lines = [held for held in allowed if held is not None]  # 10 s of a 5 kHz flood
    assert len(lines) == 10
    assert lines[0] == 0 and all(held == 4999 for held in lines[1:])
    assert events.allow("state wrong_type", 0) == 0  # another kind: its own line


# -- the status line -----------------------------------------------------------------------------


def test_a_state_message_without_telemetry_is_not_shown_as_driving() -> None:
    status = status_of(COMMAND, None, STATE, 0.5, True, True, None, Episode(), state_age_s=9.0)
    text = format_status(status)
    assert text.startswith("NO TELEMETRY (none received since the robot appeared)")
    assert "DRIVING" not in text and "in control" not in text
    # even a fresh state message: no telemetry, nothing current to show
    fresh = status_of(COMMAND, None, STATE, 0.5, True, True, None, Episode(), state_age_s=0.1)
    assert situation(fresh).startswith("NO TELEMETRY") and fresh.in_control is None


def test_a_stale_state_message_is_not_shown_as_current() -> None:
    old_state = StateMessage(5 * S, "HOLD", "command timeout", "op", 0)
    t = telemetry(2 * S, reason=None)  # an older robot's telemetry: no reason of its own
    stale = status_of(COMMAND, t, old_state, 0.5, True, True, 0.05, Episode(), state_age_s=9.0)
    assert stale.robot_state == "DRIVING"  # the fresh telemetry's state, not the old HOLD
    fresh = status_of(COMMAND, t, old_state, 0.5, True, True, 0.05, Episode(), state_age_s=0.5)
    assert fresh.robot_state == "HOLD"  # a fresh state message newer than the telemetry


def test_all_telemetry_rejected_is_said_with_the_reason() -> None:
    refused = RecentRejections(25, 25, "telemetry not_finite: 'v_ref' must be finite", 105)
    never = status_of(COMMAND, None, STATE, 0.5, True, True, None, Episode(), 0.1, refused)
    text = format_status(never)
    assert text.startswith("NO VALID TELEMETRY (the robot's telemetry is rejected, see REFUSED)")
    assert "| REFUSED 25 robot msgs in 2 s (telemetry not_finite: 'v_ref' must be finite;" in text
    assert "DRIVING" not in text and "in control" not in text
    # telemetry came once, then only bad ones: how long ago the last good one came
    t = telemetry()
    later = status_of(COMMAND, t, STATE, 0.5, True, True, 3.2, Episode(), 0.1, refused)
    assert situation(later).startswith("NO VALID TELEMETRY for 3.2 s (the robot's telemetry")


def test_bad_messages_beside_good_telemetry_are_counted_on_the_line() -> None:
    refused = RecentRejections(6521, 6521, "telemetry not_msgpack: not msgpack: FormatError", 9)
    t = telemetry()
    status = status_of(COMMAND, t, STATE, 0.5, True, True, 0.05, Episode(), 0.1, refused)
    text = format_status(status)
    assert text.startswith("DRIVING | ")
    assert "| REFUSED 6521 robot msgs in 2 s (telemetry not_msgpack" in text
    assert "REFUSED" not in format_status(replace(status, refused=None))


def test_the_clock_is_not_claimed_synced_when_its_repliers_disagree() -> None:
    note = "2 clock repliers disagree, none fits the robot's telemetry yet"
    t = telemetry()
    unsynced = status_of(COMMAND, t, STATE, None, False, True, 0.05, clock_note=note)
    assert f"link -- (clock not synced: {note})" in format_status(unsynced)
    synced = status_of(
        COMMAND, t, STATE, 0.6, True, True, 0.05, clock_note="2 clock repliers, 1 ignored"
    )
    assert "rtt   0.6 ms (clock: 2 clock repliers, 1 ignored)" in format_status(synced)


def test_an_episode_recovers_from_a_bogus_far_future_stamp() -> None:
    episode = Episode()
    episode.update(telemetry(2**63 - 1, reason="x"))
    episode.update(telemetry(5 * S, reason="command timeout", cmd_gap_max_ms=400.0))
    assert episode.of("DRIVING", "command timeout") == (400.0, 0.0)
    episode.update(telemetry(5 * S - 50 * MS, reason="late"))  # a late cycle: still ignored
    assert episode.key == ("DRIVING", "command timeout")


def test_view_age_of_telemetry_from_the_future_is_unknown_not_zero() -> None:
    assert view_age_ms(HOUR, True, 2**63 - 1) is None
    assert view_age_ms(HOUR, True, HOUR + 900 * MS) == 0  # within clock-sync error
    assert view_age_ms(HOUR, True, HOUR + 1100 * MS) is None


# -- the node, against a hostile robot on one in-process session --------------------------------


def _good(stamp_ns: int, seq: int) -> bytes:
    return telemetry(stamp_ns, cmd_age_p50_ms=5.0).encode()


def test_the_node_counts_logs_and_says_refused_telemetry(session: zenoh.Session, caplog) -> None:
    caplog.set_level(logging.INFO, logger="egc.operator")

    def on_clock(query: zenoh.Query) -> None:
        query.reply(keys.clock(ROBOT), encode_clock_reply(time.monotonic_ns() + HOUR))

    entities = [
        session.declare_queryable(keys.clock(ROBOT), on_clock),
        session.liveliness().declare_token(keys.alive_robot(ROBOT)),
    ]
    view = RecordingView()
    node = OperatorNode(session, ROBOT, "op1", Stick(), rate_hz=50.0, view=view)
    stop = threading.Event()
    runner = threading.Thread(target=node.run, args=(stop,))
    runner.start()
    try:
        # one state message, then only garbage: 2,000 bad telemetry in about a second
        session.put(keys.state(ROBOT), STATE.encode())
        bad = [
            b"\xc1garbage",
            msgpack.packb({"v": 1, "seq": "x"}),
            _good(10, 1)[:-3],
            msgpack.packb({**msgpack.unpackb(_good(10, 1)), "junk": [{}] * 100_000}),
        ]
        t0 = time.monotonic()
        for k in range(2_000):
            session.put(keys.telemetry(ROBOT), bad[k % len(bad)])
        wait_for(lambda: node.rejections.total >= 2_000)
        flood_s = time.monotonic() - t0  # until the last was refused: a busy node lags the puts
        wait_for(lambda: node._sync.synchronised)
        text = format_status(node._status_of(COMMAND))
        assert text.startswith("NO VALID TELEMETRY"), text
        assert "DRIVING" not in text.split("|")[0] and "in control" not in text
        assert len(view.telemetry) == 0
        by = node.rejections.by_reason
        assert by[("telemetry", "not_msgpack")] == 1_000  # garbage and cut-short ones
        assert by[("telemetry", "wrong_type")] == 500
        assert by[("telemetry", "too_large")] == 500  # the bombs, refused at their header
        lines = [r for r in caplog.records if "rejected telemetry" in r.getMessage()]
        assert lines and all(r.levelno == logging.WARNING for r in lines)
        # at most one line per reason per second, the count held back said
        assert len(lines) <= 3 * (flood_s + 3), [r.getMessage() for r in lines]
        # telemetry from the robot's far future, once the clock is synced: refused, counted
        before = node.rejections.total
        session.put(keys.telemetry(ROBOT), _good(2**63 - 1, 2))
        wait_for(lambda: node.rejections.total == before + 1)
        assert by[("telemetry", "stale")] == 1
        assert len(view.telemetry) == 0
        # good telemetry: shown, and the refusals are still said for a while
        now_robot = time.monotonic_ns() + HOUR
        session.put(keys.telemetry(ROBOT), _good(now_robot, 3))
        wait_for(lambda: len(view.telemetry) == 1)
        text = format_status(node._status_of(COMMAND))
        assert text.startswith("DRIVING | "), text
        assert "| REFUSED " in text
    finally:
        stop.set()
        runner.join(10)
        node.close()
        for entity in entities:
            entity.undeclare()
