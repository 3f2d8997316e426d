"""The pure link model of ``egc-teleop link``: distributions, loss, order, outages, rate,
schedules, traces, scenarios, the SPEC parser and determinism."""

from __future__ import annotations

import itertools
import math
import statistics
from pathlib import Path

import pytest
from egc_experiments.link_model import (
    MAX_DELAY_MS,
    MIN_RATE_KBITPS,
    UDP_QUEUE_LIMIT,
    DirectionStats,
    LinkModel,
    LinkSpec,
    Phase,
    Schedule,
    SpecError,
    load_scenario,
    parse_spec,
    parse_trace,
    percentile,
)

N = 50_000


def delays_ms(spec: str, n: int = N, seed: int = 1) -> list[float]:
    model = LinkModel(parse_spec(spec), seed=seed, ordered=False)
    out = []
    for i in range(n):
        t = i * 1.0  # far apart: no hold-back, delay alone
        arrival = model.transit(t, 100)
        assert arrival is not None
        out.append((arrival - t) * 1000.0)
    return out


@pytest.mark.parametrize("dist", ["normal", "uniform", "pareto"])
def test_delay_distribution_has_the_mean_and_std_asked_for(dist: str) -> None:
    d = delays_ms(f"delay=100,jitter=10,dist={dist}", n=200_000 if dist == "pareto" else N)
    assert statistics.fmean(d) == pytest.approx(100.0, abs=0.3)
    assert statistics.pstdev(d) == pytest.approx(10.0, rel=0.08 if dist == "pareto" else 0.03)
    assert min(d) >= 0


def test_uniform_stays_in_its_band_and_pareto_has_a_long_tail() -> None:
    u = delays_ms("delay=100,jitter=10,dist=uniform")
    half = 10 * math.sqrt(3)
    assert 100 - half <= min(u) < 100 - half + 0.5
    assert 100 + half - 0.5 < max(u) <= 100 + half
    p = sorted(delays_ms("delay=100,jitter=10,dist=pareto", n=100_000))
    # Shape 3 Pareto scaled to std 10 cannot go below mean - 0.577 std; its tail is long.
    assert min(p) >= 100 - 10 * 0.5774 - 1e-6
    assert percentile(p, 99.9) - percentile(p, 50) > 3 * (percentile(p, 50) - p[0])
    n = sorted(delays_ms("delay=100,jitter=10,dist=normal"))
    assert p[-1] > n[-1]


def test_delay_is_floored_at_zero() -> None:
    d = delays_ms("delay=5,jitter=20", n=20_000)
    assert min(d) == 0.0
    assert sum(1 for x in d if x == 0.0) > 0.3 * len(d)
    assert delays_ms("delay=40", n=10) == pytest.approx([40.0] * 10)


def drops(spec: str, n: int, seed: int = 3) -> list[bool]:
    model = LinkModel(parse_spec(spec), seed=seed, ordered=False)
    return [model.transit(i * 0.001, 100) is None for i in range(n)]


def bursts(lost: list[bool]) -> list[int]:
    runs, run = [], 0
    for x in lost:
        if x:
            run += 1
        elif run:
            runs.append(run)
            run = 0
    return runs


def test_bernoulli_loss_rate() -> None:
    lost = drops("loss=10", 100_000)
    assert sum(lost) / len(lost) == pytest.approx(0.10, abs=0.004)
    # Independent losses: mean run length 1 / (1 - p).
    assert statistics.fmean(bursts(lost)) == pytest.approx(1 / 0.9, abs=0.02)
    assert not any(drops("loss=0", 1000))
    assert all(drops("loss=100", 1000))


@pytest.mark.parametrize(("loss", "burst"), [(10, 4), (2, 8), (30, 2)])
def test_gilbert_elliott_mean_loss_and_burst_length(loss: float, burst: float) -> None:
    lost = drops(f"loss={loss},burst={burst}", 400_000)
    assert sum(lost) / len(lost) == pytest.approx(loss / 100, rel=0.06)
    assert statistics.fmean(bursts(lost)) == pytest.approx(burst, rel=0.06)


