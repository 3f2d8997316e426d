"""The downlink budget (DESIGN 12, ``egc_common.view_budget``): the plan's order of giving way,
the AIMD steps, and a closed loop against a fluid model of a link with a deep buffer."""

from __future__ import annotations

import itertools
import random
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import pytest
from egc_common.view_budget import (
    BudgetConfig,
    BudgetState,
    Plan,
    RateMeter,
    Report,
    camera_fps,
    initial_state,
    on_cycle,
    on_report,
    plan,
    telemetry_kbps,
)

NS = 1_000_000_000
MS = 1_000_000
OVERHEAD = 700.0  # telemetry bytes besides the scan, as measured on the demo


def test_plan_gives_way_in_design_order() -> None:
    """Camera quality and rate first down to a working camera (5 frames/s), then scan
    resolution, then telemetry rate to 10 Hz, then the camera to 1 frame/s, then telemetry to
    5 Hz, camera off last."""
    cfg = BudgetConfig(camera=True, max_beams=180)
    full_tel = telemetry_kbps(20, 180, OVERHEAD)

    def at(kbps: float) -> Plan:
        return plan(BudgetState(budget_kbps=kbps), cfg, OVERHEAD)

    top = at(full_tel + cfg.camera_max_kbps + 50)
    assert top.cut == () and top.camera_fps == cfg.camera_max_fps and top.scan_beams == 180
    camera_cut = at(full_tel + 100)
    assert camera_cut.cut == ("camera",)
    assert camera_cut.camera_fps == cfg.camera_max_fps  # fewer bits a frame first
    assert camera_cut.camera_kbps < cfg.camera_max_kbps and camera_cut.scan_beams == 180
    slower = at(full_tel + 10 + cfg.camera_keep_kbps)
    assert slower.cut == ("camera",) and 5 <= slower.camera_fps < cfg.camera_max_fps
    scan_cut = at(telemetry_kbps(20, 90, OVERHEAD) + cfg.camera_keep_kbps + 1)
    assert scan_cut.cut == ("camera", "scan")
    assert scan_cut.camera_fps == cfg.camera_keep_fps and scan_cut.scan_beams == 90
    rate_cut = at(telemetry_kbps(12, cfg.min_beams, OVERHEAD) + cfg.camera_keep_kbps)
    assert rate_cut.cut == ("camera", "scan", "rate")
    assert rate_cut.scan_beams == cfg.min_beams and rate_cut.telemetry_hz == pytest.approx(12)
    assert rate_cut.camera_fps == cfg.camera_keep_fps  # the camera keeps working down to here
    camera_slower = at(telemetry_kbps(10, cfg.min_beams, OVERHEAD) + cfg.camera_keep_kbps - 20)
    assert 1 <= camera_slower.camera_fps < cfg.camera_keep_fps
    assert camera_slower.telemetry_hz == pytest.approx(10)
    one_fps = at(telemetry_kbps(7, cfg.min_beams, OVERHEAD) + cfg.camera_min_kbps)
    assert one_fps.camera_fps == 1.0 and one_fps.telemetry_hz == pytest.approx(7)
    starved = at(telemetry_kbps(5, cfg.min_beams, OVERHEAD) + 1)
    assert starved.camera_fps == 0.0 and starved.camera_kbps == 0.0  # off before the view starves
    assert starved.telemetry_hz >= cfg.min_telemetry_hz
    floor = at(1.0)
    assert floor.telemetry_hz == cfg.min_telemetry_hz  # never below 5 Hz: control never gives way
    # Every plan keeps to its budget while it can (all but the floor), and the camera's rate
    # and the telemetry's never rise as the budget falls (but when the camera goes off).
    previous = None
    for kbps in range(400, 40, -2):
        p = at(kbps)
        used = telemetry_kbps(p.telemetry_hz, p.scan_beams, OVERHEAD) + p.camera_kbps
        assert used <= kbps + 1e-6
        if previous is not None:
            assert p.camera_fps <= previous.camera_fps and p.camera_kbps <= previous.camera_kbps
            if p.camera_fps > 0 or previous.camera_fps == 0:  # off: its share goes to the view
                assert p.telemetry_hz <= previous.telemetry_hz + 1e-9
                assert p.scan_beams <= previous.scan_beams
        previous = p


