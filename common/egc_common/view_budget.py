"""The robot's downlink budget (DESIGN 12): keep the view plane below what the link carries.

Pure: frozen dataclasses, time passed in (monotonic ns), no IO. The robot node feeds it every
accepted command's reports and the bytes its view plane sent, and asks it for a plan each cycle.

**Why**: a thin downlink (a cellular uplink of the robot) usually sits behind a deep buffer.
Zenoh's priorities and DROP only act on Zenoh's own queues; once view data is in a socket or
in the link's buffer, the robot's state, clock replies and even the session's keep-alives wait
behind it (a standing queue longer than the lease closes the session). The only cure is to send
less than the link carries, so no queue stands.

**Signal** (delay-based, as LEDBAT and BBR do): the operator reports ``view_age_ms`` (and
``camera_age_ms``), the age on the robot's clock of the newest telemetry (frame) it shows. It
is the downlink's one-way delay + the queueing delay + the time since that message arrived
(up to one message period) + the clock-sync error. So

- ``current``: the smallest age reported over the last two and a half telemetry periods (at
  least ``short_s``; the camera's: one and a half frame periods): it removes the
  message-period sawtooth and no more, so a queue is seen within a few reports;
- ``base``: the smallest of those over the last ``base_s`` (10 s, in one-second buckets): the
  delay with no queue. The clock-sync error is in both and cancels; no symmetry between uplink
  and downlink is assumed (the commands' age, DESIGN 9, measures the uplink only);
- ``queue_ms = current - base``. The camera's age gives a second queue estimate the same way
  (its own base: a large frame's serialization time is in it and cancels); the larger counts.

**Control** (AIMD, as TCP): auto mode starts low (``start_kbps``, below most links, so the first
``base`` is a clean one) and

- *multiplicative decrease at once* when ``queue_ms > margin_ms``: the operator's ``rx_kbps``
  measured while a queue stands is what the link delivers (C), so the budget goes to
  ``beta`` times the smaller of it and the budget, with ``beta = 1 - queue / drain_s`` within
  [``min_beta``, ``max_beta``] (0.3-0.7): sending at C (1 - Q / T) for T drains a queue of Q
  seconds in about T (1 s), so a long queue gets a deep cut and a short one a mild cut. One cut,
  then
  ``hold_s`` (1 s, about one report round trip on a 500 ms link) before another unless the
  queue grew by half again: the reports lag the cut by a round trip, and cutting on each stale
  report would spiral down (the usual AIMD oscillation);
- *back to cruise* once the queue has drained (``queue_ms < margin_ms / 2``): a cut deep
  enough to drain a long queue quickly is too deep to stay at, so the budget returns at once
  to ``cruise`` (0.85) times the rate the link delivered at the last cut (BBR's drain, then
  cruise);
- *additive increase, slowly*, while the ages stay flat and ``hold_s`` after the last cut:
  ``ai_kbps`` per second between ``cruise`` and 1.1 times the rate at the last cut (where the
  last queue stood: the sawtooth's peak overshoots by little and comes seconds apart), and
  ``ai_kbps`` plus ``ai_fraction`` of the budget per second elsewhere (past it with the ages
  still flat: the link widened), only while the view plane actually fills the budget (a probe
  the data never used proves nothing). From 130 kbit/s that is 1.5 s to 300 kbit/s and 3 s to
  600 kbit/s, so the camera comes back within seconds after the link widens; a probe into a
  link that did not widen overshoots by the growth of one report round trip, a queue of tens
  of milliseconds, before the cut;
- the link estimate ``link_kbps`` is the ``rx_kbps`` at the last cut, raised by any higher
  ``rx_kbps`` received with no queue (the link widened); None until a queue was first seen.

A fixed ``downlink_kbps`` (``--downlink-kbps N``) skips all that: the budget is N.

**Plan**: what gives way first (DESIGN 12): camera quality and rate (down to 1 frame/s at
``camera_min_kbps``), then scan resolution (down to ``min_beams``), then telemetry rate (down
to ``min_telemetry_hz``), then the camera goes off. Control never: it is not in the budget.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, replace

NS_PER_S = 1_000_000_000


@dataclass(frozen=True, slots=True)
class BudgetConfig:
    """The budget's settings (see the module docstring); kbit/s, Hz, seconds, milliseconds."""

    downlink_kbps: float | None = None  # None: auto
    telemetry_hz: float = 20.0
    min_telemetry_hz: float = 5.0
    max_beams: int = 180
    min_beams: int = 45
    camera: bool = False  # is there a camera to feed
    camera_max_fps: float = 10.0
    camera_max_kbps: float = 400.0
    camera_min_kbps: float = 24.0  # 1 frame/s
    start_kbps: float = 96.0
    max_kbps: float = 1400.0
    floor_kbps: float = 32.0  # about what telemetry costs at 5 Hz with min_beams anyway
    margin_ms: float = 100.0
    drain_s: float = 1.0
    max_beta: float = 0.7
    min_beta: float = 0.3
    hold_s: float = 1.0
    ai_kbps: float = 16.0
    ai_fraction: float = 0.5
    cruise: float = 0.85
    short_s: float = 0.1
    base_s: float = 10.0

    def __post_init__(self) -> None:
        if self.downlink_kbps is not None and not 1.0 <= self.downlink_kbps <= 1e7:
            raise ValueError("downlink_kbps must be within [1, 10000000] kbit/s, or auto")
        if not 0 < self.min_telemetry_hz <= self.telemetry_hz <= 1000:
            raise ValueError("telemetry_hz must be within [min_telemetry_hz, 1000]")
        if self.min_beams < 1:
            raise ValueError("min_beams must be >= 1")
        if self.max_beams < 1:
            raise ValueError("max_beams must be >= 1")
        if not 0 < self.camera_min_kbps <= self.camera_max_kbps:
            raise ValueError("camera kbit/s: 0 < min <= max")
        if not self.camera_max_fps >= 1:
            raise ValueError("camera_max_fps must be >= 1")
        if not 0 < self.floor_kbps <= self.start_kbps <= self.max_kbps:
            raise ValueError("auto budget: 0 < floor_kbps <= start_kbps <= max_kbps")
        if not (0 < self.min_beta <= self.max_beta < 1):
            raise ValueError("0 < min_beta <= max_beta < 1")

    @property
    def fixed(self) -> bool:
        return self.downlink_kbps is not None


