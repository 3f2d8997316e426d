"""The robot's downlink budget (DESIGN 12): keep the view plane below what the link carries.

Pure: frozen dataclasses, time passed in (monotonic ns), no IO. The robot node feeds it every
accepted command's reports and the bytes its view plane sent, and asks it for a plan each cycle.

**Why**: a thin downlink (a cellular uplink of the robot) usually sits behind a deep buffer.
Zenoh's priorities and DROP only act on Zenoh's own queues; once view data is in a socket or
in the link's buffer, the robot's state, clock replies and even the session's keep-alives wait
behind it (a standing queue longer than the lease closes the session). The only cure is to send
less than the link carries, so no queue stands.

**Signal** (delay-based, as LEDBAT and BBR do): the operator reports ``view_age_ms``, the age
on the robot's clock of the newest telemetry it shows. It is the downlink's one-way delay + the
queueing delay + the time since that message arrived (up to one message period) + the
clock-sync error. So

- ``current``: the smallest age reported over the last two and a half telemetry periods (at
  least ``short_s``): it removes the message-period sawtooth and no more, so a queue is seen
  within a few reports;
- ``base``: the smallest of those over the last ``base_s`` (10 s, in one-second buckets): the
  delay with no queue. The clock-sync error is in both and cancels; no symmetry between uplink
  and downlink is assumed (the commands' age, DESIGN 9, measures the uplink only);
- ``queue_ms = current - base``; unknown (no cut, no probe) until the reports in the short
  window span most of it: the first report after a gap (an operator that stalled on a busy
  machine; its view age holds the stall) must not count alone.

Each age holds the message's own time on the link (its bytes over the link's rate: 37 ms for
a 900-byte telemetry message at 192 kbit/s, 4 ms at 2 Mbit/s), which changes with the link
rather than with any queue: after the link narrows it would read as a queue that never drains
for as long as the base remembers the wide link (the budget stayed at its floor for seconds).
So a cut that finds the link slower than the base's (its rate below ``link_kbps``), or a
second's standing queue that does, raises the base by the difference in a message's time on
the link (at most ``margin_ms``). A base
raised too far comes back down by itself: it is a minimum, and the first ages with no queue
are lower. A link that widens needs nothing: its ages are lower.

The camera gives a second estimate, per frame: ``camera_age_ms`` is the age of the frame shown,
so ``stamp_ns - camera_age_ms`` (the report's own stamp, on the same estimate of the robot's
clock) is that frame's capture stamp. The first report that names a new frame carries the
frame's latency (capture to shown: encoding, the link, decoding, up to one report period more);
later reports of the same frame only say that no newer one came, which is no queue (the camera
slowed, stopped or is off: counting its growing age as a queue would cut the budget further and
the camera would never come back). The latencies of the frames shown over the last two and a
half frame periods (two at least, so one late frame is no queue), against their own 10 s base,
give the camera's queue; it counts only while frames keep coming at two a second or more (at
one a second a queue would be seen a second late: the telemetry's is earlier), and the larger
of the two estimates counts. It sees what the telemetry cannot: the operator's decoder falling
behind, camera frames waiting in the robot's lowest-priority queue.

**Control** (AIMD, as TCP): auto mode starts low (``start_kbps``, below most links, so the first
``base`` is a clean one) and

- *multiplicative decrease at once* when ``queue_ms > margin_ms``: the operator's ``rx_kbps``
  measured while a queue stands is what the link delivers (C); but it is a second's worth,
  and just after the link narrowed most of that second was the wider link. A queue that grows
  by r ms a millisecond (the short-window minimum over the last 0.1 s, in the reports'
  time; from 0.3 on: a link that narrowed, not a probe's overshoot) is fed at the view plane's
  rate S and drained at S (1 - r), which is known at once:
  C is the smaller of the two (S: the view plane's rate at the first cut in a while, which
  built the queue the next reports still show). The queue the reports show is a round trip old; growing so, it is S / C - 1 times
  that round trip (twice the base age) longer in the link already. The budget goes to
  ``beta`` times the smaller of it and the budget, with ``beta = 1 - queue / drain_s`` within
  [``min_beta``, ``max_beta``] (0.3-0.8): sending at C (1 - Q / T) for T drains a queue of Q
  seconds in about T (1 s), so a long queue gets a deep cut and a short one a mild cut (0.8
  of 180 kbit/s keeps a working camera). One cut, then ``hold_s`` (1 s, about one report round
  trip on a 500 ms link) before another unless the queue doubled: the reports lag the cut by a
  round trip, the queue they show grows meanwhile, and cutting on each stale report would
  spiral down (the usual AIMD oscillation);
- *a drain* when the link narrowed: the first cut in a while that finds the queue growing
  fast (faster than ``_FAST_GROWTH``, 0.3 ms a ms: a probe's overshoot grows at 0.1) sends
  the budget to ``floor_kbps`` at once (the camera pauses, telemetry at its least) until the
  queue has drained. Every byte sent above the link's rate until the cut takes effect waits in
  its buffer: 400 kbit/s into 128 adds 2.1 ms of queue a ms, so each 100 ms of sending at the
  old rate costs 0.3 s of drain, and a cut still above the link (0.8 of a second of
  ``rx_kbps``, most of it the wide link's) keeps adding to it; its depth must not hang on how
  well a few reports' slope tells C. That slope also misjudges a queue that grows in steps
  (a large camera frame's time on the link, then the messages behind it at once: the
  short-window minimum is flat for a while), so the growth is the larger of the slope over
  0.1 s and the mean rise since the last report with no queue (``_CALM``). Measured with
  ``bench bandwidth --scenario`` (2 Mbit/s -> 128 kbit/s, 80 ms): the first cut went to
  140-210 kbit/s in three runs of four and the view age was back under 280 ms 2.4-3.3 s after
  the change; drained at the floor, after 1.8-2.0 s in four runs (load 4-8 on 2 cores), with
  the camera and the 192 and 128 kbit/s figures as before;
- *back to cruise* once the queue has drained (``queue_ms < margin_ms / 2``): a cut deep
  enough to drain a long queue quickly is too deep to stay at, so the budget returns at once
  to ``cruise`` (0.85) times the rate the link delivered at the last cut (BBR's drain, then
  cruise); after a drain, the smaller of the estimate at the cut (what the growth says the
  link delivers) and the operator's last second (the link was busy for most of it), never
  raised by a second of ``rx_kbps`` during the drain (a frame that arrived whole within it
  makes it look larger than the link, and cruising above the link refills the queue); the
  drain ends at once, within the hold;
- *additive increase*, while the ages stay flat and ``hold_s`` after the last cut, and only
  while the view plane actually fills the budget (a probe the data never used proves nothing):
  ``ai_kbps`` per second up to 1.1 times the rate at the last cut (where the last queue stood:
  the sawtooth's peak overshoots it by little and comes seconds apart); past it (or before any
  cut), ``ai_kbps`` per second at first and twice as much with every second the ages stay flat
  (``ai_kbps`` plus ``ai_fraction`` of the budget per second at most): a link that did not
  widen sees a probe of a few kbit/s too many for one report round trip, a queue of tens of
  milliseconds; one that widened is found within seconds (from 140 kbit/s: 5 s to 600 kbit/s);
- *a deficit* cuts too, with or without ages: when the operator's ``rx_kbps`` stays below
  three quarters of what the view plane sent for two seconds, the link carries less, and the
  budget goes to 0.8 of ``rx_kbps``. A link narrower than ``start_kbps`` (64 kbit/s) has a
  queue before the first report: the operator's clock replies wait behind it, so no ages come
  for seconds, and those that come have the queue in their base (it reads as none);
- *a cut taken back* when its queue vanishes faster than a link can drain one: bytes in a queue
  leave at the link's rate, one millisecond of queue per millisecond at best, and until the
  cut's effect comes back through the queue the robot still sends at the rate that built it
  (so within the queue's own length after the cut, a link queue drains no faster). A "queue"
  of 300 ms gone 20 ms later in the operator's reports (their stamps) was no queue: a process
  stalled on a busy machine, a delay spike of the link itself. The cut is undone (budget, link
  estimate, raised base); the hold stays. Only the telemetry's estimate is judged so, over the
  window it had at the cut (a slower telemetry rate widens it to older, lower ages), only for
  cuts it made, and only for a cut two holds after the one before (whose lower rate may
  already be draining the queue, faster than a millisecond a millisecond);
- the link estimate ``link_kbps`` is the rate at the last cut, raised by any higher
  ``rx_kbps`` received with no queue (the link widened); None until a queue was first seen.
  Once a queue has stood for a whole second (all of ``rx_kbps``'s window, and twice the base
  age more: the bytes on their way when the link narrowed came at the old rate), the link was
  busy all that second whatever the robot sent, so ``rx_kbps`` is its rate: it becomes the link
  estimate and the rate cruise returns to (after the link narrowed, the cuts' rates were a
  mix of the wide link's last second and of the drain's).

A fixed ``downlink_kbps`` (``--downlink-kbps N``) skips all that: the budget is N.

**Plan**: what gives way first (DESIGN 12): camera quality and rate, down to a working camera
(``camera_keep_kbps``: 7 frames/s of 1 kB H.264 frames); then scan resolution (down to
``min_beams``); then telemetry rate, down to ``mid_telemetry_hz`` (10 Hz); then the camera below
its working rate (down to ``camera_min_kbps``, one JPEG frame a second); then telemetry down to
``min_telemetry_hz`` (5 Hz); then the camera goes off. So a thin link (a 192 kbit/s cellular
uplink) keeps a camera at 7 frames/s beside a coarser, slower scan; only a thinner one costs the
camera its rate. Control never: it is not in the budget. The camera's rate follows its kbit/s
(``camera_fps``), in whole frames a second so the encoder is not reopened at every step.
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
    mid_telemetry_hz: float = 10.0  # telemetry's rate gives way to here before the camera's
    min_telemetry_hz: float = 5.0
    max_beams: int = 180
    min_beams: int = 45
    camera: bool = False  # is there a camera to feed
    camera_max_fps: float = 10.0
    camera_max_kbps: float = 250.0
    camera_keep_kbps: float = 56.0  # a working camera: 7 frames/s of ~1 kB
    camera_keep_fps: float = 7.0
    camera_min_kbps: float = 12.0  # 1 frame/s (a small JPEG)
    start_kbps: float = 128.0
    max_kbps: float = 1400.0
    floor_kbps: float = 32.0  # about what telemetry costs at 5 Hz with min_beams anyway
    margin_ms: float = 100.0
    drain_s: float = 1.0
    max_beta: float = 0.8
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
        if not 0 < self.min_telemetry_hz <= self.mid_telemetry_hz:
            raise ValueError("mid_telemetry_hz must be >= min_telemetry_hz")
        if not 0 < self.camera_min_kbps <= self.camera_keep_kbps <= self.camera_max_kbps:
            raise ValueError("camera kbit/s: 0 < min <= keep <= max")
        if not self.camera_max_fps >= 1 or not self.camera_keep_fps >= 1:
            raise ValueError("camera_max_fps and camera_keep_fps must be >= 1")
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
    stamp_ns: int | None = None  # the command's stamp: the robot's clock when the ages were read


@dataclass(frozen=True, slots=True)
class _AgeFilter:
    """Short-window and base minima of one reported age (module docstring, "Signal")."""

    recent: tuple[tuple[int, float], ...] = ()  # (t_ns, age_ms) over the last short window
    buckets: tuple[tuple[int, float], ...] = ()  # (second, min age_ms) over the base window
    trend: tuple[tuple[int, float], ...] = ()  # (t_ns, short-window minimum), the last 0.2 s

    def add(self, now_ns: int, age_ms: float, short_ns: int, base_s: float) -> _AgeFilter:
        recent = (*(r for r in self.recent if now_ns - r[0] <= short_ns), (now_ns, age_ms))
        second = now_ns // NS_PER_S
        current = min(a for _, a in recent)
        kept = [b for b in self.buckets if second - b[0] < base_s]
        if kept and kept[-1][0] == second:
            kept[-1] = (second, min(kept[-1][1], current))
        else:
            kept.append((second, current))
        trend = (*(e for e in self.trend if now_ns - e[0] <= _TREND_NS), (now_ns, current))
        return _AgeFilter(recent, tuple(kept), trend)

    def growth(self) -> float | None:
        """How fast the short-window minimum grew (ms a ms) over the last 0.1 s (or a little
        more); None with less history."""
        if not self.trend:
            return None
        t_now, now = self.trend[-1]
        old = [(t, a) for t, a in self.trend if t_now - t >= _TREND_NS // 2]
        if not old:
            return None
        t_old, then = old[-1]  # the newest at least 0.1 s old: the slope now, not before it
        return (now - then) / ((t_now - t_old) / 1e6)

    def queue_ms(
        self, now_ns: int, window_ns: int, min_samples: int = 1, cover: float = 0.0
    ) -> float | None:
        """The minimum over the last ``window_ns`` less the base; None (no evidence either way)
        with fewer than ``min_samples`` in the window, or when they span less than ``cover``
        of it: after a gap in the reports (an operator whose process stalled) the first report
        must not count alone."""
        recent = [(t, a) for t, a in self.recent if now_ns - t <= window_ns]
        if len(recent) < min_samples or not self.buckets:
            return None
        if now_ns - recent[0][0] < cover * window_ns:
            return None
        return max(0.0, min(a for _, a in recent) - min(b for _, b in self.buckets))

    def base_ms(self) -> float | None:
        return min(b for _, b in self.buckets) if self.buckets else None

    def raised(self, delta_ms: float) -> _AgeFilter:
        """The base raised by ``delta_ms`` (the link got slower: module docstring, "Signal");
        lowered by a negative one (a cut taken back)."""
        if delta_ms == 0:
            return self
        return replace(self, buckets=tuple((s, b + delta_ms) for s, b in self.buckets))


@dataclass(frozen=True, slots=True)
class BudgetState:
    """The estimate between reports."""

    budget_kbps: float
    link_kbps: float | None = None
    cut_rx_kbps: float | None = None  # what the link delivered at the last cut
    view: _AgeFilter = _AgeFilter()
    camera: _AgeFilter = _AgeFilter()  # one sample per frame shown: its latency
    camera_shown_ns: int | None = None  # the capture stamp of the frame shown at the last report
    queue_ms: float | None = None  # the larger of the two estimates
    camera_queue_ms: float | None = None  # the camera's, while it counts
    last_cut_ns: int | None = None
    queue_at_cut_ms: float = 0.0
    last_step_ns: int | None = None
    beyond_ns: int | None = None  # since when the probe is past 1.1 times the last cut's rate
    undo: _Undo | None = None  # how to take the last cut back (module docstring, "Control")
    fed_kbps: float | None = None  # what the view plane sent before the first cut of a series
    queue_since_ns: int | None = None  # since when a queue (above margin_ms / 2) stands
    deficit_since_ns: int | None = None  # since when, with no ages, rx_kbps is short of sent
    calm_ns: int | None = None  # the last report with the telemetry's queue near none ...
    calm_queue_ms: float = 0.0  # ... and that queue
    draining: bool = False  # the link narrowed: the view plane at its floor until the queue drains
    cuts: int = 0
    undone: int = 0


@dataclass(frozen=True, slots=True)
class _Undo:
    """The last cut: the stamp of the report that made it, the telemetry's queue it saw (over
    the window then: a window that widens with a slower telemetry rate holds older, lower ages)
    and what it changed."""

    stamp_ns: int
    queue_ms: float
    window_ns: int
    budget_kbps: float
    link_kbps: float | None
    cut_rx_kbps: float | None
    view_raise_ms: float
    camera_raise_ms: float


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
    telemetry_bytes: float = 0.0  # one telemetry message as planned


def initial_state(cfg: BudgetConfig) -> BudgetState:
    budget = cfg.downlink_kbps if cfg.downlink_kbps is not None else cfg.start_kbps
    return BudgetState(budget_kbps=budget)


def on_report(
    state: BudgetState,
    cfg: BudgetConfig,
    report: Report,
    now_ns: int,
    in_force: Plan | None = None,
    sent_kbps: float | None = None,
) -> BudgetState:
    """One report of the operator in control; cuts at once when a queue stands. ``in_force``:
    the plan the robot follows (its rates set the windows that remove each stream's sawtooth,
    its sizes what a slower link adds to each age; None: ``cfg``'s full rates); ``sent_kbps``:
    what the view plane sent over the last second (how fast a growing queue says the link
    delivers)."""
    hz = in_force.telemetry_hz if in_force is not None else cfg.telemetry_hz
    camera_fps = in_force.camera_fps if in_force is not None else 0.0
    short_ns = int(max(cfg.short_s, 2.5 / max(hz, 1e-3)) * NS_PER_S)
    view, camera, shown = state.view, state.camera, state.camera_shown_ns
    if report.view_age_ms is not None:
        view = view.add(now_ns, report.view_age_ms, short_ns, cfg.base_s)
    cam_short_ns = max(short_ns, int(2.5 * NS_PER_S / camera_fps)) if camera_fps > 0 else 0
    if report.camera_age_ms is not None and report.stamp_ns is not None:
        frame_ns = report.stamp_ns - int(report.camera_age_ms * 1e6)
        # A new frame is at least half a frame period newer (a few ms of rounding and of the
        # clock estimate moving between the two reads are not one).
        new = shown is None or frame_ns > shown + _new_frame_ns(cfg)
        shown = frame_ns if shown is None else max(shown, frame_ns)
        if new and cam_short_ns:
            camera = camera.add(now_ns, report.camera_age_ms, cam_short_ns, cfg.base_s)
    flowing = camera_fps >= _CAMERA_SIGNAL_FPS and cam_short_ns > 0
    camera_queue = camera.queue_ms(now_ns, cam_short_ns, min_samples=2) if flowing else None
    view_queue = view.queue_ms(now_ns, short_ns, cover=_COVER)
    queues = [q for q in (view_queue, camera_queue) if q is not None]
    queue = max(queues) if queues else None
    if view_queue is not None and view_queue <= cfg.margin_ms * _CALM:
        state = replace(state, calm_ns=now_ns, calm_queue_ms=view_queue)
    state = replace(
        state,
        view=view,
        camera=camera,
        camera_shown_ns=shown,
        queue_ms=queue,
        camera_queue_ms=camera_queue,
    )
    undo = state.undo
    if undo is not None and report.stamp_ns is not None:
        same_window = view.queue_ms(now_ns, undo.window_ns, cover=_COVER)
        if same_window is not None:
            state = _maybe_undo(state, cfg, undo, same_window, report.stamp_ns)
    rx = report.rx_kbps
    link = state.link_kbps
    no_queue = queue is not None and queue < cfg.margin_ms / 2
    if state.draining and no_queue:
        state = _drained(state, cfg, rx)
    if link is not None and rx is not None and rx > link and no_queue:
        state = replace(state, link_kbps=rx)  # the link carries more than we thought
    if queue is not None and not no_queue:
        since = state.queue_since_ns if state.queue_since_ns is not None else now_ns
        state = replace(state, queue_since_ns=since)
        # rx_kbps's second, and the bytes that were on their way (the delay: the base age)
        # when the queue began, some sent at the rate before
        whole_ns = _RX_WINDOW_NS + int(2e6 * (view.base_ms() or 0.0))
        if rx is not None and rx > 0 and now_ns - since >= whole_ns:
            # a queue has stood for all of rx_kbps's second: the link was busy, rx is its rate
            state, _, _ = _on_slower_link(state, cfg, in_force, link, rx)
            at_cut = state.cut_rx_kbps
            if state.draining and at_cut is not None:
                at_cut = min(at_cut, rx)  # a drain never raises where cruise returns to
            else:
                at_cut = rx
            state = replace(state, link_kbps=rx, cut_rx_kbps=at_cut)
    elif queue is not None:
        state = replace(state, queue_since_ns=None)
    if not cfg.fixed:
        state = _deficit(state, cfg, rx, sent_kbps, now_ns)
    if cfg.fixed or queue is None or queue <= cfg.margin_ms:
        return state
    if state.budget_kbps <= cfg.floor_kbps:
        return state  # nothing left to cut (and the hold must not start again)
    since_cut = None if state.last_cut_ns is None else now_ns - state.last_cut_ns
    growing = queue > 2.0 * state.queue_at_cut_ms + cfg.margin_ms
    if since_cut is not None and since_cut < cfg.hold_s * NS_PER_S and not growing:
        return state  # the last cut has not reached the reports yet
    measured = rx if rx is not None and rx > 0 else None  # what the link delivered, measured
    rate = measured  # and what it delivers now, as well as can be told
    growth = _growth(state, view, view_queue, now_ns)
    ahead_ms = queue  # the queue in the link now: the reports show it a round trip late
    # The first cut in a while: the view plane sent at the rate S that built this queue; the
    # cuts right after it still see the queue that rate built.
    settled = since_cut is None or since_cut > 2 * cfg.hold_s * NS_PER_S
    fed = sent_kbps if settled else state.fed_kbps
    # The link narrowed (a queue that grows fast, not a probe's overshoot) under the rate that
    # built the queue: drain (module docstring, "Control").
    drain = settled and bool(fed) and growth is not None and growth > _FAST_GROWTH
    if fed and fed > 0 and growth is not None and growth > _FAST_GROWTH:
        # A queue growing by r ms a ms (in the reports' time) is fed at S and drained at
        # S (1 - r): what the link delivers now, before rx_kbps (a second's worth) shows it.
        r = min(growth, 0.9)
        rate = fed * (1.0 - r) if rate is None else min(rate, fed * (1.0 - r))
        # and it grew by S / C - 1 = r / (1 - r) ms a ms over the round trip since (about
        # twice the base age: the downlink's delay each way)
        ahead_ms += r / (1.0 - r) * 2.0 * (view.base_ms() or 0.0)
    beta = min(cfg.max_beta, max(cfg.min_beta, 1.0 - ahead_ms / (cfg.drain_s * 1000.0)))
    delivered = state.budget_kbps if rate is None else min(rate, state.budget_kbps)
    # The link's estimate moves on measurements only (the growth's rate is a few reports'
    # slope: good for how deep to cut, too noisy for a base or for where cruise returns to).
    view_raise = camera_raise = 0.0
    if measured is not None:
        state, view_raise, camera_raise = _on_slower_link(state, cfg, in_force, link, measured)
    undo = None
    if settled and report.stamp_ns is not None and view_queue and view_queue > cfg.margin_ms:
        undo = _Undo(  # a cut the telemetry's age made (the camera's has no undo)
            report.stamp_ns,
            view_queue - view_raise,  # what the raised base leaves of it
            short_ns,
            state.budget_kbps,
            link,
            state.cut_rx_kbps,
            view_raise,
            camera_raise,
        )
    at_cut = state.cut_rx_kbps if measured is None else measured
    return replace(
        state,
        budget_kbps=cfg.floor_kbps if drain else max(cfg.floor_kbps, beta * delivered),
        draining=state.draining or drain,
        link_kbps=link if measured is None else measured,
        cut_rx_kbps=rate if drain else at_cut,
        last_cut_ns=now_ns,
        queue_at_cut_ms=queue,
        beyond_ns=None,
        undo=undo,
        fed_kbps=fed,
        cuts=state.cuts + 1,
    )


def _drained(state: BudgetState, cfg: BudgetConfig, rx: float | None) -> BudgetState:
    """The queue a narrowing left has drained: cruise at what the link delivers, the smaller
    of the estimate at the cut and the operator's last second (the link was busy for most of
    it, so rx_kbps is about its rate; a frame that came whole within the second may add some)."""
    at_cut = state.cut_rx_kbps
    if rx is not None and rx > 0:
        at_cut = rx if at_cut is None else min(at_cut, rx)
    if at_cut is None:
        return replace(state, draining=False)
    budget = min(cfg.max_kbps, max(state.budget_kbps, cfg.cruise * at_cut))
    return replace(state, draining=False, budget_kbps=budget, cut_rx_kbps=at_cut)


_DEFICIT = 0.75  # with no ages: rx_kbps below this share of what was sent ...
_DEFICIT_NS = 2 * NS_PER_S  # ... for this long is a link that carries less


def _deficit(
    state: BudgetState,
    cfg: BudgetConfig,
    rx: float | None,
    sent_kbps: float | None,
    now_ns: int,
) -> BudgetState:
    """When the operator receives well below what the view plane sends, for two seconds
    (longer than its rx_kbps window and the delay), the link carries less: the budget goes
    below what it delivers (module docstring, "Control"). No clock needed: it works before the
    operator's clock is synchronised, and when the ages' base holds a queue already."""
    if rx is None or not sent_kbps or rx >= _DEFICIT * sent_kbps:
        return replace(state, deficit_since_ns=None) if state.deficit_since_ns else state
    since = state.deficit_since_ns if state.deficit_since_ns is not None else now_ns
    held = state.last_cut_ns is not None and now_ns - state.last_cut_ns < cfg.hold_s * NS_PER_S
    if now_ns - since < _DEFICIT_NS or held or state.budget_kbps <= cfg.floor_kbps:
        return replace(state, deficit_since_ns=since)
    return replace(
        state,
        budget_kbps=max(cfg.floor_kbps, min(state.budget_kbps, cfg.max_beta * rx)),
        link_kbps=rx,
        cut_rx_kbps=rx,
        last_cut_ns=now_ns,
        beyond_ns=None,
        deficit_since_ns=None,
        cuts=state.cuts + 1,
    )


_DRAIN_SLACK_MS = 30.0  # the link's jitter and a report period


def _maybe_undo(
    state: BudgetState, cfg: BudgetConfig, undo: _Undo, queue_ms: float, stamp_ns: int
) -> BudgetState:
    """Take the last cut back when its queue vanished faster than a link drains one (module
    docstring, "Control"); forget it once that can no longer be told."""
    elapsed_ms = (stamp_ns - undo.stamp_ns) / 1e6
    if elapsed_ms < 0:
        return state
    if elapsed_ms > min(undo.queue_ms, cfg.hold_s * 1000.0):
        return replace(state, undo=None)
    if undo.queue_ms - queue_ms <= elapsed_ms + _DRAIN_SLACK_MS:
        return state
    return replace(
        state,
        budget_kbps=undo.budget_kbps,
        link_kbps=undo.link_kbps,
        cut_rx_kbps=undo.cut_rx_kbps,
        view=state.view.raised(-undo.view_raise_ms),
        camera=state.camera.raised(-undo.camera_raise_ms),
        undo=None,
        undone=state.undone + 1,
        draining=False,
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
        return replace(state, beyond_ns=None)  # a queue begins: no faster probe from here
    if state.last_cut_ns is not None and now_ns - state.last_cut_ns < cfg.hold_s * NS_PER_S:
        return state
    budget, at_cut = state.budget_kbps, state.cut_rx_kbps
    if at_cut is not None and budget < cfg.cruise * at_cut:
        return replace(state, budget_kbps=min(cfg.max_kbps, cfg.cruise * at_cut))
    if sent_kbps is None or sent_kbps < 0.7 * budget:
        # the view plane does not use what it has: a probe would prove nothing
        return replace(state, beyond_ns=None)
    if at_cut is not None and budget <= 1.1 * at_cut:
        rate, beyond = cfg.ai_kbps, None
    else:
        beyond = now_ns if state.beyond_ns is None else state.beyond_ns
        doubled = cfg.ai_kbps * 2.0 ** min(20.0, (now_ns - beyond) / NS_PER_S)
        rate = min(doubled, cfg.ai_kbps + cfg.ai_fraction * budget)
    return replace(state, budget_kbps=min(cfg.max_kbps, budget + rate * dt_s), beyond_ns=beyond)


# A queue growing faster than this (ms a ms) is a link that narrowed, not a probe's overshoot
# (10-20 %) nor the slope's noise over 0.1 s (+-0.2): a link at half the rate gives 0.5.
_FAST_GROWTH = 0.3
_RX_WINDOW_NS = NS_PER_S  # rx_kbps: the operator's last second (DESIGN 12)
_TREND_NS = 200_000_000  # the queue's growth: over the last 0.1 s, from entries this old
_CALM = 0.25  # a telemetry queue below this share of margin_ms is none (the rise's start)
_RISE_NS = NS_PER_S  # the rise from the last calm report counts when it is this recent


def _growth(
    state: BudgetState, view: _AgeFilter, view_queue: float | None, now_ns: int
) -> float | None:
    """How fast the telemetry's queue grows (ms a ms, in the reports' time): the larger of its
    slope over the last 0.1 s and its mean rise since the last calm report (within a second).
    The slope alone misses a link that narrowed under a stream of large frames: the queue then
    grows in steps (a frame's time on the link, then the messages behind it at once), and 0.1 s
    of the short-window minimum may hold a step's flat part."""
    slope = view.growth()
    calm = state.calm_ns
    if view_queue is None or calm is None or not 0 < now_ns - calm <= _RISE_NS:
        return slope
    rise = (view_queue - state.calm_queue_ms) / ((now_ns - calm) / 1e6)
    return rise if slope is None else max(slope, rise)


_CAMERA_SIGNAL_FPS = 2.0  # the camera's latencies count as a queue signal from this rate up
_COVER = 0.6  # the reports in the view's short window must span this much of it


def _on_slower_link(
    state: BudgetState,
    cfg: BudgetConfig,
    in_force: Plan | None,
    old_kbps: float | None,
    new_kbps: float,
) -> tuple[BudgetState, float, float]:
    """The bases raised for a link found slower (module docstring, "Signal"), and by how much
    (the telemetry's, the camera's)."""
    if in_force is None or (old_kbps is not None and new_kbps >= old_kbps):
        return state, 0.0, 0.0
    fps = in_force.camera_fps
    frame_bytes = in_force.camera_kbps * 125.0 / fps if fps > 0 else 0.0
    view_raise = _slower_link_ms(in_force.telemetry_bytes, old_kbps, new_kbps, cfg.margin_ms)
    camera_raise = _slower_link_ms(frame_bytes, old_kbps, new_kbps, cfg.margin_ms)
    raised = replace(
        state, view=state.view.raised(view_raise), camera=state.camera.raised(camera_raise)
    )
    return raised, view_raise, camera_raise


def _slower_link_ms(nbytes: float, old_kbps: float | None, new_kbps: float, cap_ms: float) -> float:
    """How much longer a message of ``nbytes`` takes at ``new_kbps`` than at ``old_kbps`` (None:
    a fast link), within [0, ``cap_ms``] (module docstring, "Signal")."""
    if nbytes <= 0 or new_kbps <= 0:
        return 0.0
    old_ms = 0.0 if old_kbps is None or old_kbps <= 0 else nbytes * 8.0 / old_kbps
    return min(cap_ms, max(0.0, nbytes * 8.0 / new_kbps - old_ms))


def _new_frame_ns(cfg: BudgetConfig) -> int:
    return int(min(0.02, 0.5 / cfg.camera_max_fps) * NS_PER_S)


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
    hz_mid = min(cfg.mid_telemetry_hz, hz_max)
    min_beams = min(cfg.min_beams, cfg.max_beams)

    def tel(hz: float, beams: int) -> float:
        return telemetry_kbps(hz, beams, overhead_bytes)

    camera = 0.0
    if cfg.camera:
        keep, low = cfg.camera_keep_kbps, cfg.camera_min_kbps
        if budget >= tel(hz_max, cfg.max_beams) + keep:  # the camera's quality and rate
            camera = min(cfg.camera_max_kbps, budget - tel(hz_max, cfg.max_beams))
        elif budget >= tel(hz_mid, min_beams) + keep:  # the scan, then telemetry to hz_mid
            camera = keep
        elif budget >= tel(hz_mid, min_beams) + low:  # the camera below its working rate
            camera = budget - tel(hz_mid, min_beams)
        elif budget >= tel(cfg.min_telemetry_hz, min_beams) + low:  # telemetry to its least
            camera = low
        # else: the camera goes off before the view starves
    rest = budget - camera
    hz = hz_max
    beams = _beams_within(rest, hz, overhead_bytes, cfg)
    if beams is None:
        beams = min_beams
        per_message_kbit = tel(1.0, beams)
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
        telemetry_bytes=overhead_bytes + 2.0 * beams,
    )


def camera_fps(kbps: float, cfg: BudgetConfig) -> float:
    """Frames/s for a camera allotment: whole frames a second at ``camera_keep_kbps /
    camera_keep_fps`` kbit a frame (5 frames/s at the working rate), at least 1 and at most
    ``camera_max_fps`` (more kbit/s than that buys quality); 0 below ``camera_min_kbps`` (off)."""
    if not kbps >= cfg.camera_min_kbps:
        return 0.0
    frame_kbit = cfg.camera_keep_kbps / cfg.camera_keep_fps
    return float(min(cfg.camera_max_fps, max(1, math.floor(kbps / frame_kbit + 1e-9))))


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