def test_a_192_kbits_link_keeps_a_working_camera() -> None:
    """Issue 27: 0.7-0.85 of a 192 kbit/s link (a cut, cruise) keeps 5 frames/s."""
    cfg = BudgetConfig(camera=True, max_beams=180)
    for kbps in (0.7 * 185, 0.85 * 185, 185):
        p = plan(BudgetState(budget_kbps=kbps), cfg, 800.0)
        assert p.camera_fps >= 5.0, (kbps, p)
        assert p.telemetry_hz >= 10.0


def test_no_camera_the_whole_budget_goes_to_telemetry() -> None:
    cfg = BudgetConfig(camera=False, max_beams=180)
    p = plan(BudgetState(budget_kbps=telemetry_kbps(20, 180, OVERHEAD)), cfg, OVERHEAD)
    assert p.cut == () and p.camera_fps == 0.0 and p.scan_beams == 180


def test_camera_fps_scale() -> None:
    """Whole frames a second at the working rate's kbit a frame, 1 to the configured most."""
    cfg = BudgetConfig(camera=True)
    assert camera_fps(cfg.camera_min_kbps / 2, cfg) == 0.0
    assert camera_fps(float("nan"), cfg) == 0.0
    assert camera_fps(cfg.camera_min_kbps, cfg) == 1.0
    assert camera_fps(cfg.camera_keep_kbps, cfg) == cfg.camera_keep_fps
    assert camera_fps(cfg.camera_keep_kbps * 0.99, cfg) == cfg.camera_keep_fps - 1
    assert camera_fps(cfg.camera_max_kbps, cfg) == cfg.camera_max_fps
    steps = {camera_fps(k, cfg) for k in range(0, 500)}
    assert all(f == int(f) for f in steps)  # the encoder reopens only on whole steps


def test_flat_ages_never_cut_and_a_standing_queue_cuts_once() -> None:
    cfg = BudgetConfig()
    state = BudgetState(budget_kbps=400.0)
    t = 0
    for _ in range(200):  # 4 s of flat ages at 50 Hz
        t += 20 * MS
        state = on_report(state, cfg, Report(view_age_ms=100.0, rx_kbps=380.0), t)
    assert state.budget_kbps == 400.0 and state.cuts == 0 and state.queue_ms == 0.0
    # A queue stands: 400 ms more, the operator receives 200 kbit/s.
    for _ in range(10):
        t += 20 * MS
        state = on_report(state, cfg, Report(view_age_ms=500.0, rx_kbps=200.0), t)
    assert state.cuts == 1
    assert state.budget_kbps == pytest.approx(200.0 * 0.6)  # beta = 1 - 0.4 s / 1 s
    assert state.link_kbps == 200.0
    # Within the hold the same queue does not cut again (the cut has not reached the reports).
    for _ in range(20):
        t += 20 * MS
        state = on_report(state, cfg, Report(view_age_ms=500.0, rx_kbps=200.0), t)
    assert state.cuts == 1
    # A queue that keeps growing does (once the short window has seen it).
    for _ in range(10):
        t += 20 * MS
        state = on_report(state, cfg, Report(view_age_ms=1500.0, rx_kbps=200.0), t)
    assert state.cuts == 2 and state.budget_kbps < 120.0


def test_fixed_budget_never_moves() -> None:
    cfg = BudgetConfig(downlink_kbps=300.0)
    state = initial_state(cfg)
    t = 0
    for age in (100.0, 100.0, 900.0, 900.0):
        t += 20 * MS
        state = on_report(state, cfg, Report(view_age_ms=age, rx_kbps=10.0), t)
        state = on_cycle(state, cfg, t, 300.0)
    assert state.budget_kbps == 300.0 and state.cuts == 0


def test_probe_only_when_the_budget_is_used_and_ages_are_flat() -> None:
    cfg = BudgetConfig()
    state = initial_state(cfg)
    t = 0
    for _ in range(10):  # flat ages over 200 ms
        t += 20 * MS
        state = on_report(state, cfg, Report(view_age_ms=50.0), t)
    for _ in range(100):  # 1 s, the view plane sends a third of its budget
        t += 10 * MS
        state = on_cycle(state, cfg, t, sent_kbps=cfg.start_kbps / 3)
    assert state.budget_kbps == cfg.start_kbps
    for _ in range(100):  # 1 s, it fills the budget: additive increase
        t += 10 * MS
        state = on_cycle(state, cfg, t, sent_kbps=state.budget_kbps)
    assert cfg.start_kbps + cfg.ai_kbps < state.budget_kbps < 2 * cfg.start_kbps