@dataclass(frozen=True, slots=True)
class Report:
    """What one accepted command of the operator in control reports (DESIGN 7, 12); None:
    not reported (an older operator, no camera, not synchronised)."""

    view_age_ms: float | None
    rx_kbps: float | None = None
    camera_age_ms: float | None = None


@dataclass(frozen=True, slots=True)
class _AgeFilter:
    """Short-window and base minima of one reported age (module docstring, "Signal")."""

    recent: tuple[tuple[int, float], ...] = ()  # (t_ns, age_ms) over the last short window
    buckets: tuple[tuple[int, float], ...] = ()  # (second, min age_ms) over the base window

    def add(self, now_ns: int, age_ms: float, short_ns: int, base_s: float) -> _AgeFilter:
        recent = (*(r for r in self.recent if now_ns - r[0] <= short_ns), (now_ns, age_ms))
        second = now_ns // NS_PER_S
        current = min(a for _, a in recent)
        kept = [b for b in self.buckets if second - b[0] < base_s]
        if kept and kept[-1][0] == second:
            kept[-1] = (second, min(kept[-1][1], current))
        else:
            kept.append((second, current))
        return _AgeFilter(recent, tuple(kept))

    def queue_ms(self) -> float | None:
        if not self.recent or not self.buckets:
            return None
        current = min(a for _, a in self.recent)
        return max(0.0, current - min(b for _, b in self.buckets))

    def base_ms(self) -> float | None:
        return min(b for _, b in self.buckets) if self.buckets else None


@dataclass(frozen=True, slots=True)
class BudgetState:
    """The estimate between reports."""

    budget_kbps: float
    link_kbps: float | None = None
    cut_rx_kbps: float | None = None  # what the link delivered at the last cut
    view: _AgeFilter = _AgeFilter()
    camera: _AgeFilter = _AgeFilter()
    queue_ms: float | None = None
    last_cut_ns: int | None = None
    queue_at_cut_ms: float = 0.0
    last_step_ns: int | None = None
    cuts: int = 0