def test_tcp_arrivals_never_decrease_and_a_late_chunk_holds_back_the_rest() -> None:
    model = LinkModel(parse_spec("delay=50,jitter=30"), seed=5, ordered=True)
    arrivals = [model.transit(i * 0.002, 1000) for i in range(5000)]
    assert all(a is not None for a in arrivals)
    assert all(b >= a for a, b in itertools.pairwise(arrivals))  # type: ignore[operator]
    # A schedule: 500 ms until 0.1 s, then 0 ms. The chunk sent at 0.2 s waits for the one of 0.05 s.
    slow_then_fast = Schedule((Phase(0.0, parse_spec("delay=500")), Phase(0.1, LinkSpec())))
    tcp = LinkModel(slow_then_fast, seed=0, ordered=True)
    assert tcp.transit(0.05, 10) == pytest.approx(0.55)
    assert tcp.transit(0.2, 10) == pytest.approx(0.55)
    assert tcp.transit(0.6, 10) == pytest.approx(0.6)


def test_udp_keeps_order_unless_reorder_is_asked_for() -> None:
    def run(reorder: str) -> list[float | None]:
        sched = Schedule(
            (Phase(0.0, parse_spec("delay=500" + reorder)), Phase(0.1, parse_spec(reorder[1:])))
        )
        model = LinkModel(sched, seed=0, ordered=False)
        return [model.transit(0.05, 10), model.transit(0.2, 10)]

    assert run(",reorder=0") == pytest.approx([0.55, 0.55])
    assert run(",reorder=1") == pytest.approx([0.55, 0.2])
    jittery = LinkModel(parse_spec("delay=50,jitter=30,reorder=1"), seed=2, ordered=False)
    arrivals = [jittery.transit(i * 0.002, 100) for i in range(2000)]
    assert any(b < a for a, b in itertools.pairwise(arrivals))  # type: ignore[operator]


def test_outage_drops_on_udp_and_delays_on_tcp() -> None:
    spec = parse_spec("delay=10,outage=1+2,outage=5+0.5")
    udp = LinkModel(spec, seed=0, ordered=False)
    sent = [0.5, 0.999, 1.0, 2.0, 2.999, 3.0, 4.9, 5.2, 5.5]
    got = [udp.transit(t, 100) for t in sent]
    assert [g is None for g in got] == [False, False, True, True, True, False, False, True, False]
    assert udp.dropped == {"loss": 0, "outage": 4, "queue": 0}
    assert udp.forwarded == 5
    tcp = LinkModel(spec, seed=0, ordered=True)
    assert tcp.transit(0.5, 100) == pytest.approx(0.51)
    assert tcp.transit(1.5, 100) == pytest.approx(3.01)  # retransmitted when the link is back
    assert tcp.transit(2.0, 100) == pytest.approx(3.01)
    assert tcp.transit(5.0, 100) == pytest.approx(5.51)
    assert tcp.dropped_total == 0


def test_rate_limit_serialises_at_the_rate() -> None:
    # 800 kbit/s = 100 kB/s: a 1000-byte packet takes 10 ms on the wire.
    model = LinkModel(parse_spec("rate=800,delay=20"), seed=0, ordered=True)
    arrivals = [model.transit(i * 0.001, 1000) for i in range(200)]  # offered: 1 MB/s
    assert arrivals[0] == pytest.approx(0.0 + 0.010 + 0.020)
    gaps = [b - a for a, b in itertools.pairwise(arrivals)]  # type: ignore[operator]
    assert gaps == pytest.approx([0.010] * len(gaps))
    throughput = 199 * 1000 / (arrivals[-1] - arrivals[0])  # type: ignore[operator]
    assert throughput == pytest.approx(100_000, rel=1e-6)
    assert model.backlog_s(0.2) == pytest.approx(200 * 0.010 - 0.2)
    assert model.backlog_s(5.0) == 0.0
    # Below the rate nothing queues: only the serialization time is added.
    idle = LinkModel(parse_spec("rate=800"), seed=0, ordered=True)
    assert idle.transit(1.0, 100) == pytest.approx(1.001)
    assert idle.transit(2.0, 100) == pytest.approx(2.001)