def test_the_first_report_after_a_gap_does_not_count_alone() -> None:
    """An operator whose process stalled for 300 ms (a busy machine): its first report holds
    the stall in its view age; the next ones, a few ms later, do not. No cut."""
    cfg = BudgetConfig()
    state = BudgetState(budget_kbps=400.0)
    t = 0
    for _ in range(100):
        t += 20 * MS
        state = on_report(state, cfg, Report(view_age_ms=60.0, rx_kbps=380.0), t)
    t += 300 * MS
    state = on_report(state, cfg, Report(view_age_ms=360.0, rx_kbps=300.0), t)
    assert state.queue_ms is None and state.cuts == 0
    for age in (70.0, 60.0, 60.0, 60.0, 60.0, 60.0, 60.0):
        t += 20 * MS
        state = on_report(state, cfg, Report(view_age_ms=age, rx_kbps=300.0), t)
    assert state.cuts == 0 and state.queue_ms == 0.0
    # A queue that stands is seen once the reports span the window again.
    for _ in range(10):
        t += 20 * MS
        state = on_report(state, cfg, Report(view_age_ms=360.0, rx_kbps=300.0), t)
    assert state.cuts == 1


def test_a_fast_growing_queue_says_what_the_link_delivers_before_rx_does() -> None:
    """The link narrows from 2 Mbit/s to 128 kbit/s under a view plane sending 500 kbit/s: the
    queue grows by 0.74 ms a ms in the reports' time (fed at 500, drained at 128), while the
    operator's rx_kbps (a second's worth) still says 450. The cut goes below what the link
    delivers, not to 0.8 x 450; the link's estimate follows rx_kbps once the queue has stood
    for a second."""
    cfg = BudgetConfig()
    state = replace(BudgetState(budget_kbps=600.0), link_kbps=480.0, cut_rx_kbps=480.0)
    t = 0
    for _ in range(200):
        t += 20 * MS
        state = on_report(state, cfg, Report(100.0, 480.0, stamp_ns=t), t, sent_kbps=500.0)
    age = 100.0
    while state.cuts == 0:
        t += 20 * MS
        age += 20 * (1.0 - 128.0 / 500.0)
        state = on_report(state, cfg, Report(age, 450.0, stamp_ns=t), t, sent_kbps=500.0)
    assert state.budget_kbps < 128.0, state.budget_kbps
    # rx_kbps catches up once the queue has stood a whole second: the link's rate from then on
    for rx in (300.0, 200.0, 128.0, 128.0, 128.0, 128.0, 128.0, 128.0):
        for _ in range(10):
            t += 20 * MS
            age += 5.0
            state = on_report(state, cfg, Report(age, rx, stamp_ns=t), t, sent_kbps=60.0)
    assert state.link_kbps == 128.0 and state.cut_rx_kbps == 128.0


def telemetry_ages(
    duration_ms: int, delay_ms: Callable[[int], float], period_ms: int = 50
) -> list[tuple[int, float]]:
    """What the operator reports every 20 ms (time, view age; ms on the robot's clock) of
    telemetry sent every ``period_ms`` that arrives ``delay_ms(sent)`` after it was sent (any
    order): the age of the newest message arrived."""
    arrivals = sorted((s + delay_ms(s), s) for s in range(0, duration_ms, period_ms))
    ages, newest, i = [], None, 0
    for t in range(20, duration_ms, 20):
        while i < len(arrivals) and arrivals[i][0] <= t:
            newest = arrivals[i][1] if newest is None else max(newest, arrivals[i][1])
            i += 1
        if newest is not None:
            ages.append((t, float(t - newest)))
    return ages


def feed(
    state: BudgetState,
    cfg: BudgetConfig,
    ages: list[tuple[int, float]],
    rx_kbps: Callable[[int], float],
    sent_kbps: float,
    up_ms: float = 80.0,
) -> list[tuple[int, BudgetState]]:
    """The reports through an uplink of ``up_ms``: the state after each, by the report's time."""
    out = []
    for t, age in ages:
        now = int((t + up_ms) * MS)
        report = Report(age, rx_kbps(t), stamp_ns=t * MS)
        state = on_report(state, cfg, report, now, sent_kbps=sent_kbps)
        out.append((t, state))
    return out


NARROW_AT_MS = 5000  # the link goes from 2 Mbit/s to 128 kbit/s under 400 kbit/s of view