@dataclass(frozen=True, slots=True)
class Plan:
    """What the view plane may send now: telemetry rate, scan beams, the camera's allotment
    (0 fps: off), and what gave way (``messages.BUDGET_CUTS`` names, in that order)."""

    budget_kbps: float
    telemetry_hz: float
    scan_beams: int
    camera_fps: float
    camera_kbps: float
    cut: tuple[str, ...]


def initial_state(cfg: BudgetConfig) -> BudgetState:
    budget = cfg.downlink_kbps if cfg.downlink_kbps is not None else cfg.start_kbps
    return BudgetState(budget_kbps=budget)


def on_report(
    state: BudgetState,
    cfg: BudgetConfig,
    report: Report,
    now_ns: int,
    camera_fps: float = 0.0,
    telemetry_hz: float | None = None,
) -> BudgetState:
    """One report of the operator in control; cuts at once when a queue stands. ``camera_fps``,
    ``telemetry_hz``: the plan in force (the windows that remove each stream's sawtooth)."""
    hz = telemetry_hz if telemetry_hz is not None and telemetry_hz > 0 else cfg.telemetry_hz
    short_ns = int(max(cfg.short_s, 2.5 / hz) * NS_PER_S)
    view, camera = state.view, state.camera
    if report.view_age_ms is not None:
        view = view.add(now_ns, report.view_age_ms, short_ns, cfg.base_s)
    if report.camera_age_ms is not None:
        # a camera frame every 1/fps: the short window must hold more than one
        cam_short_ns = max(short_ns, int(1.5 * NS_PER_S / camera_fps)) if camera_fps > 0 else 0
        if cam_short_ns:
            camera = camera.add(now_ns, report.camera_age_ms, cam_short_ns, cfg.base_s)
    queues = [q for q in (view.queue_ms(), camera.queue_ms()) if q is not None]
    queue = max(queues) if queues else None
    state = replace(state, view=view, camera=camera, queue_ms=queue)
    rx = report.rx_kbps
    link = state.link_kbps
    no_queue = queue is not None and queue < cfg.margin_ms / 2
    if link is not None and rx is not None and rx > link and no_queue:
        state = replace(state, link_kbps=rx)  # the link carries more than we thought
    if cfg.fixed or queue is None or queue <= cfg.margin_ms:
        return state
    since_cut = None if state.last_cut_ns is None else now_ns - state.last_cut_ns
    growing = queue > 1.5 * state.queue_at_cut_ms + cfg.margin_ms
    if since_cut is not None and since_cut < cfg.hold_s * NS_PER_S and not growing:
        return state  # the last cut has not reached the reports yet
    beta = min(cfg.max_beta, max(cfg.min_beta, 1.0 - queue / (cfg.drain_s * 1000.0)))
    delivered = state.budget_kbps if rx is None or rx <= 0 else min(rx, state.budget_kbps)
    measured = rx is not None and rx > 0
    return replace(
        state,
        budget_kbps=max(cfg.floor_kbps, beta * delivered),
        link_kbps=rx if measured else link,
        cut_rx_kbps=rx if measured else state.cut_rx_kbps,
        last_cut_ns=now_ns,
        queue_at_cut_ms=queue,
        cuts=state.cuts + 1,
    )


def on_cycle(
    state: BudgetState, cfg: BudgetConfig, now_ns: int, sent_kbps: float | None
) -> BudgetState:
    """Time passes: probe upward while the ages stay flat (module docstring, "Control")."""
    last = state.last_step_ns
    state = replace(state, last_step_ns=now_ns)
    if cfg.fixed or last is None or state.queue_ms is None:
        return state
    dt_s = min(max((now_ns - last) / NS_PER_S, 0.0), 0.5)
    if state.queue_ms >= cfg.margin_ms / 2:
        return state
    if state.last_cut_ns is not None and now_ns - state.last_cut_ns < cfg.hold_s * NS_PER_S:
        return state
    budget, at_cut = state.budget_kbps, state.cut_rx_kbps
    if at_cut is not None and budget < cfg.cruise * at_cut:
        return replace(state, budget_kbps=min(cfg.max_kbps, cfg.cruise * at_cut))
    if sent_kbps is None or sent_kbps < 0.7 * budget:
        return state  # the view plane does not use what it has: a probe would prove nothing
    near = at_cut is not None and budget <= 1.1 * at_cut
    rate = cfg.ai_kbps if near else cfg.ai_kbps + cfg.ai_fraction * budget
    return replace(state, budget_kbps=min(cfg.max_kbps, budget + rate * dt_s))


