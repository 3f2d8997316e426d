"""Issue 31 benchmark: robot, operator and view together for N minutes; do they stay flat?

A real robot process (``--driver sim``, the simulated camera unless ``--camera none``) and a
real operator process (the ``demo`` script on a loop, its view served to the web viewer's gRPC
buffer as ``--serve-web`` does, with the camera panel) talk Zenoh on loopback for ``--minutes``.
Every ``--sample-s`` seconds this script reads each process's CPU time (utime + stime) and RSS
from /proc (and the 1-min load average); at the end it reads the robot's ``--summary``, whose
``view_timeline`` has, per second, the largest view age the operator reported while driving.

It compares the first window (``--window-minutes``, default a sixth of the run, at most 10)
with the last one, after ``--warmup-s`` (start-up costs are not a trend):

- CPU, % of one core, per process: the mean over the window;
- RSS, MB, per process: the mean over the window;
- view lag: the median of the per-second view ages in the window.

Targets (issue 31): the last window's CPU and RSS within 5 % of the first's (RSS: or within
2 MB, the allocator's granularity on a ~100 MB process), view lag flat (the last window's
median within 20 ms of the first's), and the robot without a camera at <= 10 % of a core and
<= 100 MB (issue 27: with the camera <= 25 % and <= 150 MB). The robot's figures include what
serving one operator costs. Exits 1 when a target is missed; the table says which.

    python bench/bench_soak.py [--minutes 10] [--camera sim|none] [--window-minutes W]
                               [--sample-s 5] [--out FILE.json]

Writes bench/results/soak.json (soak-none.json with ``--camera none``) unless ``--out``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from egc_experiments.bench_results import write_result

CLI = [sys.executable, "-m", "egc_app.cli"]
ROBOT_ID = "soak"
DRIFT_MAX = 0.05
RSS_SLACK_MB = 2.0
LAG_DRIFT_MS = 20.0
LIMITS = {"none": (10.0, 100.0), "sim": (25.0, 150.0)}  # robot: % of a core, MB


def _cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def window_stats(
    samples: list[dict[str, Any]], name: str, t0: float, t1: float
) -> dict[str, float]:
    """Mean CPU % and RSS MB of process ``name`` between t0 and t1 (seconds since start)."""
    inside = [s for s in samples if t0 <= s["t_s"] <= t1]
    if len(inside) < 2:
        raise SystemExit(f"bench soak: too few samples in the window {t0:.0f}-{t1:.0f} s")
    first, last = inside[0], inside[-1]
    cpu_pct = 100.0 * (last[name]["cpu_s"] - first[name]["cpu_s"]) / (last["t_s"] - first["t_s"])
    rss = statistics.fmean(s[name]["rss_mb"] for s in inside)
    return {"cpu_pct": round(cpu_pct, 2), "rss_mb": round(rss, 1)}


def _mean_load(samples: list[dict[str, Any]], t0: float, t1: float) -> float:
    return round(statistics.fmean(s["load_1m"] for s in samples if t0 <= s["t_s"] <= t1), 2)


def minute_series(samples: list[dict[str, Any]], names: list[str]) -> list[dict[str, Any]]:
    """Per minute of the run: each process's CPU % of a core and mean RSS MB, and the machine's
    1-min load average: the trend behind the two windows (a climb, a step, or the load)."""
    out: list[dict[str, Any]] = []
    t0 = samples[0]["t_s"]
    for minute in range(int((samples[-1]["t_s"] - t0) // 60)):
        lo, hi = t0 + 60 * minute, t0 + 60 * (minute + 1)
        inside = [s for s in samples if lo <= s["t_s"] <= hi]
        if len(inside) < 2:
            continue
        row: dict[str, Any] = {"minute": minute, "load_1m": _mean_load(samples, lo, hi)}
        for name in names:
            row[name] = window_stats(samples, name, lo, hi)
        out.append(row)
    return out


def lag_ms(timeline: list[dict[str, Any]], t0_s: float, t1_s: float) -> float | None:
    ages = [
        p["view_age_ms"]
        for p in timeline
        if t0_s <= p["t_s"] <= t1_s and p.get("view_age_ms") is not None
    ]
    return float(statistics.median(ages)) if ages else None


def run(args: argparse.Namespace) -> dict[str, Any]:
    work = Path(tempfile.mkdtemp(prefix="egc-bench-soak-"))
    endpoint = f"tcp/127.0.0.1:{_free_port()}"
    duration_s = 60.0 * args.minutes
    summary_file = work / "robot.json"
    robot_log = (work / "robot.log").open("w")
    op_log = (work / "operator.log").open("w")
    robot = subprocess.Popen(
        [*CLI, "robot", "--driver", "sim", "--robot", ROBOT_ID, "--listen", endpoint,
         "--camera", args.camera, "--summary", str(summary_file), "--log-level", "WARNING"],
        stdin=subprocess.DEVNULL, stdout=robot_log, stderr=robot_log,
    )  # fmt: skip
    operator = subprocess.Popen(
        [*CLI, "operator", "--robot", ROBOT_ID, "--script", "demo", "--loop", "--no-status",
         "--serve-web", str(_free_port()), "--zenoh-connect", endpoint,
         "--duration", str(args.warmup_s + duration_s + 5)],
        stdin=subprocess.DEVNULL, stdout=op_log, stderr=op_log,
    )  # fmt: skip
    procs = {"robot": robot, "operator": operator}
    samples: list[dict[str, Any]] = []
    start = time.monotonic()
    clock_start_s = time.monotonic()  # the robot's view_timeline is on this clock too
    try:
        time.sleep(args.warmup_s)
        t_end = time.monotonic() + duration_s
        while True:
            now = time.monotonic()
            sample: dict[str, Any] = {"t_s": now - start, "load_1m": os.getloadavg()[0]}
            for name, proc in procs.items():
                if proc.poll() is not None:
                    raise SystemExit(
                        f"bench soak: the {name} process ended early ({proc.returncode}); "
                        f"see {work}/{name}.log"
                    )
                sample[name] = {"cpu_s": _cpu_s(proc.pid), "rss_mb": _rss_mb(proc.pid)}
            samples.append(sample)
            if now >= t_end:
                break
            time.sleep(min(args.sample_s, max(0.0, t_end - now)))
    finally:
        for proc in (operator, robot):
            if proc.poll() is None:
                proc.terminate()
        for proc in (operator, robot):
            try:
                proc.wait(20)
            except subprocess.TimeoutExpired:
                proc.kill()
        robot_log.close()
        op_log.close()
    summary = json.loads(summary_file.read_text()) if summary_file.exists() else {}
    window_s = 60.0 * min(args.window_minutes or args.minutes / 6.0, args.minutes / 2.0)
    first = (args.warmup_s, args.warmup_s + window_s)
    last = (samples[-1]["t_s"] - window_s, samples[-1]["t_s"])
    timeline = summary.get("view_timeline", [])
    out: dict[str, Any] = {
        "minutes": args.minutes,
        "camera": args.camera,
        "window_s": window_s,
        "samples": len(samples),
        "work_dir": str(work),
    }
    for name in procs:
        out[name] = {
            "first": window_stats(samples, name, *first),
            "last": window_stats(samples, name, *last),
        }
    base = clock_start_s
    out["view_lag_ms"] = {
        "first": lag_ms(timeline, base + first[0], base + first[1]),
        "last": lag_ms(timeline, base + last[0], base + last[1]),
    }
    out["load_1m"] = {
        "first": _mean_load(samples, *first),
        "last": _mean_load(samples, *last),
    }
    out["minutes_series"] = minute_series(samples, list(procs))
    out["camera_summary"] = summary.get("camera")
    out["checks"] = checks(out)
    return out


def checks(out: dict[str, Any]) -> dict[str, bool]:
    result: dict[str, bool] = {}
    for name in ("robot", "operator"):
        a, b = out[name]["first"], out[name]["last"]
        # CPU within 5 % of the first window (or 0.5 points of a core, a sampling step)
        result[f"{name} cpu flat"] = abs(b["cpu_pct"] - a["cpu_pct"]) <= max(
            DRIFT_MAX * a["cpu_pct"], 0.5
        )
        result[f"{name} rss flat"] = abs(b["rss_mb"] - a["rss_mb"]) <= max(
            DRIFT_MAX * a["rss_mb"], RSS_SLACK_MB
        )
    lag = out["view_lag_ms"]
    result["view lag flat"] = (
        lag["first"] is not None
        and lag["last"] is not None
        and lag["last"] - lag["first"] <= LAG_DRIFT_MS
    )
    cpu_max, rss_max = LIMITS["none" if out["camera"] == "none" else "sim"]
    result[f"robot <= {cpu_max:g} % of a core"] = out["robot"]["last"]["cpu_pct"] <= cpu_max
    result[f"robot <= {rss_max:g} MB"] = out["robot"]["last"]["rss_mb"] <= rss_max
    return result


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--minutes", type=float, default=10.0)
    parser.add_argument("--camera", choices=("sim", "none"), default="sim")
    parser.add_argument("--window-minutes", type=float, default=None)
    parser.add_argument("--sample-s", type=float, default=5.0)
    parser.add_argument("--warmup-s", type=float, default=20.0)
    parser.add_argument(
        "--out", type=Path, default=None, help="default bench/results/soak.json, soak-none.json"
    )
    args = parser.parse_args()
    if not 0.5 <= args.minutes <= 24 * 60:
        parser.error("--minutes must be within [0.5, 1440]")
    if not 0.5 <= args.sample_s <= 60:
        parser.error("--sample-s must be within [0.5, 60]")
    out = run(args)
    name = "soak" if args.camera == "sim" else f"soak-{args.camera}"
    path = write_result(name, out, args.out)  # the machine, date and commit with it
    print(f"soak {args.minutes:g} min, camera {args.camera}, windows of {out['window_s']:.0f} s")
    print(f"{'':10} {'CPU % first':>12} {'last':>8} {'RSS MB first':>13} {'last':>8}")
    for name in ("robot", "operator"):
        a, b = out[name]["first"], out[name]["last"]
        print(
            f"{name:10} {a['cpu_pct']:12.1f} {b['cpu_pct']:8.1f} {a['rss_mb']:13.1f} "
            f"{b['rss_mb']:8.1f}"
        )
    lag = out["view_lag_ms"]
    print(f"view lag median: first {lag['first']} ms, last {lag['last']} ms")
    for name, ok in out["checks"].items():
        print(f"  {'ok  ' if ok else 'MISS'} {name}")
    print(f"written to {path}")
    return 0 if all(out["checks"].values()) else 1


if __name__ == "__main__":
    sys.exit(main())
