"""Clock sync with more than one peer answering the clock query (ClockSync per replier).

Outside check: a second peer answering egc/<robot>/clock with another clock (a rogue, or two
robots started with the same id) made every sync look like a clock jump and the command stamps
follow the rogue; the real robot rejected ~250 commands as stale and held 10-12 s of 15 while
the status line said synced, rtt 0.7 ms. The robot's own telemetry (its stamp_ns is the robot's
clock) now says which replier's clock is the robot's.
"""

from __future__ import annotations

import pytest
from egc_operator.clock_sync import ClockSync

MS = 1_000_000
S = 1_000 * MS
LOCAL0 = 50_000 * S  # our monotonic clock at the start
ROBOT_OFFSET = -7 * S  # the robot's clock = ours - 7 s (booted 7 s after us)
ROGUES = {"future": 2**62, "one": 1, "past": 10**9, "ahead_2s": None}


class Link:
    """Replies with 0.5 ms each way, telemetry 3 ms after its stamp."""

    def __init__(self, sync: ClockSync) -> None:
        self.sync = sync
        self.now = LOCAL0

    def reply(self, replier: str, robot_ns: int | None = None) -> None:
        sent = self.now
        stamp = sent + MS // 2 + ROBOT_OFFSET if robot_ns is None else robot_ns
        self.sync.add(sent, stamp, sent + MS, replier=replier)

    def telemetry(self, age_ms: float = 3.0, stamp: int | None = None) -> int | None:
        if stamp is None:
            stamp = self.now + ROBOT_OFFSET - int(age_ms * MS)
        return self.sync.admit_telemetry(stamp, self.now)

    def robot_error_ms(self) -> float:
        """How far the stamps are from the robot's clock (0 when unsynchronised)."""
        stamp = self.sync.robot_now(self.now)
        return 0.0 if stamp == 0 else (stamp - (self.now + ROBOT_OFFSET)) / MS


def rogue_stamp(kind: str, link: Link) -> int:
    value = ROGUES[kind]
    return link.now + ROBOT_OFFSET + 2 * S if value is None else value


@pytest.mark.parametrize("kind", sorted(ROGUES))
@pytest.mark.parametrize("rogue_first", [True, False])
def test_the_robot_s_telemetry_picks_the_robot_s_clock(kind: str, rogue_first: bool) -> None:
    link = Link(ClockSync())
    for k in range(40):  # 4 s of 10 Hz queries, telemetry at 20 Hz
        order = ["rogue", "robot"] if rogue_first else ["robot", "rogue"]
        for who in order:
            link.reply(who, rogue_stamp(kind, link) if who == "rogue" else None)
        assert link.telemetry() is None  # the robot's telemetry is never refused
        if k >= 1:  # two disagreeing repliers: telemetry decides at once
            assert link.sync.synchronised
            assert abs(link.robot_error_ms()) < 1.0, (k, link.robot_error_ms())
            assert link.sync.driver == "robot"
        link.now += 50 * MS
        assert link.telemetry() is None
        link.now += 50 * MS
    views = link.sync.repliers()
    assert [(v.replier, v.drives) for v in views] == [("robot", True), ("rogue", False)]
    assert views[0].fits
    # 2 s ahead, the telemetry looks 2 s old on the rogue's clock, which a slow link allows:
    # it fits, but the robot's clock is the one least ahead that fits
    assert views[1].fits is (kind == "ahead_2s")
    assert link.sync.note() == "2 clock repliers, 1 ignored"


def test_two_disagreeing_repliers_and_no_telemetry_yet_is_no_sync() -> None:
    """Unsynchronised (stamp 0: the robot bounds the age by arrival) rather than a guess."""
    link = Link(ClockSync())
    link.reply("robot")
    assert link.sync.synchronised  # one replier: its clock
    link.reply("rogue", 1)
    assert not link.sync.synchronised
    assert link.sync.robot_now(link.now) == 0
    assert link.sync.latest is None  # no round trip claimed for either
    note = link.sync.note()
    assert note is not None and "disagree" in note


def test_a_lone_replier_whose_clock_the_telemetry_contradicts_is_not_used() -> None:
    """Only a rogue answers (the robot's reply lost, or its queryable not reachable) with a
    clock far ahead: the telemetry is all 'hours old' on it, so commands go out unsynchronised
    rather than stamped in the robot's far future."""
    link = Link(ClockSync())
    link.reply("rogue", 2**62)
    assert link.sync.synchronised
    link.telemetry()
    assert not link.sync.synchronised
    assert link.sync.note() == "the clock reply disagrees with the robot's telemetry"


def test_telemetry_from_the_future_is_refused_once_synced() -> None:
    """stamp_ns 2**63 - 1 made the operator report view_age_ms 0 and froze its episode."""
    link = Link(ClockSync())
    assert link.telemetry(stamp=2**63 - 1) is None  # no clock yet: nothing to judge it by
    link.reply("robot")
    ahead = link.telemetry(stamp=2**63 - 1)
    assert ahead is not None and ahead > 10**18
    assert link.telemetry(age_ms=-900.0) is None  # within the 1 s tolerance
    assert link.telemetry(age_ms=-1100.0) is not None
    assert link.sync.synchronised  # refused telemetry is no evidence against the clock
    assert abs(link.robot_error_ms()) < 1.0


def test_a_rogue_that_stops_answering_is_forgotten_and_an_outage_changes_nothing() -> None:
    link = Link(ClockSync())
    link.reply("robot")
    link.reply("rogue", 1)
    link.telemetry()
    assert link.sync.driver == "robot"
    # a 30 s outage: no replies, no telemetry; the estimate stays as it was
    link.now += 30 * S
    assert link.sync.driver == "robot" and abs(link.robot_error_ms()) < 1.0
    for _ in range(12):  # the robot answers again, the rogue no more
        link.now += 1 * S
        link.reply("robot")
        link.telemetry()
    assert [v.replier for v in link.sync.repliers()] == ["robot"]
    assert link.sync.note() is None


def test_a_robot_clock_jump_is_still_followed_per_replier() -> None:
    link = Link(ClockSync())
    link.reply("robot")
    link.reply("rogue", 1)
    link.telemetry()
    assert link.sync.driver == "robot"
    # the robot (same replier id) comes back on another boot: 9 h behind; its telemetry too
    offset = ROBOT_OFFSET - 9 * 3600 * S
    link.now += S
    link.sync.add(link.now, link.now + MS // 2 + offset, link.now + MS, replier="robot")
    link.now += MS
    assert link.sync.admit_telemetry(link.now + offset - 3 * MS, link.now) is None
    assert link.sync.driver == "robot"
    assert abs(link.sync.robot_now(link.now) - (link.now + offset)) < MS


def test_repliers_are_bounded() -> None:
    link = Link(ClockSync())
    for i in range(100):
        link.reply(f"rogue{i}", 10**9 + i)
    assert len(link.sync.repliers()) <= 8