def telemetry_kbps(hz: float, beams: int, overhead_bytes: float) -> float:
    """Telemetry kbit/s at ``hz`` with a compact scan of ``beams`` (2 bytes each) on top of
    ``overhead_bytes`` (every other key, as the robot measures it)."""
    return hz * (overhead_bytes + 2.0 * beams) * 8.0 / 1000.0


def _beams_within(kbps: float, hz: float, overhead_bytes: float, cfg: BudgetConfig) -> int | None:
    """The most beams (``max_beams`` / k, whole k) at ``hz`` within ``kbps``; None: not even
    ``min_beams``."""
    for k in range(1, cfg.max_beams + 1):
        beams = math.ceil(cfg.max_beams / k)
        if beams < cfg.min_beams and k > 1:
            return None
        if telemetry_kbps(hz, beams, overhead_bytes) <= kbps:
            return beams
    return None


def plan(state: BudgetState, cfg: BudgetConfig, overhead_bytes: float) -> Plan:
    """The plan for ``state.budget_kbps`` (module docstring, "Plan")."""
    budget = state.budget_kbps
    hz_max = cfg.telemetry_hz
    min_beams = min(cfg.min_beams, cfg.max_beams)
    full = telemetry_kbps(hz_max, cfg.max_beams, overhead_bytes)
    camera = 0.0
    if cfg.camera:
        camera = min(cfg.camera_max_kbps, max(cfg.camera_min_kbps, budget - full))
        if telemetry_kbps(cfg.min_telemetry_hz, min_beams, overhead_bytes) > budget - camera:
            camera = 0.0  # last resort: the camera goes off before the view starves
    rest = budget - camera
    hz = hz_max
    beams = _beams_within(rest, hz, overhead_bytes, cfg)
    if beams is None:
        beams = min_beams
        per_message_kbit = telemetry_kbps(1.0, beams, overhead_bytes)
        hz = max(cfg.min_telemetry_hz, min(hz_max, rest / per_message_kbit))
    cut: list[str] = []
    if cfg.camera and camera < cfg.camera_max_kbps:
        cut.append("camera")
    if beams < cfg.max_beams:
        cut.append("scan")
    if hz < hz_max:
        cut.append("rate")
    return Plan(
        budget_kbps=budget,
        telemetry_hz=hz,
        scan_beams=beams,
        camera_fps=camera_fps(camera, cfg),
        camera_kbps=camera,
        cut=tuple(cut),
    )


def camera_fps(kbps: float, cfg: BudgetConfig) -> float:
    """Frames/s for a camera allotment: 1 at ``camera_min_kbps`` up to ``camera_max_fps`` at
    ``camera_max_kbps`` (linear); 0 below the minimum (off)."""
    if kbps < cfg.camera_min_kbps:
        return 0.0
    span = cfg.camera_max_kbps - cfg.camera_min_kbps
    share = 1.0 if span <= 0 else (kbps - cfg.camera_min_kbps) / span
    return 1.0 + share * (cfg.camera_max_fps - 1.0)


class RateMeter:
    """Bytes over a sliding window, as kbit/s (the robot's view plane sent, the operator's
    ``rx_kbps`` received). Time passed in; bounded (one entry per message of the window)."""

    def __init__(self, window_s: float = 1.0) -> None:
        if not window_s > 0:
            raise ValueError("window_s must be > 0")
        self._window_ns = int(window_s * NS_PER_S)
        self._entries: deque[tuple[int, int]] = deque()
        self._bytes = 0
        self.total_bytes = 0

    def add(self, now_ns: int, nbytes: int) -> None:
        if nbytes <= 0:
            return
        self._entries.append((now_ns, nbytes))
        self._bytes += nbytes
        self.total_bytes += nbytes
        self._expire(now_ns)

    def kbps(self, now_ns: int) -> float:
        """kbit/s over the window ending at ``now_ns``."""
        self._expire(now_ns)
        return self._bytes * 8.0 / 1000.0 / (self._window_ns / NS_PER_S)

    def _expire(self, now_ns: int) -> None:
        entries = self._entries
        while entries and now_ns - entries[0][0] >= self._window_ns:
            self._bytes -= entries.popleft()[1]
