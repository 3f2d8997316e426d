"""Estimating the robot's monotonic clock on the operator (DESIGN 7: ``stamp_ns``).

The operator queries ``egc/<robot>/clock``; the reply carries the robot's monotonic time. With
the local send and receive times this gives one sample (Cristian's method):

    offset = robot_stamp - (t_send + t_recv) / 2,    rtt = t_recv - t_send,

whose error is at most rtt / 2. Samples slower than ``max_rtt_ns`` (default 3 s, above a
satellite link's round trip with jitter) are ignored. ``ClockSync`` keeps the last ``window`` samples and uses the one
with the smallest round trip (the least queueing delay). All arithmetic is on integer
nanoseconds, so clocks that differ by hours (or machines booted days apart) lose no precision.
If a new sample's error interval does not overlap the estimate's, the robot's clock has jumped
(the robot restarted on another boot): the window restarts from that sample.

Pure: the caller passes local monotonic times in; nothing here reads a clock.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

from egc_common.messages import MAX_INT

_MS = 1_000_000


@dataclass(frozen=True, slots=True)
class ClockSample:
    offset_ns: int
    rtt_ns: int
    local_ns: int


class ClockSync:
    def __init__(self, window: int = 16, max_rtt_ns: int = 3000 * _MS) -> None:
        if window < 1:
            raise ValueError("window must be >= 1")
        self._samples: deque[ClockSample] = deque(maxlen=window)
        self._max_rtt_ns = max_rtt_ns
        self.latest: ClockSample | None = None

    def add(
        self, send_local_ns: int, robot_ns: int, recv_local_ns: int, same_clock: bool = False
    ) -> ClockSample | None:
        """One query round trip; returns the sample, or None if it is unusable.

        ``same_clock``: the robot's reply says its clock *is* ours (the same kernel's
        CLOCK_MONOTONIC: the same host, or network namespaces of one host), so the offset is
        exactly 0 whatever the path's asymmetry. Cristian's midpoint assumes equal delays both
        ways; over a link that delays only one direction by d it is off by d / 2.
        """
        rtt = recv_local_ns - send_local_ns
        if rtt < 0 or rtt > self._max_rtt_ns or robot_ns <= 0:
            return None
        offset = 0 if same_clock else robot_ns - (send_local_ns + recv_local_ns) // 2
        sample = ClockSample(offset, rtt, recv_local_ns)
        best = self.best
        if (
            best is not None
            and abs(sample.offset_ns - best.offset_ns) > (sample.rtt_ns + best.rtt_ns) // 2 + _MS
        ):
            self._samples.clear()  # the robot's clock jumped: forget the old boot
        self._samples.append(sample)
        self.latest = sample
        return sample

    @property
    def best(self) -> ClockSample | None:
        """The sample with the smallest round trip in the window."""
        return min(self._samples, key=lambda s: s.rtt_ns, default=None)

    @property
    def synchronised(self) -> bool:
        return bool(self._samples)

    def robot_now(self, local_ns: int) -> int:
        """The robot's monotonic time now, or 0 (the wire's "unsynchronised") before a sample."""
        best = self.best
        if best is None:
            return 0
        # Clamped to the wire's range: a reply near 2**63 (any peer can answer the clock key)
        # made the command's stamp overflow it, and the operator died on its own command.
        return min(max(0, local_ns + best.offset_ns), MAX_INT)
