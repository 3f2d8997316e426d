"""Link statistics on the robot's clock (DESIGN 7, 9), pure: time is passed in.

Fed with every decoded command of the operator in control (accepted or rejected as stale, since
both arrived) and with the accepted ones' ages, it reports over a sliding window (1 s):

- command age percentiles p50/p90 (arrival minus ``stamp_ns``, synchronised operators only);
- the largest gap between arrivals that ends in the window, including the gap still open now
  (so it grows during an outage, and a 2 s outage shows for a second after the link returns);
- loss from ``seq`` gaps: 1 - received / expected, expected = the span of ``seq`` over the window;
- the loop delay tau = p90 age + the operator's latest ``view_age_ms`` + ``reaction_time``,
  each unknown part counted as ``command_timeout`` (DESIGN 9).
"""

from __future__ import annotations

from bisect import bisect_left, insort
from collections import deque
from dataclasses import dataclass

NS_PER_MS = 1_000_000
NS_PER_S = 1_000_000_000


@dataclass(frozen=True, slots=True)
class LinkFigures:
    """One snapshot of the link as the robot sees it (None: not known yet)."""

    cmd_age_p50_ms: float | None
    cmd_age_p90_ms: float | None
    cmd_gap_max_ms: float | None
    link_loss: float | None
    view_age_ms: float | None
    loop_delay_s: float


class LinkStats:
    """Sliding-window statistics of one operator's command stream (see the module docstring)."""

    def __init__(
        self, window_s: float = 1.0, reaction_time_s: float = 0.25, unknown_part_s: float = 0.25
    ) -> None:
        if not (window_s > 0 and reaction_time_s >= 0 and unknown_part_s >= 0):
            raise ValueError("window_s must be > 0, the other times >= 0")
        self._window_ns = int(window_s * NS_PER_S)
        self._reaction_s = reaction_time_s
        self._unknown_s = unknown_part_s
        self._arrivals: deque[tuple[int, int]] = deque()  # (rx_ns, seq)
        self._ages: deque[tuple[int, int]] = deque()  # (rx_ns, age_ns) of accepted commands
        self._sorted_ages: list[int] = []  # the same ages, ascending
        self._view_age_ms: float | None = None
        self._last_rx_ns: int | None = None
        self._seq_before: int | None = None  # the last seq that left the window
        self._rx_before: int | None = None  # when that command arrived
        # Totals over the whole run (kept across sessions): commands that arrived, and seq
        # numbers skipped on the way (a late one that fills a gap takes one back).
        self.received_total = 0
        self.missing_total = 0
        self._max_seq: int | None = None

    def reset(self) -> None:
        """A new operator session: forget everything."""
        self._arrivals.clear()
        self._ages.clear()
        self._sorted_ages.clear()
        self._view_age_ms = None
        self._last_rx_ns = None
        self._seq_before = None
        self._rx_before = None
        self._max_seq = None  # a new session numbers from 1 again

    def on_arrival(self, seq: int, rx_ns: int) -> None:
        """A decoded command of the operator in control arrived (accepted or stale)."""
        self._arrivals.append((rx_ns, seq))
        self._last_rx_ns = rx_ns
        self.received_total += 1
        if self._max_seq is None or seq > self._max_seq:
            if self._max_seq is not None:
                self.missing_total += seq - self._max_seq - 1
            self._max_seq = seq
        elif seq < self._max_seq and self.missing_total > 0:
            self.missing_total -= 1

    def on_accepted(self, age_ns: int | None, view_age_ms: int | None, rx_ns: int) -> None:
        if age_ns is not None:
            # Stamped ahead of our clock (an operator's clock sync off, or a hostile one): the
            # link cannot be faster than instant, and a negative tau broke the governor.
            age_ns = max(age_ns, 0)
            self._ages.append((rx_ns, age_ns))
            insort(self._sorted_ages, age_ns)
        if view_age_ms is not None:
            self._view_age_ms = float(view_age_ms)

    @property
    def view_age_ms(self) -> float | None:
        """The operator's newest report of its view's age (as ``figures``)."""
        return self._view_age_ms

    def loop_delay_s(self, now_ns: int) -> float:
        """The loop delay tau at ``now_ns``, as ``figures(now_ns).loop_delay_s``.

        The latency governor needs it before the base command is sent; the other figures are
        only reported, so the robot computes them after the send (``figures``).
        """
        self._expire(now_ns)
        return self._tau(self._p90_ms())

    def figures(self, now_ns: int) -> LinkFigures:
        # Plain Python on purpose: the window holds ~50 commands, where numpy's per-call
        # overhead (~300 us from cold caches) cost more than the filter itself (bench link).
        self._expire(now_ns)
        ages = self._sorted_ages
        p50 = _percentile(ages, 0.5) / NS_PER_MS if ages else None
        p90 = self._p90_ms()
        gap_ms = None
        if self._last_rx_ns is not None:
            gap_ns = now_ns - self._last_rx_ns
            previous = self._rx_before
            for rx, _ in self._arrivals:
                if previous is not None and rx - previous > gap_ns:
                    gap_ns = rx - previous
                previous = rx
            gap_ms = gap_ns / NS_PER_MS
        loss = None
        if self._arrivals:
            seqs = {s for _, s in self._arrivals}
            first = min(seqs) if self._seq_before is None else self._seq_before + 1
            expected = max(seqs) - first + 1
            loss = min(max(1.0 - len(seqs) / expected, 0.0), 1.0) if expected > 0 else 0.0
        return LinkFigures(p50, p90, gap_ms, loss, self._view_age_ms, self._tau(p90))

    def _p90_ms(self) -> float | None:
        ages = self._sorted_ages
        return _percentile(ages, 0.9) / NS_PER_MS if ages else None

    def _tau(self, p90_ms: float | None) -> float:
        return (
            (p90_ms / 1e3 if p90_ms is not None else self._unknown_s)
            + (self._view_age_ms / 1e3 if self._view_age_ms is not None else self._unknown_s)
            + self._reaction_s
        )

    def _expire(self, now_ns: int) -> None:
        horizon = now_ns - self._window_ns
        while self._arrivals and self._arrivals[0][0] < horizon:
            self._rx_before, seq = self._arrivals.popleft()
            self._seq_before = seq if self._seq_before is None else max(self._seq_before, seq)
        while self._ages and self._ages[0][0] < horizon:
            _, age = self._ages.popleft()
            ages = self._sorted_ages
            del ages[bisect_left(ages, age)]


def _percentile(sorted_values: list[int], q: float) -> float:
    """Linear interpolation between closest ranks (numpy's default), of a sorted list."""
    pos = q * (len(sorted_values) - 1)
    lo = int(pos)
    hi = min(lo + 1, len(sorted_values) - 1)
    return sorted_values[lo] + (sorted_values[hi] - sorted_values[lo]) * (pos - lo)
