"""Issue 14 benchmark: ``egc-teleop replay`` throughput, scans per second, 720-beam scans.

ROS 2 logs written here with rosbags (MCAP and sqlite3): a robot at 10 Hz in a
6 x 4 m room with a box ahead that comes and goes between 0.4 m and 3 m, commanded 0.12 m/s
forward with a slow turn on ``/cmd_vel``, so the filter works through all its branches (pass,
expanded, stopped). The whole replay is timed (opening the log, reading and deserialising every
message, REP 117, the robot's pipeline, the summary), once without and once with ``--record``
(the Rerun recording: scan points, guide circles, arrows, four velocity series per scan), best
of ``--repeats``. Also the real third-party ``../shared/bags/Mapping1.bag`` (90 beams), when it
is there.

    python bench/bench_replay.py [--scans N] [--filter NAME] [--profile NAME] [--repeats N] [--out FILE.json]

Target: at least 500 scans/s without ``--record`` for 720-beam scans; exits non-zero when missed.
"""

from __future__ import annotations

import argparse
import math
import platform
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from egc_common.cli_args import PROFILE_HELP, profile_arg
from egc_common.profiles import get_profile
from egc_experiments.bench_results import write_result
from egc_experiments.log_replay import replay
from egc_robot.replay_core import Replayer
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

MAPPING1 = Path(__file__).resolve().parents[1] / ".." / "shared" / "bags" / "Mapping1.bag"
TARGET_SCANS_PER_S = 500.0
BEAMS = 720
PERIOD_NS = 100_000_000
START_NS = 1_700_000_000_000_000_000


def room_ranges(box_m: float, beams: int = BEAMS) -> np.ndarray:
    """A 6 x 4 m room seen from its middle, a 0.4 m box ``box_m`` ahead, a few NaN beams."""
    a = -math.pi + 2 * math.pi * np.arange(beams) / beams
    c, s = np.cos(a), np.sin(a)
    with np.errstate(divide="ignore"):
        r = np.minimum(
            np.where(c != 0, 3.0 / np.abs(c), np.inf), np.where(s != 0, 2.0 / np.abs(s), np.inf)
        )
    box = np.abs(a - 0.05) < math.atan2(0.2, box_m)
    r[box] = np.minimum(r[box], box_m / np.maximum(c[box], 1e-3))
    r[:: beams // 8] = np.nan  # a few beams without information
    return r.astype(np.float32)


def write_log(path: Path, scans: int, storage: StoragePlugin) -> Path:
    ts = get_typestore(Stores.ROS2_JAZZY)
    t = ts.types
    header = t["std_msgs/msg/Header"]
    stamp = t["builtin_interfaces/msg/Time"]
    vec = t["geometry_msgs/msg/Vector3"]
    twist = t["geometry_msgs/msg/Twist"]
    laser = t["sensor_msgs/msg/LaserScan"]
    empty = np.zeros(0, dtype=np.float32)
    with Writer(path, version=9, storage_plugin=storage) as w:
        scan_c = w.add_connection("/scan", laser.__msgtype__, typestore=ts)
        cmd_c = w.add_connection("/cmd_vel", twist.__msgtype__, typestore=ts)
        for i in range(scans):
            now = START_NS + i * PERIOD_NS
            box = 1.7 + 1.3 * math.cos(2 * math.pi * i / 200)
            cmd = twist(vec(0.12, 0.0, 0.0), vec(0.0, 0.0, 0.1 * math.sin(i / 30)))
            w.write(cmd_c, now - 1_000_000, ts.serialize_cdr(cmd, twist.__msgtype__))
            msg = laser(
                header(stamp(now // 10**9, now % 10**9), "laser"),
                -math.pi,
                math.pi - 2 * math.pi / BEAMS,
                2 * math.pi / BEAMS,
                0.0,
                0.1,
                0.05,
                10.0,
                room_ranges(box),
                empty,
            )
            w.write(scan_c, now, ts.serialize_cdr(msg, laser.__msgtype__))
    return path


def timed(path: Path, replayer: Replayer, record: Path | None, repeats: int) -> dict[str, Any]:
    best = math.inf
    summary: dict[str, Any] = {}
    for _ in range(repeats):
        if record is not None and record.exists():
            record.unlink()
        t0 = time.perf_counter()
        summary = replay(path, replayer, record=None if record is None else str(record))
        best = min(best, time.perf_counter() - t0)
    return {
        "scans": summary["scans"],
        "seconds": best,
        "scans_per_s": summary["scans"] / best,
        "changed": summary["changed"],
        "hold_s": summary["hold_s"],
        "rrd_bytes": record.stat().st_size if record is not None else None,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scans", type=int, default=2000)
    ap.add_argument("--filter", default="egc")
    ap.add_argument("--profile", default="pioneer3dx", type=profile_arg, help=PROFILE_HELP)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--out", type=Path, help="JSON file (default bench/results/replay.json)")
    args = ap.parse_args(argv)
    replayer = Replayer.for_filter(args.filter, get_profile(args.profile))
    rows: list[dict[str, Any]] = []
    storages = [("mcap", StoragePlugin.MCAP), ("sqlite3", StoragePlugin.SQLITE3)]
    print(
        f"egc-teleop replay, filter {args.filter}, profile {args.profile}, "
        f"{platform.processor() or platform.machine()}, Python {platform.python_version()}"
    )
    print(f"{'log':<28}{'beams':>6}{'scans':>7}{'record':>8}{'s':>8}{'scans/s':>10}{'changed':>9}")
    with tempfile.TemporaryDirectory() as tmp:
        logs: list[tuple[str, Path, int]] = []
        for name, plugin in storages:
            path = write_log(Path(tmp) / f"log_{name}", args.scans, plugin)
            logs.append((f"synthetic {name}", path, BEAMS))
        if MAPPING1.exists():
            logs.append(("Mapping1.bag (ROS 1)", MAPPING1, 90))
        for label, path, beams in logs:
            for record in (False, True):
                rrd = Path(tmp) / "replay.rrd" if record else None
                row = timed(path, replayer, rrd, args.repeats)
                row.update(log=label, beams=beams, record=record)
                rows.append(row)
                print(
                    f"{label:<28}{beams:>6}{row['scans']:>7}{'yes' if record else 'no':>8}"
                    f"{row['seconds']:>8.2f}{row['scans_per_s']:>10.0f}{row['changed']:>9}"
                )
    plain = [r for r in rows if r["beams"] == BEAMS and not r["record"]]
    met = all(r["scans_per_s"] >= TARGET_SCANS_PER_S for r in plain)
    print(f"target {BEAMS} beams >= {TARGET_SCANS_PER_S:.0f} scans/s: {'met' if met else 'MISSED'}")
    result = {
        "rows": rows,
        "target_scans_per_s": TARGET_SCANS_PER_S,
        "met": met,
        "filter": args.filter,
        "profile": args.profile,
        "python": sys.version,
    }
    print(f"wrote {write_result('replay', result, args.out)}")
    return 0 if met else 1


if __name__ == "__main__":
    raise SystemExit(main())
