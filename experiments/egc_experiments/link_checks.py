"""The demo through emulated links, end to end (issue 12's acceptance runs).

Each scenario runs ``egc-teleop demo`` (robot with the simulated hallway, the built-in operator
script, no view) for ``--duration`` seconds, with ``egc-teleop link`` between operator and robot,
and reads the robot's own run summary back: distance, collisions, time in HOLD, time capped by
the latency governor, command ages, stale rejections. Distances are reported as a ratio to the
loopback run of the same invocation, so a slow or loaded machine shows up in both.

    python -m egc_experiments.link_checks --out docs/link-aware-driving.md [--duration 30]

Runs one scenario at a time (they are real-time and use real processes).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any


@dataclass(frozen=True, slots=True)
class Scenario:
    name: str
    up: str | None = None
    down: str | None = None
    transport: str = "tcp"
    link_aware: bool = True


def scenarios() -> list[Scenario]:
    cell = "delay=200,jitter=50"
    lossy = "delay=100,jitter=20,loss=5"
    sat = "delay=500,jitter=100"
    out: list[Scenario] = [Scenario("loopback")]
    for aware in (True, False):
        out += [
            Scenario("200 +- 50 ms, tcp", cell, cell, "tcp", aware),
            Scenario("100 +- 20 ms, 5% loss, udp", lossy, lossy, "udp", aware),
            Scenario("500 +- 100 ms, tcp", sat, sat, "tcp", aware),
        ]
    return out


def run_scenario(s: Scenario, duration_s: float, seed: int, workdir: Path) -> dict[str, Any]:
    out = workdir / f"run-{time.monotonic_ns()}.json"
    cmd = [sys.executable, "-m", "egc_app.cli", "demo", "--no-view", "--duration", str(duration_s)]
    cmd += ["--json", str(out), "--transport", s.transport, "--link-seed", str(seed)]
    if s.up is not None:
        cmd += ["--up", s.up]
    if s.down is not None:
        cmd += ["--down", s.down]
    if not s.link_aware:
        cmd.append("--no-link-aware")
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=duration_s + 120)
    if proc.returncode != 0:
        raise RuntimeError(f"{s.name}: demo exited {proc.returncode}:\n{proc.stderr[-2000:]}")
    summary: dict[str, Any] = json.loads(out.read_text(encoding="utf-8"))
    return summary


def row(s: Scenario, summary: dict[str, Any], baseline_m: float) -> dict[str, Any]:
    by_state = summary.get("seconds_by_state", {})
    total = sum(by_state.values()) or 1.0
    lat = summary.get("command_latency", {})
    return {
        "scenario": s.name,
        "link_aware": s.link_aware,
        "distance_m": summary["distance_m"],
        "of_loopback": summary["distance_m"] / baseline_m if baseline_m else None,
        "collisions": summary["collisions"],
        "hold_pct": 100.0 * summary.get("hold_s", 0.0) / total,
        "driving_pct": 100.0 * by_state.get("DRIVING", 0.0) / total,
        "hold_events": summary.get("hold_events", 0),
        "latency_capped_s": summary.get("latency_limited_s", 0.0),
        "cmd_age_p50_ms": lat.get("p50_ms"),
        "cmd_age_p99_ms": lat.get("p99_ms"),
        "stale_rejected": summary.get("rejected", {}).get("stale", 0),
    }


def markdown(rows: list[dict[str, Any]], duration_s: float, command: str) -> str:
    def f(v: Any, spec: str) -> str:
        return "n/a" if v is None else format(v, spec)

    lines = [
        f"Made by `{command}` (each run {duration_s:g} s of the demo script, shared mode, "
        "the link given in both directions; DRIVING, HOLD: share of the robot's time, the rest "
        "IDLE: no operator in control yet, or never). Load average when it ended: "
        f"{os.getloadavg()[0]:.1f} on 2 cores.",
        "",
        "| link | link-aware | distance | of loopback | collisions | DRIVING | HOLD | HOLD entries "
        "| capped by latency | cmd age p50 / p99 | stale dropped |",
        "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for r in rows:
        lines.append(
            f"| {r['scenario']} | {'on' if r['link_aware'] else 'off'} | {r['distance_m']:.2f} m "
            f"| {f(r['of_loopback'], '.0%')} | {r['collisions']} | {r['driving_pct']:.0f}% "
            f"| {r['hold_pct']:.1f}% "
            f"| {r['hold_events']} | {r['latency_capped_s']:.1f} s "
            f"| {f(r['cmd_age_p50_ms'], '.0f')} / {f(r['cmd_age_p99_ms'], '.0f')} ms "
            f"| {r['stale_rejected']} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=30.0)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--out", type=Path, required=True, help="markdown table")
    parser.add_argument("--only", help="run only scenarios whose name contains this")
    args = parser.parse_args(argv)
    workdir = Path(tempfile.mkdtemp(prefix="egc-link-checks-"))
    rows: list[dict[str, Any]] = []
    baseline = run_scenario(Scenario("loopback"), args.duration, args.seed, workdir)
    base_m = float(baseline["distance_m"])
    rows.append(row(Scenario("loopback"), baseline, base_m))
    for s in scenarios()[1:]:
        if args.only and args.only not in s.name:
            continue
        rows.append(row(s, run_scenario(s, args.duration, args.seed, workdir), base_m))
        print(json.dumps(rows[-1]), file=sys.stderr, flush=True)
    command = "python -m egc_experiments.link_checks " + " ".join(argv or sys.argv[1:])
    args.out.write_text(markdown(rows, args.duration, command), encoding="utf-8")
    (args.out.with_suffix(".json")).write_text(json.dumps(rows, indent=2) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