def test_udp_rate_queue_drops_when_full() -> None:
    model = LinkModel(parse_spec("rate=80"), seed=0, ordered=False)  # 10 ms per 100 bytes
    got = [model.transit(0.0, 100) for _ in range(UDP_QUEUE_LIMIT + 50)]
    assert sum(g is None for g in got) == 50
    assert model.dropped["queue"] == 50
    # Once the queue has drained, packets pass again.
    assert model.transit(UDP_QUEUE_LIMIT * 0.010 + 1.0, 100) is not None


def test_schedule_applies_the_phase_active_at_send_time() -> None:
    sched = Schedule(
        (Phase(1.0, parse_spec("delay=100")), Phase(2.0, parse_spec("delay=300,loss=100")))
    )
    assert sched.spec_at(0.5) == LinkSpec()  # before the first phase: perfect
    assert sched.spec_at(1.0).delay_ms == 100
    assert sched.spec_at(1.999).delay_ms == 100
    assert sched.spec_at(2.0).delay_ms == 300
    model = LinkModel(sched, seed=0, ordered=False)
    assert model.transit(0.5, 10) == pytest.approx(0.5)
    assert model.transit(1.5, 10) == pytest.approx(1.6)
    assert model.transit(2.5, 10) is None
    with pytest.raises(SpecError, match="increasing"):
        Schedule((Phase(1.0, LinkSpec()), Phase(1.0, LinkSpec())))
    with pytest.raises(SpecError, match="loss is not possible on a TCP link"):
        LinkModel(sched, seed=0, ordered=True)


def test_trace_replays_with_zero_order_hold() -> None:
    trace = parse_trace("# recorded\nt_s,delay_ms,loss\n0,20,0\n1.5,200,0\n3,50,100\n")
    assert [r.t_s for r in trace.rows] == [0, 1.5, 3]
    model = LinkModel(trace, seed=0, ordered=False)
    assert model.transit(0.0, 10) == pytest.approx(0.02)
    assert model.transit(1.49, 10) == pytest.approx(1.51)
    assert model.transit(2.9, 10) == pytest.approx(3.1)  # 200 ms held, no interpolation
    assert model.transit(10.0, 10) is None  # the last row holds for ever: 100 % loss
    with_jitter = parse_trace("t_s,delay_ms,loss,jitter_ms\n0,100,0,10\n")
    assert with_jitter.schedule().spec_at(5).jitter_ms == 10
    base = parse_spec("burst=3,loss=1,dist=pareto")
    sched = parse_trace("t_s,delay_ms,loss\n0,10,0\n1,10,5\n").schedule(base)
    assert sched.spec_at(0).burst == 0 and sched.spec_at(0).loss_pct == 0
    assert sched.spec_at(1) == LinkSpec(delay_ms=10, loss_pct=5, burst=3, dist="pareto")


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", None),
        ("t_s,delay_ms\n0,1\n", "header"),
        ("t_s,delay_ms,loss\n", "no rows"),
        ("t_s,delay_ms,loss\n0,1,0\n0,2,0\n", "trace:3: t_s must increase"),
        ("t_s,delay_ms,loss\n0,x,0\n", "trace:2: delay_ms='x' is not a number"),
        ("t_s,delay_ms,loss\n0,1,101\n", "percentage"),
        ("t_s,delay_ms,loss\n0,1\n", "expected 3 columns"),
        ("t_s,delay_ms,loss\n0,1,0\n5,1e15,0\n", "trace:3: delay_ms=1e15 ms is more than 600000"),
        ("t_s,delay_ms,loss,jitter_ms\n0,1,0,1e308\n", "trace:2: jitter_ms=1e308 ms is more"),
    ],
)
def test_trace_errors(text: str, message: str | None) -> None:
    with pytest.raises(SpecError, match=message or "empty trace"):
        parse_trace(text)


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ("delay=abc", "delay='abc' is not a number"),
        ("delay=-5", "delay=-5 must be >= 0"),
        ("delay=inf", "not a finite number"),
        ("latency=5", "unknown SPEC key 'latency'"),
        ("delay", "is not KEY=VALUE"),
        ("delay=5,,jitter=1", "empty item"),
        ("delay=5,delay=6", "given twice"),
        ("loss=120", r"loss=120 is a percentage in \[0, 100\]"),
        ("burst=3", "burst without loss"),
        ("loss=5,burst=0.5", "0, 1 or more"),
        ("loss=90,burst=2", "too short for loss=90%"),
        ("dist=cauchy", "dist='cauchy' is not one of normal, uniform, pareto"),
        ("outage=5", "START_S\\+DURATION_S"),
        ("outage=5+0", "duration must be > 0"),
        ("outage=1+5,outage=3+1", "outages overlap"),
        ("reorder=maybe", "must be 1 or 0"),
        # Outside check: absurd sizes were taken, and then nothing was ever forwarded.
        ("delay=1e308", r"delay=1e308 ms is more than 600000 ms \(10 minutes\)"),
        ("delay=1e15", "delay=1e15 ms is more than 600000 ms"),
        ("delay=600000.5ms", "delay=600000.5 ms is more than 600000 ms"),
        ("jitter=1e308", "jitter=1e308 ms is more than 600000 ms"),
        ("rate=1e-300", r"rate=1e-300 kbit/s is below 1 kbit/s.*rate=0, for no limit"),
        ("rate=0.999", "rate=0.999 kbit/s is below 1 kbit/s"),
    ],
)
def test_spec_errors_are_clear(spec: str, message: str) -> None:
    with pytest.raises(SpecError, match=message):
        parse_spec(spec)