def serialized_delays(
    narrow_at_ms: int, end_ms: int, wide_kbps: float = 2000.0, thin_kbps: float = 128.0
) -> dict[int, float]:
    """The one-way delay (ms) of each telemetry message (1.1 kB every 50 ms; key: its send
    time) through a link with a deep buffer that narrows from ``wide_kbps`` to ``thin_kbps`` at
    ``narrow_at_ms``, shared with 4 kB camera frames every 100 ms (400 kbit/s in all): each
    message waits for the link to carry everything sent before it, so the delays rise in
    steps (a frame's time on the link, then less for the messages right behind it)."""
    sent = [(s, 1100, True) for s in range(0, end_ms, 50)]
    sent += [(s, 4000, False) for s in range(25, end_ms, 100)]
    free_ms, delays = 0.0, {}
    for s, nbytes, telemetry in sorted(sent):
        start = max(float(s), free_ms)
        free_ms = start + nbytes * 8.0 / (wide_kbps if start < narrow_at_ms else thin_kbps)
        if telemetry:
            delays[s] = 80.0 + free_ms - s
    return delays


@pytest.mark.parametrize("phase_ms", [0, 13, 26, 39])
def test_a_link_that_narrows_is_drained_at_the_floor_at_once(phase_ms: int) -> None:
    """2 Mbit/s -> 128 kbit/s under 400 kbit/s of view data (``serialized_delays``; the step
    at four phases of the streams). The ages rise in steps, and the slope over 0.1 s used to
    misjudge them: the first cut went to 0.8 x a second of rx_kbps (142 kbit/s, still above
    the link) in three phases of four, and the queue grew for 0.3 s more. Within 300 ms of the
    first report older than the sawtooth allows (base + a telemetry period + 20 ms), the
    budget is at its floor (the camera off), where cruise will return to is well below what
    was sent, and the budget stays at the floor while the queue is still growing."""
    cfg = BudgetConfig(camera=True)
    narrow_at = NARROW_AT_MS + phase_ms
    delays = serialized_delays(narrow_at, narrow_at + 1500)
    ages = telemetry_ages(narrow_at + 1500, lambda s: delays[s])

    def rx(t: int) -> float:  # a second's worth: the wide link's for a while
        return 400.0 if t < narrow_at + 200 else 330.0

    states = feed(BudgetState(budget_kbps=600.0), cfg, ages, rx, sent_kbps=400.0)
    base = min(a for t, a in ages if t < narrow_at)
    evidence = next(t for t, a in ages if t > narrow_at and a > base + 50.0 + 20.0)
    cut_at, cut = next((t, s) for t, s in states if s.cuts)
    assert cut_at - evidence <= 300, (evidence, cut_at)
    assert cut.cuts == 1 and cut.draining
    assert cut.budget_kbps == cfg.floor_kbps
    assert plan(cut, cfg, OVERHEAD).camera_fps == 0.0  # the camera pauses
    assert cut.cut_rx_kbps is not None and cut.cut_rx_kbps <= 200.0
    growing = [s for t, s in states if cut_at < t <= cut_at + 600]
    assert all(s.budget_kbps == cfg.floor_kbps for s in growing)


def test_steady_jitter_of_30_ms_never_cuts() -> None:
    """A link whose delay jitters by +-30 ms (uniform, messages may overtake each other) and
    carries all that is sent: 30 s of reports, no cut, no drain."""
    cfg = BudgetConfig(camera=True)
    rng = random.Random(27)
    jitter = {s: rng.uniform(-30.0, 30.0) for s in range(0, 30_000, 50)}
    ages = telemetry_ages(30_000, lambda s: 80.0 + jitter[s])
    states = feed(BudgetState(budget_kbps=300.0), cfg, ages, lambda t: 300.0, sent_kbps=300.0)
    assert all(s.cuts == 0 and not s.draining for _, s in states)
    assert max(s.queue_ms or 0.0 for _, s in states) < cfg.margin_ms


