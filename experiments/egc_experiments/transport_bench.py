"""TCP against UDP on a lossy, delayed link, measured with the real processes (docs/transport.md).

::

    python -m egc_experiments.transport_bench --out runs.json [--duration 60] [--seeds 0,1]

Each scenario is one emulated run (``egc_experiments.emulated``): the hallway, the ``forward``
operator (stick held forward, EGC in shared mode), the robot, the operator process and
``egc-teleop link`` in network namespaces when root (loopback otherwise), ``--duration``
seconds from the operator's first stick. Scenarios:

- ``tcp``: delay 100 ms, jitter 20 ms (normal) each way, no loss (the relay cannot drop bytes
  of a TCP stream);
- ``tcp+kernel loss``: the same delays in the relay and 5 % loss each way in the kernel
  (nftables in the middle namespace): TCP retransmits, and what follows a lost segment waits;
- ``udp``: our ``udp/`` (a TCP link for Zenoh's reliable traffic, a best-effort UDP link for
  the data), the same delays, 5 % loss each way on the UDP datagrams in the relay (and on the
  TCP half's packets in the kernel, with nft);
- ``udp plain``: the same loss with Zenoh's UDP link alone (``rel=0``);
- ``udp mixed``: the same loss with Zenoh's mixed-reliability QUIC (``rel=1;mixed_rel=1``);
- ``udp, no loss``: the delays alone, for the cost of UDP itself.

Per run, on the robot's clock: the accepted commands' age p50/p99 (the robot's summary), the
largest command gap over any 1 s window (telemetry ``cmd_gap_max_ms``) and its p99 over the
cycles, the time in HOLD and how often HOLD was entered for a command timeout, the operator's
view age p50/p99 (the age of the newest telemetry it had when it sent a command: how fresh the
downlink is), the distance driven, and the relay's own counts.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from egc_experiments import netns
from egc_experiments.emulated import NS_PER_S, run_emulated
from egc_experiments.run_point import RunPoint

DELAY = {"delay_ms": 100.0, "jitter_ms": 20.0}


def scenarios() -> list[tuple[str, dict[str, Any]]]:
    lossy = {"transport": "udp", "loss": 5.0, **DELAY}
    out: list[tuple[str, dict[str, Any]]] = [
        ("tcp", {"transport": "tcp", **DELAY}),
        ("udp", lossy),
        ("udp plain", lossy | {"extra": {"udp": "plain"}}),
        ("udp mixed", lossy | {"extra": {"udp": "mixed"}}),
        ("udp, no loss", {"transport": "udp", **DELAY}),
    ]
    if netns.nft_unavailable_reason() is None:
        out.insert(1, ("tcp+kernel loss", {"transport": "tcp", "loss": 5.0, **DELAY}))
    return out


def _pct(values: Sequence[float], q: float) -> float | None:
    return round(float(np.percentile(values, q)), 1) if len(values) else None


def robot_side(workdir: Path, result: dict[str, Any]) -> dict[str, Any]:
    """Gap, HOLD and view-age figures from the recorder's telemetry of the run's window."""
    lines = [json.loads(x) for x in (workdir / "watch.jsonl").read_text().splitlines() if x]
    t0, t_end = result["t0_ns"], result["end_ns"]
    window = [ln for ln in lines if t0 <= ln["t"] <= t_end]
    gaps = [float(ln["gap"]) for ln in window if ln.get("gap") is not None]
    views = [float(ln["va"]) for ln in window if ln.get("va") is not None]
    hold_s = 0.0
    timeouts = 0
    for i, ln in enumerate(window):
        nxt = window[i + 1]["t"] if i + 1 < len(window) else ln["t"]
        if ln["state"] == "HOLD":
            hold_s += (nxt - ln["t"]) / NS_PER_S
            before = window[i - 1]["state"] if i else "DRIVING"
            timeouts += before != "HOLD" and ln.get("reason") == "command timeout"
    # Command arrivals: the robot runs a cycle on every accepted command, so a new ``seq`` in
    # the telemetry marks an arrival (stamped on the robot's clock).
    arrivals = [ln["t"] for i, ln in enumerate(window) if i and ln["seq"] > window[i - 1]["seq"]]
    inter = np.diff(np.asarray(arrivals, dtype=np.float64)) / 1e6 if len(arrivals) > 1 else []
    return {
        "arrival_gap_p50_ms": _pct(inter, 50),
        "arrival_gap_p99_ms": _pct(inter, 99),
        "arrival_gap_max_ms": round(float(np.max(inter)), 1) if len(inter) else None,
        "arrival_gaps_over_100ms": int(np.sum(np.asarray(inter) > 100.0)),
        "gap_max_ms": round(max(gaps), 1) if gaps else None,
        "gap_p99_ms": _pct(gaps, 99),
        "robot_hold_s": round(hold_s, 2),
        "timeout_holds": timeouts,
        "view_age_p50_ms": _pct(views, 50),
        "view_age_p99_ms": _pct(views, 99),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m egc_experiments.transport_bench")
    parser.add_argument("--out", required=True, metavar="FILE.json")
    parser.add_argument("--duration", type=float, default=60.0, metavar="S")
    parser.add_argument("--seeds", default="0", metavar="N,N")
    parser.add_argument("--only", action="append", metavar="NAME", help="run only these")
    args = parser.parse_args(argv)
    rows: list[dict[str, Any]] = []
    base = Path(tempfile.mkdtemp(prefix="egc-transport-"))
    for seed in (int(s) for s in args.seeds.split(",")):
        for name, kw in scenarios():
            if args.only and name not in args.only:
                continue
            point = RunPoint(
                world="hallway", operator="forward", seed=seed, max_time_s=args.duration, **kw
            )
            workdir = base / f"{name.replace(' ', '_').replace(',', '')}-{seed}"
            started = time.monotonic()
            result = run_emulated(point, workdir)
            row = {"scenario": name, "seed": seed, **robot_side(workdir, result)}
            for key in ("outcome", "path_m", "hold_s", "hold_events", "cmd_age_p50_ms"):
                row[key] = result[key]
            row |= {
                "cmd_age_p99_ms": result["cmd_age_p99_ms"],
                "stale_rejected": result["stale_rejected"],
                "emulated": result["emulated"],
                "kernel_loss": result["kernel_loss"],
                "link": result["link"],
                "link_tcp": result.get("link_tcp"),
                "wall_s": round(time.monotonic() - started, 1),
                "workdir": str(workdir),
                "t0_ns": result["t0_ns"],
                "end_ns": result["end_ns"],
            }
            rows.append(row)
            brief = {k: v for k, v in row.items() if k not in ("link", "link_tcp")}
            print(json.dumps(brief), file=sys.stderr, flush=True)
            Path(args.out).write_text(json.dumps(rows, indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