def test_spec_parses_every_key_and_round_trips() -> None:
    spec = parse_spec(
        " delay=100ms , jitter=10, dist=pareto, loss=2.5%, burst=3, rate=512, "
        "outage=20+2, outage=5s+1s, reorder=1"
    )
    assert spec == LinkSpec(
        delay_ms=100,
        jitter_ms=10,
        dist="pareto",
        loss_pct=2.5,
        burst=3,
        rate_kbitps=512,
        outages=((5, 1), (20, 2)),
        reorder=True,
    )
    assert parse_spec(spec.to_text()) == spec
    assert parse_spec("") == LinkSpec() and parse_spec("  ").perfect
    assert parse_spec("loss=5,burst=1") == LinkSpec(loss_pct=5, burst=1)


def test_spec_sizes_are_bounded_where_no_link_study_goes() -> None:
    """Delay and jitter up to 10 minutes and a rate from 1 kbit/s (or 0, no limit) are taken,
    beyond that one line: in SPECs, in a LinkSpec built directly, in scenarios and traces."""
    assert (MAX_DELAY_MS, MIN_RATE_KBITPS) == (600_000.0, 1.0)
    spec = parse_spec("delay=600000,jitter=600000ms,rate=1")
    assert (spec.delay_ms, spec.jitter_ms, spec.rate_kbitps) == (600_000, 600_000, 1)
    assert parse_spec("rate=0").rate_kbitps == 0
    for kwargs in ({"delay_ms": 1e15}, {"jitter_ms": 6e5 + 1}, {"rate_kbitps": 1e-300}):
        with pytest.raises(SpecError, match=r"600000 ms|below 1 kbit/s"):
            LinkSpec(**kwargs)  # type: ignore[arg-type]
    # A 10-minute delay still gives a finite arrival the relay can schedule.
    slowest = parse_spec("delay=600000,rate=1")
    assert LinkModel(slowest, seed=0, ordered=True).transit(0.0, 125) == pytest.approx(601.0)