def test_a_drain_returns_to_cruise_at_what_the_link_delivered() -> None:
    """Once the queue a narrowing left has drained, the budget returns at once (no hold) to
    cruise times the smaller of the estimate at the cut and the operator's last second; an
    rx_kbps that a frame arriving whole made look larger during the drain raises neither."""
    cfg = BudgetConfig(camera=True)

    def delay(sent: int) -> float:
        if sent <= NARROW_AT_MS:
            return 80.0
        if sent <= NARROW_AT_MS + 400:  # the queue builds until the cut takes effect ...
            return 80.0 + (sent - NARROW_AT_MS) * 2.1
        return max(80.0, 80.0 + 840.0 - (sent - NARROW_AT_MS - 400))  # ... then drains

    ages = telemetry_ages(NARROW_AT_MS + 2500, delay)

    def rx(t: int) -> float:
        return 400.0 if t < NARROW_AT_MS + 300 else 170.0 if t < NARROW_AT_MS + 1400 else 120.0

    states = feed(BudgetState(budget_kbps=600.0), cfg, ages, rx, sent_kbps=400.0)
    cut_at, cut = next((t, s) for t, s in states if s.cuts)
    assert cut.draining and cut.budget_kbps == cfg.floor_kbps
    estimate = cut.cut_rx_kbps
    assert estimate is not None
    back_at, back = next((t, s) for t, s in states if t > cut_at and not s.draining)
    assert back_at - cut_at < 1000 * cfg.hold_s + 800  # the queue drained: ~1.2 s of it
    assert back.cuts == 1
    assert back.budget_kbps == pytest.approx(cfg.cruise * min(estimate, rx(back_at)))
    assert back.budget_kbps <= cfg.cruise * 170.0


def test_with_no_ages_a_link_that_delivers_less_than_is_sent_cuts() -> None:
    """A link narrower than start_kbps: the operator's clock replies wait behind the view data,
    so it never synchronises and reports no ages; its rx_kbps (no clock needed) says the link
    carries 60 kbit/s of the 120 sent. After two seconds of that the budget goes below it."""
    cfg = BudgetConfig()
    state = initial_state(cfg)
    t = 0
    for i in range(150):  # 3 s of reports without view_age
        t += 20 * MS
        rx = min(60.0, 3.0 * i)  # the operator's first second fills its window
        state = on_report(state, cfg, Report(None, rx), t, sent_kbps=120.0)
        if t < 2 * NS:
            assert state.cuts == 0
    assert state.cuts == 1 and state.budget_kbps == pytest.approx(0.8 * 60.0)
    assert state.link_kbps == 60.0
    # A link that carries what is sent never cuts, ages or not.
    state = initial_state(cfg)
    for _ in range(300):
        t += 20 * MS
        state = on_report(state, cfg, Report(None, 115.0), t, sent_kbps=120.0)
    assert state.cuts == 0 and state.budget_kbps == cfg.start_kbps


def test_at_the_floor_a_standing_queue_does_not_restart_the_hold() -> None:
    cfg = BudgetConfig()
    state = replace(BudgetState(budget_kbps=cfg.floor_kbps), last_cut_ns=0, cuts=3)
    t = 0
    for _ in range(100):
        t += 20 * MS
        state = on_report(state, cfg, Report(100.0 if t < NS else 900.0, 40.0), t)
    assert state.cuts == 3 and state.last_cut_ns == 0


def test_a_queue_that_vanishes_faster_than_a_link_drains_is_taken_back() -> None:
    """A busy machine: the operator's process stalls 300 ms, and for a window its reports show
    the view 300 ms older; 20 ms later (by their stamps) it is fresh again. Bytes in a link's
    queue cannot leave that fast, so the cut is undone. A queue that drains no faster than a
    millisecond a millisecond stays cut."""
    cfg = BudgetConfig()

    def run(after_ms: list[float]) -> BudgetState:
        state = replace(BudgetState(budget_kbps=500.0), link_kbps=480.0, cut_rx_kbps=480.0)
        t = 0
        for _ in range(100):
            t += 20 * MS
            state = on_report(state, cfg, Report(60.0, 470.0, stamp_ns=t), t)
        for age in [360.0] * 8 + after_ms:
            t += 20 * MS
            state = on_report(state, cfg, Report(age, 300.0, stamp_ns=t), t)
        return state

    stall = run([60.0] * 10)
    assert stall.cuts == 1 and stall.undone == 1
    assert stall.budget_kbps == 500.0 and stall.link_kbps == 480.0
    draining = run([340.0, 320.0, 300.0, 280.0, 260.0, 240.0, 220.0, 200.0])
    assert draining.cuts == 1 and draining.undone == 0 and draining.budget_kbps < 300.0


