"""Issue 5 benchmark: does the operator view keep up with 20 Hz telemetry carrying 720-point scans?

Messages "arrive" on a fixed 20 Hz schedule for ``--minutes`` (default 10). Each one is a
msgpack telemetry payload as the robot publishes it (720 scan points, guide circles, pose); the
loop decodes it and hands it to ``OperatorView.on_telemetry``, as the operator process does, plus
a link round trip and a state message once a second. For every message we measure

- cost: decode + logging time (the time the operator's receive path is busy);
- lag: time from its scheduled arrival until it is logged. When logging falls behind, the next
  arrival is already past and the lag grows, so a view that keeps up has the same lag at the
  end as at the start.

Once a minute the recording is flushed and the flush timed: the sink's backlog (Rerun encodes
and writes on background threads of this process, so their CPU is in the measurement too).
Sinks: ``file`` (the default: an .rrd, as ``--save``/episodes) or ``web`` (``--serve-web``: the
gRPC server that buffers for the web viewer). Pass: median lag of the last window within 1 ms of
the first window's, and 99% of the last window's messages logged within one period (50 ms).

    python bench/bench_view.py [--minutes 10] [--sink file|web] [--out FILE.json]
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from egc_common.messages import StateMessage, Telemetry, decode_telemetry
from egc_common.transport import free_tcp_port
from egc_experiments.bench_results import write_result
from egc_operator.view import OperatorView, open_view, record_episode

RATE_HZ = 20.0
BEAMS = 720


def telemetry(i: int, stamp_ns: int) -> Telemetry:
    """Cycle i of a robot weaving down a 2.8 m corridor: 720 points, circles, a moving pose."""
    a = np.linspace(-math.pi, math.pi, BEAMS, endpoint=False)
    heading = 0.3 * math.sin(i / 40.0)
    s, c = np.sin(a + heading), np.cos(a + heading)
    with np.errstate(divide="ignore"):
        r = np.minimum(np.where(s != 0, 1.4 / np.abs(s), np.inf), 8.0 / np.maximum(np.abs(c), 1e-3))
    r = np.minimum(r, 8.0) + 0.01 * np.sin(37.0 * a + i)
    scan = np.column_stack((r * np.cos(a), r * np.sin(a))).astype(np.float32)
    w = 0.2 * math.cos(i / 40.0)
    return Telemetry(
        seq=i,
        stamp_ns=stamp_ns,
        state="DRIVING",
        mode="shared",
        v_ref=0.14,
        w_ref=0.0,
        v_cmd=0.12,
        w_cmd=w,
        w_si=0.9,
        region="conditional" if i % 50 < 20 else "safe",
        side="left",
        limiter="egc" if i % 50 < 20 else "none",
        igc=(0.59, 0.0, 0.4),
        agc=(0.5, 0.3, 0.5),
        egc=(0.55, 0.12, 0.55),
        r_rc=0.595,
        scan_xy=scan,
        pose=(0.006 * i, 0.3 * math.sin(i / 40.0), heading),
        cmd_age_ms=20.0,
        scan_age_ms=30.0,
        operator="op1",
        profile="pioneer3dx",
        cycle=i,
    )


@dataclass
class Window:
    lag_ms: list[float] = field(default_factory=list)
    cost_ms: list[float] = field(default_factory=list)
    decode_ms: list[float] = field(default_factory=list)
    flush_ms: float = math.nan
    rss_mb: float = math.nan

    def summary(self) -> dict[str, float | int]:
        lag = np.array(self.lag_ms)
        cost = np.array(self.cost_ms)
        return {
            "messages": len(lag),
            "lag_median_ms": float(np.median(lag)),
            "lag_p99_ms": float(np.percentile(lag, 99)),
            "lag_max_ms": float(lag.max()),
            "cost_median_ms": float(np.median(cost)),
            "cost_p99_ms": float(np.percentile(cost, 99)),
            "decode_median_ms": float(np.median(self.decode_ms)),
            "flush_ms": self.flush_ms,
            "rss_mb": self.rss_mb,
        }


def rss_mb() -> float:
    """Resident memory of this process (Linux), MB."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return math.nan


def open_sink(sink: str, workdir: Path) -> tuple[OperatorView, Path | None]:
    if sink == "file":
        path = workdir / "bench_view.rrd"
        return record_episode(path, "bench"), path
    args = argparse.Namespace(
        serve_web=free_tcp_port(), connect=None, save=None, no_view=False
    )  # the web viewer's gRPC server buffers the data; no browser is attached
    return open_view(args, "bench"), None