def test_tcp_link_refuses_loss_with_a_clear_message() -> None:
    with pytest.raises(SpecError, match=r"loss is not possible on a TCP link.*udp/"):
        LinkModel(parse_spec("loss=1"), seed=0, ordered=True)


def test_same_seed_same_decisions_other_seed_other_decisions() -> None:
    spec = parse_spec("delay=50,jitter=20,dist=pareto,loss=10,burst=3,reorder=1")

    def run(seed: int) -> list[float | None]:
        model = LinkModel(spec, seed=seed, ordered=False)
        return [model.transit(i * 0.01, 200) for i in range(2000)]

    assert run(7) == run(7)
    assert run(7) != run(8)
    # Delay and loss draw from separate streams: the k-th packet a lossy link forwards gets the
    # k-th delay of the same link without loss.
    lossy = LinkModel(spec, seed=7, ordered=False)
    clean = LinkModel(parse_spec("delay=50,jitter=20,dist=pareto,reorder=1"), 7, False)
    times = [i * 0.01 for i in range(2000)]
    kept = [(a - t) for t in times if (a := lossy.transit(t, 200)) is not None]
    clean_delays = [clean.transit(t, 200) - t for t in times]  # type: ignore[operator]
    assert 1500 < len(kept) < 1950
    assert kept == pytest.approx(clean_delays[: len(kept)])


def write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


def test_scenario_with_phases(tmp_path: Path) -> None:
    path = write(
        tmp_path / "s.toml",
        '[[phase]]\nstart_s = 0\nboth = "delay=50"\n'
        '[[phase]]\nstart_s = 10\nup = "delay=300,loss=2,burst=3"\n',
    )
    up, down = load_scenario(path)
    assert up.spec_at(5) == down.spec_at(5) == LinkSpec(delay_ms=50)
    assert up.spec_at(10) == LinkSpec(delay_ms=300, loss_pct=2, burst=3)
    assert down.spec_at(10) == LinkSpec()  # left out: a perfect link in that phase


def test_scenario_with_traces(tmp_path: Path) -> None:
    write(tmp_path / "up.csv", "t_s,delay_ms,loss\n0,100,0\n2,10,0\n")
    both = write(tmp_path / "both.toml", 'trace = "up.csv"\ndown_base = "jitter=3"\n')
    up, down = load_scenario(both)
    assert up.spec_at(1).delay_ms == down.spec_at(1).delay_ms == 100
    assert down.spec_at(3) == LinkSpec(delay_ms=10, jitter_ms=3)
    one = write(tmp_path / "one.toml", '[trace]\nup = "up.csv"\ndown_base = "delay=7"\n')
    with pytest.raises(SpecError, match="takes up"):
        load_scenario(one)
    one = write(tmp_path / "one.toml", 'down_base = "delay=7"\n[trace]\nup = "up.csv"\n')
    up, down = load_scenario(one)
    assert up.spec_at(3).delay_ms == 10 and down.spec_at(3) == LinkSpec(delay_ms=7)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (None, "scenario file .* does not exist"),
        ("[[phase]\n", "not valid TOML"),
        ("", "found neither"),
        ('[[phase]]\nstart_s = 0\nup = "delay=x"\n', "phase 1 up: delay='x' is not a number"),
        ('[[phase]]\nup = "delay=1"\n', "phase 1: start_s"),
        ('[[phase]]\nstart_s = 0\nboth = "delay=1"\nup = "delay=2"\n', "not both"),
        ("[[phase]]\nstart_s = 0\nspeed = 3\n", "unknown key"),
        ("[[phase]]\nstart_s = 5\n[[phase]]\nstart_s = 1\n", "increasing order"),
        ('trace = "nope.csv"\n', "trace file .*nope.csv does not exist"),
        ('trace = "x.csv"\n[[phase]]\nstart_s = 0\n', "not both"),
        ("delay = 5\n", "unknown key"),
        ("[[phase]]\nstart_s = 0\nup = 5\n", "must be a SPEC string"),
        ('[[phase]]\nstart_s = 0\nboth = "jitter=1e308"\n', "phase 1 up: jitter=1e308 ms is"),
        ('[[phase]]\nstart_s = 0\ndown = "rate=1e-300"\n', "phase 1 down: rate=1e-300 kbit/s"),
        ('trace = "x.csv"\nup_base = "delay=1e15"\n', "up_base: delay=1e15 ms is more than"),
    ],
)
def test_scenario_errors(tmp_path: Path, text: str | None, message: str) -> None:
    path = tmp_path / "scenario.toml"
    if text is not None:
        write(path, text)
    with pytest.raises(SpecError, match=message):
        load_scenario(path)