def test_a_camera_that_slowed_or_stopped_is_no_queue() -> None:
    """Issue 27 (a): the operator keeps reporting the age of the last frame shown, growing
    without bound once frames stop coming; that is no queue (the budget used to read it as one,
    cut, and the camera never came back)."""
    cfg = BudgetConfig(camera=True)
    in_force = plan(BudgetState(budget_kbps=300.0), cfg, OVERHEAD)
    assert in_force.camera_fps >= 5
    state = BudgetState(budget_kbps=300.0)
    t = 10 * NS
    frame = t - 120 * MS
    for i in range(500):  # 10 s of commands at 50 Hz; frames stop after the first second
        t += 20 * MS
        if i < 50 and (t - frame) >= 200 * MS:
            frame = t - 120 * MS  # a new frame every 200 ms, shown 120 ms after capture
        report = Report(
            view_age_ms=100.0, rx_kbps=280.0, camera_age_ms=(t - frame) / MS, stamp_ns=t
        )
        state = on_report(state, cfg, report, t + 80 * MS, in_force)
    assert state.cuts == 0 and state.budget_kbps == 300.0
    assert state.camera_queue_ms is None  # no frame for seconds: the camera says nothing


def test_camera_frames_that_arrive_later_and_later_cut() -> None:
    """What only the camera sees (its frames waiting at the robot or in the operator's
    decoder) is a queue: frames shown each later after capture than the last."""
    cfg = BudgetConfig(camera=True)
    in_force = plan(BudgetState(budget_kbps=300.0), cfg, OVERHEAD)
    state = BudgetState(budget_kbps=300.0)
    t = 10 * NS
    latency_ms = 120.0
    frame = t - int(latency_ms * MS)
    for i in range(300):
        t += 20 * MS
        if (t - frame) >= int((latency_ms + 100) * MS):  # the next frame is shown
            latency_ms += 0.0 if i < 100 else 60.0  # from 2 s on, 60 ms later each frame
            frame = t - int(latency_ms * MS)
        report = Report(
            view_age_ms=100.0, rx_kbps=280.0, camera_age_ms=(t - frame) / MS, stamp_ns=t
        )
        state = on_report(state, cfg, report, t + 80 * MS, in_force)
    assert state.cuts >= 1 and state.budget_kbps < 300.0
    assert state.camera_queue_ms is not None and state.camera_queue_ms > cfg.margin_ms


def test_one_frame_a_second_is_no_queue_signal() -> None:
    """At 1 frame/s a queue would be seen a second late; the telemetry's age is earlier."""
    cfg = BudgetConfig(camera=True)
    in_force = replace(plan(BudgetState(budget_kbps=300.0), cfg, OVERHEAD), camera_fps=1.0)
    state = BudgetState(budget_kbps=300.0)
    t = 10 * NS
    frame, latency = t, 120.0
    for _ in range(300):
        t += 20 * MS
        if t - frame >= int((latency + 1000) * MS):
            latency += 200.0
            frame = t - int(latency * MS)
        report = Report(
            view_age_ms=100.0, rx_kbps=280.0, camera_age_ms=(t - frame) / MS, stamp_ns=t
        )
        state = on_report(state, cfg, report, t, in_force)
    assert state.cuts == 0 and state.camera_queue_ms is None


def test_the_probe_past_the_last_cut_starts_slowly_and_doubles() -> None:
    cfg = BudgetConfig()
    state = replace(
        initial_state(cfg),
        budget_kbps=200.0,
        cut_rx_kbps=180.0,
        link_kbps=180.0,
        queue_ms=0.0,
        last_step_ns=0,
    )
    budgets = []
    t = 0
    for _ in range(400):  # 4 s, the view plane filling its budget, no queue
        t += 10 * MS
        state = on_cycle(state, cfg, t, sent_kbps=state.budget_kbps)
        if t % NS == 0:
            budgets.append(state.budget_kbps)
    steps = [b - a for a, b in zip([200.0, *budgets], budgets, strict=False)]
    assert steps[0] < 2 * cfg.ai_kbps  # a link that did not widen sees a few kbit/s too many
    assert all(b > 1.5 * a for a, b in itertools.pairwise(steps)), steps  # doubling
    # A queue that begins stops the doubling; the next probe starts slowly again.
    state = replace(state, queue_ms=cfg.margin_ms * 0.6)
    state = on_cycle(state, cfg, t + 10 * MS, sent_kbps=state.budget_kbps)
    assert state.beyond_ns is None


