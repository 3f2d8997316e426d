"""Clock sync (DESIGN 7 stamp_ns): min-RTT filter, hour-scale offsets, clock jumps."""

from __future__ import annotations

from egc_operator.clock_sync import ClockSync

MS = 1_000_000
HOUR = 3600 * 10**9


def test_unsynchronised_is_zero():
    assert ClockSync().robot_now(123 * MS) == 0


def test_offset_of_an_hour_is_exact_with_a_symmetric_round_trip():
    sync = ClockSync()
    local = 2 * HOUR
    # robot clock = local - 1 h; the reply was taken halfway through a 2 ms round trip
    sync.add(local, local + 1 * MS - HOUR, local + 2 * MS)
    assert sync.robot_now(local + 50 * MS) == local + 50 * MS - HOUR


def test_min_rtt_sample_wins_over_later_slow_ones():
    sync = ClockSync()
    true_offset = 5 * HOUR
    sync.add(0, true_offset + 1 * MS, 2 * MS)  # rtt 2 ms, exact
    # a reply delayed 40 ms on the way back: midpoint estimate is 20 ms off
    sync.add(100 * MS, 100 * MS + true_offset + 1 * MS, 142 * MS)
    assert sync.best is not None and sync.best.rtt_ns == 2 * MS
    assert sync.robot_now(1000 * MS) == 1000 * MS + true_offset
    assert sync.latest is not None and sync.latest.rtt_ns == 42 * MS


def test_unusable_samples_are_ignored():
    sync = ClockSync(max_rtt_ns=100 * MS)
    assert sync.add(10, 5, 5) is None  # negative round trip
    assert sync.add(0, 5, 200 * MS) is None  # slower than max_rtt
    assert sync.add(0, 0, 1 * MS) is None  # robot stamp 0 is "no clock"
    assert not sync.synchronised


def test_a_robot_clock_jump_restarts_the_window():
    sync = ClockSync()
    t = 20 * HOUR
    sync.add(t, t + HOUR + 1 * MS, t + 2 * MS)
    # the robot restarted on another boot: its clock is now 9 h behind ours
    sync.add(t + 10 * MS, t + 12 * MS - 9 * HOUR, t + 14 * MS)
    assert sync.best is not None and sync.best.rtt_ns == 4 * MS  # the old sample is gone
    assert sync.robot_now(t + 20 * MS) == t + 20 * MS - 9 * HOUR


def test_same_clock_replies_give_offset_zero_on_a_one_sided_link():
    # 100 ms on the way to the robot, nothing back: Cristian's midpoint is off by 50 ms ...
    sync = ClockSync()
    sync.add(0, 100 * MS, 100 * MS)
    assert sync.robot_now(1_000 * MS) == 1_050 * MS
    # ... while a robot that names the same clock gives the exact offset, 0.
    same = ClockSync()
    same.add(0, 100 * MS, 100 * MS, same_clock=True)
    assert same.robot_now(1_000 * MS) == 1_000 * MS


def test_a_clock_reply_near_the_end_of_the_wire_range_cannot_overflow_a_command():
    """Outside check: a peer answering egc/<robot>/clock with stamp 2**63 - 1 made the
    operator's next command stamp overflow the wire's range, and the operator died."""
    from egc_common.messages import MAX_INT, OperatorCommand

    sync = ClockSync()
    sync.add(1_000, MAX_INT, 2_000)
    stamp = sync.robot_now(10**12)
    assert stamp == MAX_INT
    OperatorCommand(1, stamp, 0.0, 0.0, "shared", True, False, False, "a")
