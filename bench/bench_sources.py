"""Issue 29 benchmark: what command sources and locks (DESIGN 14) cost the control cycle.

The same controller cycle, in the same process, on the same 360-beam scan with an obstacle the
filter acts on: (a) without ``[[source]]`` tables, an operator driving (the baseline); (b) with
four sources and three locks, a navigation source driving (the arbitration, the source's own
link statistics, ``filter_velocity``). Each cycle is one input (a command or a source message
and a lock heartbeat) and one ``step``, as the robot runs them. ``arbitrate`` alone is timed too.
Target: (b) / (a) median <= 1.25 (the arbitration must not matter beside the filter).

    python bench/bench_sources.py [--cycles N] [--out FILE.json]
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import statistics
import sys
import time
from pathlib import Path

import msgpack
import numpy as np
from egc_common.profiles import get_profile
from egc_common.scan import Scan
from egc_common.source_msg import SourceCommand, encode_lock
from egc_robot.controller import ControllerConfig, RobotController
from egc_robot.pipeline import PipelineConfig
from egc_robot.source_mux import LockFeed, LockSpec, MuxConfig, SourceSpec, arbitrate

PROFILE = get_profile("pioneer3dx")
MS = 1_000_000
T0 = 3600 * 1000 * MS
MUX = MuxConfig(
    (
        SourceSpec("nav", "zenoh", 10, 0.5),
        SourceSpec("dock", "zenoh", 20, 0.5),
        SourceSpec("planner", "zenoh", 30, 0.5),
        SourceSpec("teleop", "operator", 100, 0.5),
    ),
    (LockSpec("pause", 200, 1.0), LockSpec("hb", 300, 0.5), LockSpec("zone", 5, 1.0)),
)
TARGET_RATIO = 1.25


def scan() -> Scan:
    """Open space with a box 0.8 m ahead, slightly right: the filter changes the command."""
    n = 360
    angles = -math.pi + 2 * math.pi / n * np.arange(n)
    ranges = np.full(n, 5.0)
    ranges[np.abs(angles + 0.1) < 0.25] = 0.8
    return Scan.uniform(ranges, -math.pi, 2 * math.pi / n, 0.05, 10.0)


def command(seq: int, now: int, x: float = 1.0) -> bytes:
    msg = {"v": 1, "seq": seq, "stamp_ns": now - MS, "x": x, "y": 0.0, "mode": "shared"}
    msg |= {"deadman": True, "estop": False, "reset": False, "op": "op"}
    return bytes(msgpack.packb(msg))


def time_operator(cycles: int) -> list[float]:
    c = RobotController(ControllerConfig(PipelineConfig(PROFILE)), T0)
    s, now, out = scan(), T0, []
    c.on_scan(s, now)
    c.on_command(command(1, now, x=0.0), now)  # control is taken with a centred stick
    c.step(now)
    for i in range(cycles):
        now += 50 * MS
        c.on_scan(s, now)
        t0 = time.perf_counter_ns()
        c.on_command(command(2 + i, now), now)
        out_ = c.step(now)
        out.append((time.perf_counter_ns() - t0) / 1e3)
    assert out_.telemetry.state == "DRIVING" and out_.telemetry.limiter != "none"
    return out


def time_sources(cycles: int) -> list[float]:
    cfg = ControllerConfig(PipelineConfig(PROFILE), sources=MUX)
    c = RobotController(cfg, T0)
    s, now, out = scan(), T0, []
    for i in range(cycles):
        now += 50 * MS
        c.on_scan(s, now)
        t0 = time.perf_counter_ns()
        c.on_source("nav", SourceCommand(i + 1, now - MS, PROFILE.v_max_mps, 0.0).encode(), now)
        for lock in ("pause", "hb", "zone"):
            c.on_lock(lock, encode_lock(False), now)
        out_ = c.step(now)
        out.append((time.perf_counter_ns() - t0) / 1e3)
    t = out_.telemetry
    assert t.state == "DRIVING" and t.source == "nav" and t.limiter != "none", t
    return out


def time_arbitrate(calls: int) -> list[float]:
    claims = {"nav": T0, "dock": T0 - 600 * MS, "teleop": T0 - 700 * MS}
    locks = {"pause": LockFeed(False, T0), "hb": LockFeed(False, T0), "zone": LockFeed(True, T0)}
    out = []
    for _ in range(calls):
        t0 = time.perf_counter_ns()
        arbitrate(MUX, claims, locks, T0 + 10 * MS)
        out.append((time.perf_counter_ns() - t0) / 1e3)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cycles", type=int, default=3000)
    ap.add_argument("--out", default="bench/results/bench_sources.json")
    args = ap.parse_args(argv)
    time_operator(200), time_sources(200)  # warm up
    # Interleaved rounds, so that a busy machine slows both alike.
    base: list[float] = []
    mux: list[float] = []
    rounds = 5
    for _ in range(rounds):
        base += time_operator(args.cycles // rounds)
        mux += time_sources(args.cycles // rounds)
    arb = time_arbitrate(args.cycles)
    rows = {
        "operator, no sources (baseline)": base,
        "nav source, 4 sources, 3 locks": mux,
        "arbitrate alone": arb,
    }
    print(
        f"control cycle, {platform.processor() or platform.machine()}, Python {platform.python_version()}"
    )
    print(f"{'case':<36}{'median us':>12}{'p95 us':>10}")
    result = {}
    for name, values in rows.items():
        med, p95 = statistics.median(values), float(np.percentile(values, 95))
        result[name] = {"median_us": med, "p95_us": p95, "n": len(values)}
        print(f"{name:<36}{med:>12.1f}{p95:>10.1f}")
    ratio = statistics.median(mux) / statistics.median(base)
    ok = ratio <= TARGET_RATIO
    print(f"ratio sources / baseline (median): {ratio:.2f}")
    print(f"target ratio <= {TARGET_RATIO}: {'met' if ok else 'MISSED'}")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(
        json.dumps(
            {"rows": result, "ratio": ratio, "target_met": ok, "python": sys.version}, indent=2
        )
    )
    print(f"wrote {out}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
