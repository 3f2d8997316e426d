"""Issue 31 benchmark: start and stop the ROS 2 driver many times with traffic flowing; count the
crashes, the hangs and the stops whose last /cmd_vel was not zero.

A CI run under load segfaulted in ``destroy_node`` (issue 31); destroying a node while another
thread spins its executor is a known rclpy crash (ros2/rclpy#663). Here a traffic process (its own rclpy participant) publishes 360-beam LaserScans at
50 Hz and Odometry at 100 Hz and records every /cmd_vel it receives. A cycle worker (a child
process, ``PYTHONFAULTHANDLER=1``) runs cycles one after the other, each the life of a robot
process's driver: the real ``Ros2Driver``, a cycle (poll, then a 0.2 m/s command) on every
accepted scan in the executor's thread (``set_scan_listener``) and at 20 Hz in a loop thread,
until scans have arrived and a random 0-0.3 s more; then, as the robot process stops, the loop
and the listener stop, a zero command, ``close()``. A worker that dies (a signal, a non-zero
exit) is a crash: its stderr tail (the faulthandler's stacks) is shown and a new worker takes
the next cycle. A cycle that takes longer than ``--hang-s`` is a hang (SIGABRT for the stacks).
Each cycle's commands carry its number in their turn rate (``TAG_RADPS`` per cycle), so the
traffic process's record says whose they are; the zeros that follow them in arrival order are
that cycle's stop. A stop is clean when the last /cmd_vel of its cycle that the traffic process
received is zero (DESIGN 11: one last zero twist before the node closes); a cycle none of whose
commands arrived (discovery had not matched /cmd_vel yet) is counted apart, as unheard.

``--busy N`` keeps N more processes spinning (``while True: pass``) for the whole run, so the
cycles run with the cores taken. ``--stall-s S`` holds the executor's thread inside a scan
callback for S seconds as each stop begins (a thread that the scheduler does not run for that
long): ``close()`` must wait for it rather than destroy the node under it. To compare with
another version of the driver, put its ``robot`` folder first on PYTHONPATH; the driver's file
is printed.

    python bench/bench_ros2_teardown.py [--cycles 200] [--busy 2] [--stall-s 8] [--out FILE.json]

Exits non-zero on any crash, hang or unclean stop; skips (exit 0, a line) without rclpy.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import queue
import random
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

from egc_experiments.bench_results import write_result

ROOT = Path(__file__).resolve().parents[1]
SCAN_HZ = 50.0
ODOM_HZ = 100.0
LOOP_HZ = 20.0
TAG_RADPS = 1e-3  # cycle k commands a turn of (k + 1) * TAG_RADPS


# -- the traffic process -----------------------------------------------------------------------


def traffic(record: Path) -> int:
    """Scans and odometry out, every /cmd_vel recorded; ends when stdin closes."""
    import numpy as np
    import rclpy
    from egc_common.executor_thread import ExecutorThread
    from geometry_msgs.msg import Twist
    from nav_msgs.msg import Odometry
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
    from sensor_msgs.msg import LaserScan

    rclpy.init()
    node = rclpy.create_node("bench_teardown_traffic")
    received: list[tuple[float, float]] = []
    reliable = QoSProfile(
        depth=10, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE
    )
    node.create_subscription(
        Twist, "/cmd_vel", lambda m: received.append((m.linear.x, m.angular.z)), reliable
    )
    scan_pub = node.create_publisher(LaserScan, "/scan", qos_profile_sensor_data)
    odom_pub = node.create_publisher(Odometry, "/odom", qos_profile_sensor_data)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    errors: list[Exception] = []
    spinner = ExecutorThread(executor, errors.append)
    spinner.start()
    beams = 360
    angles = -math.pi + 2 * math.pi / beams * np.arange(beams)
    c = np.cos(angles)
    with np.errstate(divide="ignore"):
        ranges = np.where(c > 1e-6, 2.0 / c, np.inf)
    ranges = np.where(ranges <= 8.0, ranges, np.inf).astype(np.float32)
    stop = threading.Event()
    threading.Thread(target=lambda: (sys.stdin.read(), stop.set()), daemon=True).start()
    period_ns = int(1e9 / ODOM_HZ)
    every = round(ODOM_HZ / SCAN_HZ)
    tick = 0
    next_ns = time.monotonic_ns()
    while not stop.wait(max(0, next_ns - time.monotonic_ns()) / 1e9):
        stamp = node.get_clock().now().to_msg()
        if tick % every == 0:
            scan = LaserScan()
            scan.header.stamp = stamp
            scan.header.frame_id = "laser"
            scan.angle_min = -math.pi
            scan.angle_increment = 2 * math.pi / beams
            scan.angle_max = math.pi - scan.angle_increment
            scan.range_min = 0.1
            scan.range_max = 8.0
            scan.ranges = ranges
            scan_pub.publish(scan)
        odom = Odometry()
        odom.header.stamp = stamp
        odom.header.frame_id = "odom"
        odom.child_frame_id = "base_link"
        odom.pose.pose.orientation.w = 1.0
        odom_pub.publish(odom)
        tick += 1
        next_ns += period_ns
    out = spinner.stop(10.0)
    record.write_text(json.dumps({"cmd_vel": received, "errors": [repr(e) for e in errors]}))
    if out:
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown()
    return 0


# -- the cycle worker --------------------------------------------------------------------------


def cycles(first: int, last: int, seed: int, stall_s: float, scan_deadline_s: float) -> int:
    """Cycles ``first`` .. ``last - 1``, one JSON line each on stdout when it has ended."""
    import logging

    from egc_common.messages import BaseCommand
    from egc_robot import ros2_driver
    from egc_robot.ros2_core import Ros2Settings

    logging.basicConfig(level=logging.WARNING, format="worker: %(name)s: %(message)s")
    print(json.dumps({"driver": ros2_driver.__file__}), flush=True)
    rng = random.Random(seed * 1_000_003 + first)
    for k in range(first, last):
        start_ns = time.monotonic_ns()
        driver = ros2_driver.Ros2Driver(Ros2Settings())
        shut = threading.Event()
        seq = [0]

        def cycle(
            driver: Any = driver, shut: threading.Event = shut, seq: list[int] = seq, k: int = k
        ) -> None:
            # What the robot's node does per cycle; the node stops doing it once shut down.
            if shut.is_set():
                return
            now = time.monotonic_ns()
            driver.poll(now)
            seq[0] += 1
            tag = (k + 1) * TAG_RADPS
            driver.send(BaseCommand(stamp_ns=now, seq=seq[0], linear_mps=0.2, angular_radps=tag))

        def loop(cycle: Any = cycle, shut: threading.Event = shut) -> None:
            while not shut.wait(1.0 / LOOP_HZ):
                cycle()

        stalled = threading.Event()

        def on_scan(
            cycle: Any = cycle, shut: threading.Event = shut, stalled: threading.Event = stalled
        ) -> None:
            if stall_s > 0 and shut.is_set() and not stalled.is_set():
                stalled.set()
                time.sleep(stall_s)  # --stall-s: the executor's thread held inside a callback
                return
            cycle()

        driver.set_scan_listener(on_scan)
        loop_thread = threading.Thread(target=loop, daemon=True)
        loop_thread.start()
        deadline = time.monotonic() + scan_deadline_s
        while driver.scans_received < 3 and time.monotonic() < deadline:
            time.sleep(0.01)
        time.sleep(rng.uniform(0.0, 0.3))
        shut.set()
        loop_thread.join()
        if stall_s > 0:
            stalled.wait(scan_deadline_s)
        close_ns = time.monotonic_ns()
        driver.send(
            BaseCommand(stamp_ns=close_ns, seq=seq[0] + 1, linear_mps=0.0, angular_radps=0.0)
        )
        driver.close()
        end_ns = time.monotonic_ns()
        line = {
            "cycle": k,
            "start_ns": start_ns,
            "close_ns": close_ns,
            "end_ns": end_ns,
            "scans": driver.scans_received,
            "stalled": stalled.is_set(),
        }
        print(json.dumps(line), flush=True)
    return 0


# -- the conductor -----------------------------------------------------------------------------


def _reader(stream: Any, lines: queue.Queue[str | None]) -> None:
    for line in stream:
        lines.put(line)
    lines.put(None)


def _tail(path: Path, n: int = 40) -> str:
    return "\n".join(path.read_text(errors="replace").splitlines()[-n:])


def conduct(args: argparse.Namespace, workdir: Path) -> dict[str, Any]:
    me = [sys.executable, str(Path(__file__).resolve())]
    os.environ["PYTHONFAULTHANDLER"] = "1"  # a crash prints every thread's stack
    busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(args.busy)]
    record = workdir / "traffic.json"
    traffic_proc = subprocess.Popen(
        [*me, "--role", "traffic", "--record", str(record)], stdin=subprocess.PIPE
    )
    done: list[dict[str, Any]] = []
    crashes: list[dict[str, Any]] = []
    hangs: list[dict[str, Any]] = []
    driver_file = None
    t0 = time.monotonic()
    load_before = os.getloadavg()[0]
    try:
        k = 0
        n_worker = 0
        while k < args.cycles:
            n_worker += 1
            err_path = workdir / f"worker{n_worker}.err"
            argv = [*me, "--role", "cycles", "--first", str(k), "--last", str(args.cycles)]
            argv += ["--seed", str(args.seed), "--stall-s", str(args.stall_s)]
            with err_path.open("w") as err:
                worker = subprocess.Popen(
                    argv,
                    stdout=subprocess.PIPE,
                    stderr=err,
                    text=True,
                )
            lines: queue.Queue[str | None] = queue.Queue()
            threading.Thread(target=_reader, args=(worker.stdout, lines), daemon=True).start()
            while True:
                try:
                    line = lines.get(timeout=args.hang_s)
                except queue.Empty:
                    worker.send_signal(signal.SIGABRT)  # faulthandler prints the stacks
                    worker.wait(30)
                    hangs.append({"cycle": k, "stderr": _tail(err_path)})
                    print(f"cycle {k}: HANG (no end within {args.hang_s:g} s)", flush=True)
                    print(_tail(err_path), flush=True)
                    k += 1
                    break
                if line is None:  # the worker has gone
                    code = worker.wait()
                    if k < args.cycles or code != 0:
                        crashes.append({"cycle": k, "returncode": code, "stderr": _tail(err_path)})
                        print(f"cycle {k}: CRASH (worker exit {code})", flush=True)
                        print(_tail(err_path), flush=True)
                        k += 1
                    break
                info = json.loads(line)
                if "driver" in info:
                    driver_file = info["driver"]
                    continue
                done.append(info)
                k = info["cycle"] + 1
                if k % 20 == 0:
                    print(
                        f"{k} cycles, {len(crashes)} crashes, {len(hangs)} hangs, "
                        f"{time.monotonic() - t0:.0f} s",
                        flush=True,
                    )
    finally:
        assert traffic_proc.stdin is not None
        traffic_proc.stdin.close()
        traffic_proc.wait(60)
        for p in busy:
            p.kill()
            p.wait()
    elapsed_s = time.monotonic() - t0
    received = json.loads(record.read_text())["cmd_vel"]
    return {
        "driver": driver_file,
        "cycles": args.cycles,
        "completed": len(done),
        "crashes": crashes,
        "hangs": hangs,
        **stops([d["cycle"] for d in done], received),
        "close_s": sorted((d["end_ns"] - d["close_ns"]) / 1e9 for d in done),
        "elapsed_s": elapsed_s,
        "busy": args.busy,
        "stall_s": args.stall_s,
        "stalled": sum(d["stalled"] for d in done),
        "load_before": load_before,
        "load_after": os.getloadavg()[0],
    }


def stops(completed: list[int], received: list[list[float]]) -> dict[str, list[int]]:
    """The completed cycles whose last /cmd_vel received was not zero (``unclean_stops``), and
    those none of whose commands arrived (``unheard``), from the traffic process's record in
    arrival order: a tagged command belongs to the cycle its tag names, a zero to the cycle of
    the tagged command before it."""
    last_is_zero: dict[int, bool] = {}
    current = None
    for v, w in received:
        if v == 0.0 and w == 0.0:
            if current is not None:
                last_is_zero[current] = True
        else:
            current = round(w / TAG_RADPS) - 1
            last_is_zero[current] = False
    return {
        "unclean_stops": [k for k in completed if last_is_zero.get(k) is False],
        "unheard": [k for k in completed if k not in last_is_zero],
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cycles", type=int, default=200)
    parser.add_argument("--busy", type=int, default=0, help="busy-loop processes (default: 0)")
    parser.add_argument("--hang-s", type=float, default=60.0, help="a cycle this long is a hang")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument(
        "--stall-s",
        type=float,
        default=0.0,
        help="hold the executor's thread inside a scan callback this long as each stop begins "
        "(default: 0, no stall)",
    )
    parser.add_argument("--out", help="JSON file (default bench/results/ros2_teardown.json)")
    parser.add_argument("--role", choices=("conductor", "traffic", "cycles"), default="conductor")
    parser.add_argument("--record", type=Path, help=argparse.SUPPRESS)
    parser.add_argument("--first", type=int, default=0, help=argparse.SUPPRESS)
    parser.add_argument("--last", type=int, default=0, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.role == "traffic":
        return traffic(args.record)
    if args.role == "cycles":
        return cycles(args.first, args.last, args.seed, args.stall_s, scan_deadline_s=30.0)
    if args.cycles < 1 or args.busy < 0 or args.stall_s < 0:
        parser.error("--cycles must be >= 1, --busy and --stall-s >= 0")
    try:
        import rclpy  # noqa: F401
    except ImportError:
        print("bench_ros2_teardown: skipped, rclpy is not installed (pip install -e '.[ros2]')")
        return 0
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    os.environ.setdefault("ROS_DOMAIN_ID", str(random.randrange(1, 102)))
    import tempfile

    with tempfile.TemporaryDirectory(prefix="bench_ros2_teardown.") as tmp:
        result = conduct(args, Path(tmp))
    close_s = result.pop("close_s")
    result["close_p50_s"] = close_s[len(close_s) // 2] if close_s else math.nan
    result["close_max_s"] = close_s[-1] if close_s else math.nan
    print(f"driver: {result['driver']}")
    print(
        f"{result['cycles']} start/stop cycles with {args.busy} busy processes"
        + (f", a {args.stall_s:g} s stall in {result['stalled']}" if args.stall_s else "")
        + ": "
        f"{result['completed']} completed, {len(result['crashes'])} crashes, "
        f"{len(result['hangs'])} hangs, {len(result['unclean_stops'])} stops whose last /cmd_vel "
        f"was not zero ({len(result['unheard'])} cycles unheard); close() p50 {result['close_p50_s']:.2f} s, max "
        f"{result['close_max_s']:.2f} s; {result['elapsed_s']:.0f} s in all; load "
        f"{result['load_before']:.2f} -> {result['load_after']:.2f}"
    )
    print(f"wrote {write_result('ros2_teardown', result, args.out)}")
    failed = result["crashes"] or result["hangs"] or result["unclean_stops"]
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
