"""The bandwidth sweep of docs/bandwidth.md (issue 27 item 6): the demo through downlinks from
64 kbit/s to 4 Mbit/s, the camera on and off, 50-200 ms each way, loss on UDP.

Each point is one ``egc-teleop demo --no-view --duration S`` (the simulated robot with its
camera, or ``--camera none``, a scripted operator, ``egc-teleop link`` between them: ``--up
delay=D --down delay=D,rate=R[,loss=L]``), run one after the other; the same demo on loopback
(camera on and off) is run first, in the same sweep, for the distance ratios. From each robot
summary: distance (and its share of the loopback run with the same camera setting), HOLD
share, operator-lost events, collisions, view age p50 / p90, command age p99, the camera's
frames/s (while an operator drove: the summary's ``fps`` also counts the seconds before one
connected) and age p50, the view plane's kbit/s p50.

    python docs/bandwidth_sweep.py [--duration 20] [--out docs/bandwidth-sweep.json]
    nice python docs/bandwidth_sweep.py ...      # as docs/bandwidth.md's table was made

It prints the table as Markdown (the JSON has every summary's numbers) and the machine's load
average before and after: the demos run in real time, and on a busy machine (2 cores, load
15-25 while docs/bandwidth.md's table was made) the processes' stalls show in the ages.
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

DOCS = Path(__file__).resolve().parent
CLI = [sys.executable, "-m", "egc_app.cli"]


@dataclass(frozen=True)
class Point:
    """One demo of the sweep: the downlink's rate (kbit/s, 0: loopback, no relay), the delay
    each way, loss on the downlink (%, UDP), the camera."""

    rate_kbps: float
    delay_ms: float = 80.0
    loss_pct: float = 0.0
    camera: bool = True

    @property
    def transport(self) -> str:
        return "udp" if self.loss_pct else "tcp"

    def flags(self) -> list[str]:
        out = ["--camera", "sim" if self.camera else "none"]
        if not self.rate_kbps:
            return out
        down = f"delay={self.delay_ms:g},rate={self.rate_kbps:g}"
        if self.loss_pct:
            down += f",loss={self.loss_pct:g}"
        out += ["--up", f"delay={self.delay_ms:g}", "--down", down]
        return [*out, "--transport", self.transport]

    def label(self) -> str:
        if not self.rate_kbps:
            return "loopback"
        rate = (
            f"{self.rate_kbps / 1000:g} Mbit/s"
            if self.rate_kbps >= 1000
            else f"{self.rate_kbps:g} kbit/s"
        )
        loss = f", {self.loss_pct:g} % loss (UDP)" if self.loss_pct else ""
        return f"{rate}, {self.delay_ms:g} ms{loss}"


POINTS: tuple[Point, ...] = (
    Point(0),
    Point(0, camera=False),
    *(Point(r) for r in (64, 128, 192, 512, 1000, 4000)),
    *(Point(r, camera=False) for r in (64, 192, 512)),
    Point(192, delay_ms=50),
    Point(192, delay_ms=200),
    Point(512, loss_pct=2),
    Point(192, loss_pct=2),
)


def run(point: Point, duration_s: float) -> dict[str, Any]:
    with tempfile.TemporaryDirectory(prefix="egc-sweep-") as tmp:
        out = Path(tmp) / "demo.json"
        cmd = [*CLI, "demo", "--no-view", "--duration", f"{duration_s:g}", "--json", str(out)]
        started = time.monotonic()
        subprocess.run([*cmd, *point.flags()], stdin=subprocess.DEVNULL, capture_output=True)
        try:
            summary: dict[str, Any] = json.loads(out.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return {"error": "no summary"}
    by_state = summary.get("seconds_by_state", {})
    total = sum(by_state.values()) or 1.0
    camera = summary.get("camera") or {}
    driving = [
        e["cam_frames"]
        for e in summary.get("view_timeline", [])
        if "cam_frames" in e and "view_age_ms" in e
    ]
    return {
        "wall_s": round(time.monotonic() - started, 1),
        "distance_m": summary["distance_m"],
        "hold_pct": round(100 * summary["hold_s"] / total, 1),
        "operator_lost": summary.get("operator_lost", 0),
        "collisions": summary["collisions"],
        "view_age_ms": summary["view_age_ms"],
        "cmd_age_p99_ms": summary["command_latency"]["p99_ms"],
        "camera": camera or None,
        "camera_fps_driving": round(sum(driving) / len(driving), 1) if driving else None,
        "camera_age_ms": summary.get("camera_age_ms"),
        "downlink_kbps": summary.get("downlink_kbps"),
    }


def _ms(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.0f}"


def table(rows: list[tuple[Point, dict[str, Any]]]) -> str:
    base = {p.camera: r for p, r in rows if not p.rate_kbps and "error" not in r}
    lines = [
        "| downlink | camera | distance | HOLD | lost | view age p50 / p90 | cmd age p99 | "
        "camera frames/s | camera age p50 | view plane p50 |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for p, r in rows:
        if "error" in r:
            lines.append(f"| {p.label()} | {'on' if p.camera else 'off'} | {r['error']} |")
            continue
        ref = base.get(p.camera)
        share = (
            f" ({100 * r['distance_m'] / ref['distance_m']:.0f} %)"
            if ref and p.rate_kbps and ref["distance_m"]
            else ""
        )
        view = r["view_age_ms"]
        cam = r["camera"]
        fps = "off" if cam is None else f"{r['camera_fps_driving'] or 0:g} ({cam['codec']})"
        cam_age = "" if cam is None else _ms((r["camera_age_ms"] or {}).get("p50_ms"))
        kbps = (r["downlink_kbps"] or {}).get("p50")
        lines.append(
            f"| {p.label()} | {'on' if p.camera else 'off'} | {r['distance_m']:.2f} m{share} | "
            f"{r['hold_pct']:g} % | {r['operator_lost']} | {_ms(view['p50_ms'])} / "
            f"{_ms(view['p90_ms'])} ms | {_ms(r['cmd_age_p99_ms'])} ms | {fps} | "
            f"{cam_age}{' ms' if cam_age else ''} | {_ms(kbps)} kbit/s |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=20.0, metavar="S")
    parser.add_argument("--out", type=Path, default=DOCS / "bandwidth-sweep.json")
    args = parser.parse_args(argv)
    load_before = os.getloadavg()
    started = time.monotonic()
    rows = []
    for point in POINTS:
        result = run(point, args.duration)
        rows.append((point, result))
        print(f"{point.label()}, camera {'on' if point.camera else 'off'}: {result}", flush=True)
    load_after = os.getloadavg()
    minutes = (time.monotonic() - started) / 60
    print()
    print(table(rows))
    print(
        f"\n{len(POINTS)} demos of {args.duration:g} s in {minutes:.1f} min; load average "
        f"(1/5/15 min) {' '.join(f'{x:.1f}' for x in load_before)} before, "
        f"{' '.join(f'{x:.1f}' for x in load_after)} after, on {os.cpu_count()} cores"
    )
    args.out.write_text(
        json.dumps(
            {
                "duration_s": args.duration,
                "load_before": load_before,
                "load_after": load_after,
                "cpus": os.cpu_count(),
                "points": [{"point": vars(p), **r} for p, r in rows],
            },
            indent=2,
        )
        + "\n",
        encoding="utf-8",
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