def test_rate_meter() -> None:
    meter = RateMeter(window_s=1.0)
    assert meter.kbps(0) == 0.0
    for i in range(10):
        meter.add(i * 100 * MS, 1250)  # 12.5 kB in a second: 100 kbit/s
    assert meter.kbps(999 * MS) == pytest.approx(100.0)
    assert meter.kbps(3 * NS) == 0.0 and meter.total_bytes == 12_500


# ------------------------------------------------------------------------------------------
# Closed loop: the robot's budget against a fluid model of a rate-limited link with a deep
# buffer (the relay's rate=), reports travelling back over the uplink.


@dataclass
class FluidLink:
    """Bits queue behind a bottleneck of ``rate_kbps``; one-way delay ``delay_ms`` each way."""

    delay_ms: float
    rate_kbps: float
    queue_kbit: float = 0.0
    delivered: deque[tuple[int, float]] = field(default_factory=deque)  # (t_ns, kbit)

    def step(self, t_ns: int, dt_s: float, sent_kbit: float) -> None:
        self.queue_kbit += sent_kbit
        out = min(self.queue_kbit, self.rate_kbps * dt_s)
        self.queue_kbit -= out
        self.delivered.append((t_ns, out))
        while self.delivered and t_ns - self.delivered[0][0] >= NS:
            self.delivered.popleft()

    @property
    def queue_ms(self) -> float:
        return 1000.0 * self.queue_kbit / self.rate_kbps

    def rx_kbps(self) -> float:
        return sum(k for _, k in self.delivered)


@dataclass(frozen=True)
class Sample:
    """Every 100 ms of a closed-loop run: what the operator sees and the plan in force."""

    t_s: float
    view_age_ms: float
    camera_age_ms: float | None
    plan: Plan


def run_loop(
    phases: list[tuple[float, float]], duration_s: float, delay_ms: float = 80.0
) -> list[Sample]:
    """``phases``: (start_s, rate_kbps). The operator reports every 20 ms; the reports take
    ``delay_ms`` up. Telemetry messages go out at the plan's rate and arrive after the delay,
    the queue and their own time on the link; the view's age is the newest arrived message's.
    Camera frames likewise; the last one shown stays (its age grows while the camera is off)."""
    cfg = BudgetConfig(camera=True, max_beams=180)
    state = initial_state(cfg)
    link = FluidLink(delay_ms, phases[0][1])
    sent_meter = RateMeter()
    dt_ns = 10 * MS
    in_flight: deque[tuple[int, Report]] = deque()  # reports on their way up
    out: list[Sample] = []
    current = plan(state, cfg, OVERHEAD)
    shown_ns: int | None = None  # the capture stamp of the camera frame shown
    telemetry: deque[tuple[int, int]] = deque()  # (stamp, arrival) of messages on their way
    view_ns: int | None = None  # the stamp of the newest telemetry message arrived
    next_tel = 0
    for i in range(int(duration_s * 100)):
        t = i * dt_ns
        t_s = t / NS
        for start_s, rate in phases:
            if t_s >= start_s:
                link.rate_kbps = rate
        state = on_cycle(state, cfg, t, sent_kbps=sent_meter.kbps(t) if i >= 100 else None)
        current = plan(state, cfg, OVERHEAD)
        sent = telemetry_kbps(current.telemetry_hz, current.scan_beams, OVERHEAD)
        sent += current.camera_kbps
        sent_meter.add(t, int(sent * dt_ns / NS * 1000 / 8))
        link.step(t, dt_ns / NS, sent * dt_ns / NS)
        if t >= next_tel:
            own_ms = current.telemetry_bytes * 8.0 / link.rate_kbps
            telemetry.append((t, t + int((delay_ms + link.queue_ms + own_ms) * MS)))
            next_tel += int(NS / current.telemetry_hz)
        while telemetry and telemetry[0][1] <= t:
            stamp = telemetry.popleft()[0]
            view_ns = stamp if view_ns is None else max(view_ns, stamp)
        if view_ns is None:
            continue  # nothing to report before the first message
        view_age = (t - view_ns) / MS
        if current.camera_fps > 0:
            frame_ms = current.camera_kbps / current.camera_fps / link.rate_kbps * 1000.0
            latency_ns = int((delay_ms + link.queue_ms + frame_ms) * MS)
            frame_period_ns = int(NS / current.camera_fps)
            newest = (t - latency_ns) // frame_period_ns * frame_period_ns
            shown_ns = newest if shown_ns is None else max(shown_ns, newest)
        camera_age = None if shown_ns is None else max(0.0, (t - shown_ns) / MS)
        if i % 2 == 0:  # a command every 20 ms
            report = Report(
                view_age_ms=round(view_age),
                rx_kbps=round(link.rx_kbps()),
                camera_age_ms=None if camera_age is None else round(camera_age),
                stamp_ns=t,
            )
            in_flight.append((t + int(delay_ms * MS), report))
        while in_flight and in_flight[0][0] <= t:
            state = on_report(state, cfg, in_flight.popleft()[1], t, current, sent_meter.kbps(t))
        if i % 10 == 0:
            out.append(Sample(t_s, view_age, camera_age, current))
    return out


