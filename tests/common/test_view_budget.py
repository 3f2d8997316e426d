"""The downlink budget (DESIGN 12, ``egc_common.view_budget``): the plan's order of giving way,
the AIMD steps, and a closed loop against a fluid model of a link with a deep buffer."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

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
    """Camera quality and rate first, then scan resolution, then telemetry rate, camera off last."""
    cfg = BudgetConfig(camera=True, max_beams=180)
    full_tel = telemetry_kbps(20, 180, OVERHEAD)

    def at(kbps: float) -> Plan:
        return plan(BudgetState(budget_kbps=kbps), cfg, OVERHEAD)

    top = at(full_tel + cfg.camera_max_kbps + 50)
    assert top.cut == () and top.camera_fps == cfg.camera_max_fps and top.scan_beams == 180
    camera_cut = at(full_tel + 100)
    assert camera_cut.cut == ("camera",)
    assert 1 < camera_cut.camera_fps < cfg.camera_max_fps and camera_cut.scan_beams == 180
    assert camera_cut.telemetry_hz == 20
    scan_cut = at(telemetry_kbps(20, 90, OVERHEAD) + cfg.camera_min_kbps + 1)
    assert scan_cut.cut == ("camera", "scan")
    assert scan_cut.camera_fps == 1.0 and scan_cut.scan_beams == 90
    rate_cut = at(telemetry_kbps(10, cfg.min_beams, OVERHEAD) + cfg.camera_min_kbps)
    assert rate_cut.cut == ("camera", "scan", "rate")
    assert rate_cut.scan_beams == cfg.min_beams and rate_cut.telemetry_hz == pytest.approx(10)
    assert rate_cut.camera_fps == 1.0
    starved = at(telemetry_kbps(5, cfg.min_beams, OVERHEAD) + 1)
    assert starved.camera_fps == 0.0 and starved.camera_kbps == 0.0  # off before the view starves
    assert starved.telemetry_hz >= cfg.min_telemetry_hz
    floor = at(1.0)
    assert floor.telemetry_hz == cfg.min_telemetry_hz  # never below 5 Hz: control never gives way
    # Every plan keeps to its budget while it can (all but the floor).
    for kbps in (100, 150, 250, 400, 800):
        p = at(kbps)
        used = telemetry_kbps(p.telemetry_hz, p.scan_beams, OVERHEAD) + p.camera_kbps
        assert used <= kbps + 1e-6


def test_no_camera_the_whole_budget_goes_to_telemetry() -> None:
    cfg = BudgetConfig(camera=False, max_beams=180)
    p = plan(BudgetState(budget_kbps=telemetry_kbps(20, 180, OVERHEAD)), cfg, OVERHEAD)
    assert p.cut == () and p.camera_fps == 0.0 and p.scan_beams == 180


def test_camera_fps_scale() -> None:
    cfg = BudgetConfig(camera=True)
    assert camera_fps(cfg.camera_min_kbps / 2, cfg) == 0.0
    assert camera_fps(cfg.camera_min_kbps, cfg) == 1.0
    assert camera_fps(cfg.camera_max_kbps, cfg) == cfg.camera_max_fps


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
    state = on_report(state, cfg, Report(view_age_ms=50.0), t)
    for _ in range(100):  # 1 s, the view plane sends a third of its budget
        t += 10 * MS
        state = on_cycle(state, cfg, t, sent_kbps=cfg.start_kbps / 3)
    assert state.budget_kbps == cfg.start_kbps
    for _ in range(100):  # 1 s, it fills the budget: additive increase
        t += 10 * MS
        state = on_cycle(state, cfg, t, sent_kbps=state.budget_kbps)
    assert cfg.start_kbps + cfg.ai_kbps < state.budget_kbps < 2 * cfg.start_kbps


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


def run_loop(
    phases: list[tuple[float, float]], duration_s: float, delay_ms: float = 80.0
) -> list[tuple[float, float, Plan]]:
    """(t_s, view age ms, plan) every 100 ms; ``phases``: (start_s, rate_kbps)."""
    cfg = BudgetConfig(camera=True, max_beams=180)
    state = initial_state(cfg)
    link = FluidLink(delay_ms, phases[0][1])
    dt_ns = 10 * MS
    in_flight: deque[tuple[int, Report]] = deque()  # reports on their way up
    out: list[tuple[float, float, Plan]] = []
    current = plan(state, cfg, OVERHEAD)
    for i in range(int(duration_s * 100)):
        t = i * dt_ns
        t_s = t / NS
        for start_s, rate in phases:
            if t_s >= start_s:
                link.rate_kbps = rate
        state = on_cycle(state, cfg, t, sent_kbps=link.rx_kbps() if i else None)
        current = plan(state, cfg, OVERHEAD)
        sent = telemetry_kbps(current.telemetry_hz, current.scan_beams, OVERHEAD)
        sent += current.camera_kbps
        link.step(t, dt_ns / NS, sent * dt_ns / NS)
        # The view's age when the operator sends a command: the downlink's delay, the queue,
        # and the time since the newest telemetry message arrived (a sawtooth).
        period_ms = 1000.0 / current.telemetry_hz
        view_age = delay_ms + link.queue_ms + (t / MS) % period_ms
        if i % 2 == 0:  # a command every 20 ms
            report = Report(view_age_ms=round(view_age), rx_kbps=round(link.rx_kbps()))
            in_flight.append((t + int(delay_ms * MS), report))
        while in_flight and in_flight[0][0] <= t:
            state = on_report(
                state,
                cfg,
                in_flight.popleft()[1],
                t,
                camera_fps=current.camera_fps,
                telemetry_hz=current.telemetry_hz,
            )
        if i % 10 == 0:
            out.append((t_s, view_age, current))
    return out


def test_closed_loop_thin_link_keeps_the_view_fresh() -> None:
    trace = run_loop([(0.0, 192.0)], duration_s=30.0)
    late = [age for t, age, _ in trace if t >= 5.0]
    late.sort()
    assert late[len(late) // 2] <= 80.0 + 200.0  # p50 within delay + 200 ms
    assert max(late) < 80.0 + 600.0  # the sawtooth's peaks stay short
    assert all(p.telemetry_hz >= 5.0 for _, _, p in trace)


def test_closed_loop_recovers_within_3_s_of_each_change() -> None:
    """2 Mbit/s -> 128 kbit/s -> 2 Mbit/s, 10 s each (the issue's scenario)."""
    trace = run_loop([(0.0, 2000.0), (10.0, 128.0), (20.0, 2000.0)], duration_s=30.0)
    for change_s in (10.0, 20.0):
        after = sorted(age for t, age, _ in trace if change_s + 3.0 <= t < change_s + 10.0)
        # Back under delay + 200 ms; the probes' short peaks (AIMD's sawtooth) stay below 400.
        assert after[int(0.9 * len(after))] <= 80.0 + 200.0, (change_s, after)
        assert after[-1] <= 80.0 + 400.0, (change_s, after[-1])
    wide = [p for t, _, p in trace if 25.0 <= t < 30.0]
    assert min(p.camera_fps for p in wide) >= 2.0  # the camera came back up
    thin = [p for t, _, p in trace if 15.0 <= t < 20.0]
    assert all("camera" in p.cut for p in thin)