def test_direction_stats() -> None:
    stats = DirectionStats.from_samples(4, 1, [40.0, 10.0, 30.0, 20.0], lateness_ms=[0.1, 0.3])
    assert (stats.p50_ms, stats.max_ms) == (25.0, 40.0)
    assert stats.p90_ms == pytest.approx(37.0)
    assert stats.late_max_ms == 0.3
    assert stats.loss_pct == 20.0
    assert stats.line("up").startswith("up: forwarded 4, dropped 1 (20.0%), delay p50 25.0")
    empty = DirectionStats.from_samples(0, 0, [])
    assert empty.p50_ms is None and empty.to_dict()["loss_pct"] == 0.0
    assert "p50 -" in empty.line("down")


def test_a_refused_send_is_a_send_error_not_a_forwarded_packet() -> None:
    """The relay's lane: a send the system refuses (ECONNREFUSED, no route) is counted as a send
    error of its direction and shown in the summary; it was counted as forwarded before."""
    from egc_experiments.relay import Lane, Recorder

    refuse = [False, True, False]

    def send(data: bytes) -> None:
        if refuse.pop(0):
            raise ConnectionRefusedError(111, "Connection refused")

    recorder = Recorder(seed=0)
    model = LinkModel(Schedule.constant(parse_spec("")), seed=1, ordered=False)
    lane = Lane(None, model, 0.0, send, recorder)  # type: ignore[arg-type]  # delay 0: no timer
    for _ in range(3):
        lane.push(b"x", 0.0)
    stats = recorder.stats()
    assert (stats.forwarded, stats.dropped, stats.send_errors) == (2, 0, 1)
    assert stats.line("up").endswith("; send errors 1")
    assert stats.to_dict()["send_errors"] == 1
    assert (
        DirectionStats.from_samples(0, 0, [], send_errors=3)
        .line("down")
        .endswith("; send errors 3")
    )


def test_what_a_lane_still_holds_when_it_closes_is_counted_in_flight() -> None:
    """Outside check: delay=5000, 50 datagrams, SIGTERM at 4.4 s printed 'forwarded 0,
    dropped 0'. What the lane held (delayed, or behind a rate limit) is now in_flight, in the
    line and the JSON, so forwarded + dropped + in_flight + send_errors is what was read."""
    import asyncio

    from egc_experiments.relay import Lane, Recorder

    loop = asyncio.new_event_loop()
    try:
        recorder = Recorder(seed=0)
        sent: list[bytes] = []
        model = LinkModel(parse_spec("delay=5000,loss=20"), seed=3, ordered=False)
        lane = Lane(loop, model, 0.0, sent.append, recorder)
        for i in range(50):
            lane.push(b"x", i * 0.02)
        lane.close()
    finally:
        loop.close()
    stats = recorder.stats()
    assert sent == [] and stats.forwarded == 0 and stats.dropped == model.dropped_total > 0
    assert stats.in_flight == model.forwarded == 50 - stats.dropped
    assert stats.to_dict()["in_flight"] == stats.in_flight
    assert f"; in flight at stop {stats.in_flight}; send errors 0" in stats.line("up")
    assert DirectionStats.from_samples(1, 0, [1.0]).to_dict()["in_flight"] == 0
