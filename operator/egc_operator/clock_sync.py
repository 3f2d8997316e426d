"""Estimating the robot's monotonic clock on the operator (DESIGN 7: ``stamp_ns``).

The operator queries ``egc/<robot>/clock``; the reply carries the robot's monotonic time. With
the local send and receive times this gives one sample (Cristian's method):

    offset = robot_stamp - (t_send + t_recv) / 2,    rtt = t_recv - t_send,

whose error is at most rtt / 2. Samples slower than ``max_rtt_ns`` (default 3 s, above a
satellite link's round trip with jitter) are ignored. ``ClockSync`` keeps the last ``window``
samples and uses the one with the smallest round trip (the least queueing delay). All
arithmetic is on integer nanoseconds, so clocks that differ by hours (or machines booted days
apart) lose no precision. If a new sample's error interval does not overlap the estimate's, the
robot's clock has jumped (the robot restarted on another boot): the window restarts from that
sample.

More than one peer may answer the query (any peer can declare the queryable: a rogue, or two
robots started with the same id). Samples are kept per replier (its Zenoh id), and the robot's
own telemetry says which clock is the robot's: its ``stamp_ns`` is the robot's clock when it
was sent, so with a replier's offset the telemetry's age at arrival is known. Telemetry that
*fits* a replier arrived neither in that clock's future (beyond the sample's error, rtt / 2)
nor more than ``max_rtt_ns`` after it was sent. The stamps follow:

- the replier that fitted telemetry within the last ``fit_window_ns`` (several: the one whose
  clock is least ahead, the one that makes the telemetry freshest without being early);
- else the only replier, unless the recent telemetry was all far older than its clock says;
- else nothing: ``robot_now`` is 0, the wire's "unsynchronised" (two disagreeing repliers and
  no telemetry yet to tell them apart; an outside check had every other sync follow a rogue
  replier's clock, and the robot rejected the commands as stale while the status line said
  synced).

Once there is an estimate, telemetry stamped more than ``future_tolerance_ns`` ahead of it is
refused (``admit_telemetry``): a stamp near 2**63 made the operator report ``view_age_ms`` 0
and froze the status line's episode tracking.

Pure: the caller passes local monotonic times in; nothing here reads a clock.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

from egc_common.messages import MAX_INT

_MS = 1_000_000
_S = 1_000_000_000
MAX_REPLIERS = 8  # repliers tracked at once; the one heard least recently makes room
FIT_SLACK_NS = 20 * _MS  # telemetry this much earlier than a clock's error allows still fits


@dataclass(frozen=True, slots=True)
class ClockSample:
    offset_ns: int
    rtt_ns: int
    local_ns: int


@dataclass(slots=True)
class _Replier:
    samples: deque[ClockSample]
    latest: ClockSample | None = None
    heard_ns: int = 0
    fit_ns: int | None = None  # local time of the newest telemetry that fitted its clock
    old_ns: int | None = None  # ... of the newest one far older than its clock says
    ahead_ns: int | None = None  # ... of the newest one in its clock's future
    skew_ns: int = 0  # the newest telemetry's age at arrival on its clock (negative: early)

    @property
    def best(self) -> ClockSample | None:
        return min(self.samples, key=lambda s: s.rtt_ns, default=None)


@dataclass(frozen=True, slots=True)
class ReplierView:
    """One replier as the log and status line describe it."""

    replier: str
    drives: bool
    fits: bool  # telemetry fitted its clock recently
    offset_ns: int | None  # its best sample's offset
    # How far the newest telemetry's stamp lies from its clock at arrival (age, ns; negative:
    # the telemetry is in its clock's future), when known.
    telemetry_age_ns: int | None


class ClockSync:
    def __init__(
        self,
        window: int = 16,
        max_rtt_ns: int = 3000 * _MS,
        future_tolerance_ns: int = 1 * _S,
        fit_window_ns: int = 10 * _S,
        forget_ns: int = 10 * _S,
    ) -> None:
        if window < 1:
            raise ValueError("window must be >= 1")
        self._window = window
        self._max_rtt_ns = max_rtt_ns
        self._future_ns = future_tolerance_ns
        self._fit_window_ns = fit_window_ns
        self._forget_ns = forget_ns
        self._repliers: dict[str, _Replier] = {}
        # Local times of the newest reply and the newest admitted telemetry: the windows count
        # back from them, not from now, so a link outage changes nothing while it lasts.
        self._reply_ns: int | None = None
        self._telemetry_ns: int | None = None

    # -- input --------------------------------------------------------------------------------

    def add(
        self,
        send_local_ns: int,
        robot_ns: int,
        recv_local_ns: int,
        same_clock: bool = False,
        replier: str = "",
    ) -> ClockSample | None:
        """One query round trip; returns the sample, or None if it is unusable.

        ``same_clock``: the robot's reply says its clock *is* ours (the same kernel's
        CLOCK_MONOTONIC: the same host, or network namespaces of one host), so the offset is
        exactly 0 whatever the path's asymmetry. Cristian's midpoint assumes equal delays both
        ways; over a link that delays only one direction by d it is off by d / 2.
        ``replier``: who answered (the reply's Zenoh id); samples are kept per replier.
        """
        rtt = recv_local_ns - send_local_ns
        if rtt < 0 or rtt > self._max_rtt_ns or robot_ns <= 0:
            return None
        if self._reply_ns is None or recv_local_ns > self._reply_ns:
            self._reply_ns = recv_local_ns
        offset = 0 if same_clock else robot_ns - (send_local_ns + recv_local_ns) // 2
        sample = ClockSample(offset, rtt, recv_local_ns)
        peer = self._repliers.get(replier)
        if peer is None:
            if len(self._repliers) >= MAX_REPLIERS:
                oldest = min(self._repliers, key=lambda k: self._repliers[k].heard_ns)
                del self._repliers[oldest]
            peer = _Replier(deque(maxlen=self._window))
            self._repliers[replier] = peer
        best = peer.best
        if (
            best is not None
            and abs(sample.offset_ns - best.offset_ns) > (sample.rtt_ns + best.rtt_ns) // 2 + _MS
        ):
            # the robot's clock jumped: forget the old boot, and what telemetry said of it
            peer.samples.clear()
            peer.fit_ns = peer.old_ns = peer.ahead_ns = None
        peer.samples.append(sample)
        peer.latest = sample
        peer.heard_ns = recv_local_ns
        return sample

    def admit_telemetry(self, stamp_ns: int, recv_local_ns: int) -> int | None:
        """Telemetry stamped ``stamp_ns`` (robot clock) arrived at ``recv_local_ns``.

        Returns None when it is admitted (and notes which repliers' clocks it fits), or how
        far (ns) it lies ahead of the robot clock estimate when it is refused: more than
        ``future_tolerance_ns`` in the future of a clock that the telemetry itself chose.
        """
        best = self.best
        if best is not None:
            ahead = stamp_ns - (recv_local_ns + best.offset_ns)
            if ahead > self._future_ns:
                return ahead
        if self._telemetry_ns is None or recv_local_ns > self._telemetry_ns:
            self._telemetry_ns = recv_local_ns
        for peer in self._repliers.values():
            best = peer.best
            if best is None:
                continue
            age = recv_local_ns + best.offset_ns - stamp_ns
            peer.skew_ns = age
            if age < -(best.rtt_ns // 2 + FIT_SLACK_NS):
                peer.ahead_ns = recv_local_ns
            elif age > self._max_rtt_ns:
                peer.old_ns = recv_local_ns
            else:
                peer.fit_ns = recv_local_ns
        return None

    # -- which clock ----------------------------------------------------------------------------

    def _recent(self) -> dict[str, _Replier]:
        """The repliers heard within ``forget_ns`` of the newest reply."""
        newest = self._reply_ns
        return {
            k: p
            for k, p in self._repliers.items()
            if p.samples and newest is not None and newest - p.heard_ns <= self._forget_ns
        }

    def _lately(self, local_ns: int | None) -> bool:
        """``local_ns`` is within ``fit_window_ns`` of the newest admitted telemetry."""
        newest = self._telemetry_ns
        return (
            local_ns is not None and newest is not None and newest - local_ns <= self._fit_window_ns
        )

    def _fits(self, peer: _Replier) -> bool:
        return self._lately(peer.fit_ns)

    def _driver_id(self) -> str | None:
        recent = self._recent()
        fitting = [k for k, p in recent.items() if self._fits(p)]
        if fitting:
            # the clock least ahead among those the telemetry fits (offsets share our clock)
            return min(fitting, key=lambda k: (self._offset(recent[k]), k))
        if len(recent) == 1:
            key, peer = next(iter(recent.items()))
            return None if self._lately(peer.old_ns) else key
        return None

    @staticmethod
    def _offset(peer: _Replier) -> int:
        best = peer.best
        return 0 if best is None else best.offset_ns

    def _driver(self) -> _Replier | None:
        key = self._driver_id()
        return None if key is None else self._repliers[key]

    # -- output -------------------------------------------------------------------------------

    @property
    def best(self) -> ClockSample | None:
        """The sample with the smallest round trip in the window of the clock in use."""
        driver = self._driver()
        return None if driver is None else driver.best

    @property
    def latest(self) -> ClockSample | None:
        """The newest sample of the clock in use."""
        driver = self._driver()
        return None if driver is None else driver.latest

    @property
    def synchronised(self) -> bool:
        return self._driver() is not None

    @property
    def confirmed(self) -> bool:
        """The clock in use is the one the robot's telemetry fitted lately."""
        driver = self._driver()
        return driver is not None and self._fits(driver)

    @property
    def driver(self) -> str | None:
        """The replier whose clock the stamps follow, or None."""
        return self._driver_id()

    def repliers(self) -> list[ReplierView]:
        """The repliers heard recently, the one in use first."""
        driver = self._driver_id()
        views = [
            ReplierView(
                key,
                key == driver,
                self._fits(peer),
                self._offset(peer),
                None
                if peer.fit_ns is None and peer.old_ns is None and peer.ahead_ns is None
                else peer.skew_ns,
            )
            for key, peer in self._recent().items()
        ]
        return sorted(views, key=lambda v: (not v.drives, v.replier))

    def note(self) -> str | None:
        """What the status line says of the clock besides the round trip: None when one
        replier answers and it is in use (or none answered yet)."""
        views = self.repliers()
        n = len(views)
        driving = any(v.drives for v in views)
        if n > 1 and driving:
            return f"{n} clock repliers, {n - 1} ignored"
        if n > 1:
            return f"{n} clock repliers disagree, none fits the robot's telemetry yet"
        if n == 1 and not driving:
            return "the clock reply disagrees with the robot's telemetry"
        return None

    def robot_now(self, local_ns: int) -> int:
        """The robot's monotonic time now, or 0 (the wire's "unsynchronised") before a sample."""
        best = self.best
        if best is None:
            return 0
        # Clamped to the wire's range: a reply near 2**63 (any peer can answer the clock key)
        # made the command's stamp overflow it, and the operator died on its own command.
        return min(max(0, local_ns + best.offset_ns), MAX_INT)