def run(minutes: float, sink: str, window_s: float) -> dict[str, Any]:
    period = 1.0 / RATE_HZ
    total = round(minutes * 60.0 * RATE_HZ)
    per_window = max(1, round(window_s * RATE_HZ))
    windows: list[Window] = []
    with tempfile.TemporaryDirectory(prefix="bench-view-") as tmp:
        view, path = open_sink(sink, Path(tmp))
        robot_epoch = time.monotonic_ns()
        cpu0, t0 = time.process_time(), time.perf_counter()
        for i in range(total):
            if i % per_window == 0:
                if windows:
                    windows[-1].flush_ms = _timed_flush(view)
                    windows[-1].rss_mb = rss_mb()
                windows.append(Window())
            arrival = t0 + i * period
            stamp = robot_epoch + round(i * period * 1e9)
            payload = telemetry(i, stamp).encode()  # the robot's work, before the arrival
            wait = arrival - time.perf_counter()
            if wait > 0:
                time.sleep(wait)
            start = time.perf_counter()
            decoded = decode_telemetry(payload)
            assert isinstance(decoded, Telemetry)
            parsed = time.perf_counter()
            view.on_telemetry(decoded)
            if i % round(RATE_HZ) == 0:
                view.on_link(3.0, robot_epoch - time.monotonic_ns())
                view.on_state(StateMessage(stamp, "DRIVING", "operator op1 in control", "op1"))
            done = time.perf_counter()
            w = windows[-1]
            w.lag_ms.append((done - arrival) * 1e3)
            w.cost_ms.append((done - start) * 1e3)
            w.decode_ms.append((parsed - start) * 1e3)
        windows[-1].flush_ms = _timed_flush(view)
        windows[-1].rss_mb = rss_mb()
        wall, cpu = time.perf_counter() - t0, time.process_time() - cpu0
        close_start = time.perf_counter()
        view.close()
        close_s = time.perf_counter() - close_start
        file_mb = path.stat().st_size / 1e6 if path else None
    first, last = np.array(windows[0].lag_ms), np.array(windows[-1].lag_ms)
    keeps_up = bool(
        np.median(last) <= np.median(first) + 1.0 and np.percentile(last, 99) < period * 1e3
    )
    return {
        "benchmark": "bench_view",
        "sink": sink,
        "minutes": minutes,
        "rate_hz": RATE_HZ,
        "beams": BEAMS,
        "messages": total,
        "wall_s": wall,
        "cpu_s": cpu,
        "cpu_share_of_one_core": cpu / wall,
        "close_s": close_s,
        "file_mb": file_mb,
        "window_s": window_s,
        "windows": [w.summary() for w in windows],
        "keeps_up": keeps_up,
    }


def _timed_flush(view: OperatorView) -> float:
    """How long the sink takes to drain what was logged (its backlog), ms."""
    start = time.perf_counter()
    view.flush()
    return (time.perf_counter() - start) * 1e3


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=10.0, help="run length (default 10)")
    parser.add_argument("--sink", choices=("file", "web"), default="file")
    parser.add_argument("--window", type=float, help="seconds per reported window (default 60)")
    parser.add_argument(
        "--out", type=Path, help="JSON file (default bench/results/view.json, view-web.json)"
    )
    args = parser.parse_args(argv)
    if args.minutes <= 0:
        parser.error("--minutes must be positive")
    window_s = args.window or min(60.0, args.minutes * 60.0 / 5.0)
    result = run(args.minutes, args.sink, window_s)
    print(
        f"operator view, {RATE_HZ:.0f} Hz telemetry with {BEAMS}-point scans, "
        f"{args.minutes:g} min, sink={args.sink}"
    )
    print(
        f"{'window':>8} {'msgs':>6} {'lag med':>8} {'lag p99':>8} {'lag max':>8} "
        f"{'cost med':>9} {'cost p99':>9} {'decode':>7} {'flush':>7} {'RSS MB':>7}"
    )
    for k, row in enumerate(result["windows"]):
        print(
            f"{k * window_s:>7.0f}s {row['messages']:>6} {row['lag_median_ms']:>8.2f} "
            f"{row['lag_p99_ms']:>8.2f} {row['lag_max_ms']:>8.1f} {row['cost_median_ms']:>9.2f} "
            f"{row['cost_p99_ms']:>9.2f} {row['decode_median_ms']:>7.3f} "
            f"{row['flush_ms']:>7.1f} {row['rss_mb']:>7.0f}"
        )
    print(
        f"CPU {result['cpu_share_of_one_core']:.0%} of one core; close {result['close_s']:.2f} s; "
        f"file {result['file_mb'] or 0:.0f} MB; keeps up: {result['keeps_up']} "
        "(all times in ms; lag = arrival to logged)"
    )
    out = write_result("view" if args.sink == "file" else f"view-{args.sink}", result, args.out)
    print(f"wrote {out}")
    return 0 if result["keeps_up"] else 1


if __name__ == "__main__":
    raise SystemExit(main())