def test_closed_loop_thin_link_keeps_the_view_fresh_and_the_camera_on() -> None:
    """Issue 27 at 192 kbit/s: view age p50 within delay + 200 ms, the camera at 5 frames/s or
    more nearly all the time, its age p50 within delay + 300 ms."""
    trace = [s for s in run_loop([(0.0, 192.0)], duration_s=40.0) if s.t_s >= 5.0]
    ages = sorted(s.view_age_ms for s in trace)
    assert ages[len(ages) // 2] <= 80.0 + 200.0
    assert ages[-1] < 80.0 + 600.0  # the sawtooth's peaks stay short
    assert all(s.plan.telemetry_hz >= 5.0 for s in trace)
    working = [s.plan.camera_fps >= 5.0 for s in trace]
    assert sum(working) >= 0.9 * len(trace), [s.plan.camera_fps for s in trace]
    camera = sorted(s.camera_age_ms for s in trace if s.camera_age_ms is not None)
    assert camera[len(camera) // 2] <= 80.0 + 300.0


def test_closed_loop_recovers_within_3_s_of_each_change() -> None:
    """2 Mbit/s -> 128 kbit/s -> 2 Mbit/s, 10 s each (the issue's scenario): the view's age back
    under delay + 200 ms within 3 s of each change (its median over half a second: the
    telemetry period's sawtooth rides on top) and at the median over the rest of the phase (the
    probes' sawtooth too), and the camera back up after the link widens."""
    trace = run_loop([(0.0, 2000.0), (10.0, 128.0), (20.0, 2000.0)], duration_s=30.0)

    def median(values: list[float]) -> float:
        return sorted(values)[len(values) // 2]

    for change_s in (10.0, 20.0):
        # the median over the last half second, every 100 ms from the change on
        halves = [
            (s.t_s, median([a.view_age_ms for a in trace if s.t_s - 0.5 < a.t_s <= s.t_s]))
            for s in trace
            if change_s + 0.5 <= s.t_s < change_s + 10.0
        ]
        assert [age for t, age in halves if t <= change_s + 3.0][-1] <= 80.0 + 200.0, halves
        rest = [s.view_age_ms for s in trace if change_s + 3.0 <= s.t_s < change_s + 10.0]
        assert median(rest) <= 80.0 + 200.0, (change_s, halves)
        assert max(rest) <= 80.0 + 600.0, (change_s, halves)
    thin = [s.plan for s in trace if 13.0 <= s.t_s < 20.0]
    assert all("camera" in p.cut for p in thin)
    assert max(p.camera_fps for p in thin) >= 1.0  # a thin link still carries some camera
    wide = [s.plan for s in trace if 27.0 <= s.t_s < 30.0]
    assert min(p.camera_fps for p in wide) == BudgetConfig().camera_max_fps  # back up


def test_closed_loop_camera_comes_back_after_a_long_thin_stretch() -> None:
    """Issue 27 (a): 30 s at 64 kbit/s (the camera at 1 frame/s or off, its age growing), then
    the link widens: the camera is back at full rate within 10 s."""
    trace = run_loop([(0.0, 64.0), (30.0, 2000.0)], duration_s=42.0)
    thin = [s.plan for s in trace if 5.0 <= s.t_s < 30.0]
    assert sorted(p.camera_fps for p in thin)[len(thin) // 2] <= 2.0  # mostly 1 frame/s or off
    assert trace[-1].plan.camera_fps == BudgetConfig().camera_max_fps
    assert trace[-1].camera_age_ms is not None and trace[-1].camera_age_ms < 300.0
