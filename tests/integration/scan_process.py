"""The observer's lidar in a process of its own: ``python -m tests.integration.scan_process``.

A robot holds when no scan has arrived for 200 ms (``scan_timeout_s``). CI runs 11, 44 and 79,
on a machine kept busy by other work, saw the robot hold for "sensor stale" (run 79: "newest
scan 261 ms old") and then wait for a centred stick that the test's operator never gives. The
scans came from a thread of the pytest worker, shared with the test's Zenoh callbacks (every
telemetry decoded) and its polling. A real lidar driver is a process of its own; so is this one,
and it does nothing else. That was not the whole cause: run 87 saw "newest scan 211 ms old" with
this process. So it reports its own gaps, and the robot how late its loop woke.

Arguments: ``ENDPOINT MODE ROBOT PERIOD_S RANGE_M``. It publishes an all-``RANGE_M`` scan every
``PERIOD_S`` (paced on the clock, not by sleeping a period after each one) until its stdin
closes. A line ``range R`` on stdin changes its range (``nan``: beams without information). It
prints ``ready`` once its session is open, then ``gap MS`` for every gap between two of its
scans longer than two periods: a robot that held for "sensor stale" then says whether its lidar
went quiet.
"""

from __future__ import annotations

import json
import math
import sys
import threading
import time

import numpy as np
import zenoh
from egc_common import keys
from egc_common.messages import ScanMessage
from egc_common.transport import ZenohOptions, build_config, open_config

QUICK_RETRY = {"period_init_ms": 20, "period_max_ms": 50, "period_increase_factor": 1.5}


def quick_config(endpoint: str, mode: str) -> zenoh.Config:
    """A test's own Zenoh session to ``endpoint``. It usually opens before the robot listens; the
    product's retry (250 ms, doubling to 1 s) then connected it up to a second after the robot
    was ready, so the test's sessions retry every 20-50 ms."""
    config = build_config(ZenohOptions(mode=mode, connect=(endpoint,)))
    config.insert_json5("connect/retry", json.dumps(QUICK_RETRY))
    return config


def scan(stamp_ns: int, range_m: float, beams: int = 360) -> bytes:
    return ScanMessage(
        stamp_ns=stamp_ns,
        angle_min_rad=-math.pi,
        angle_increment_rad=2 * math.pi / beams,
        range_min_m=0.05,
        range_max_m=10.0,
        ranges_m=np.full(beams, range_m, np.float32),
        no_return_is_free=True,
    ).encode()


def main(argv: list[str]) -> int:
    endpoint, mode, robot, period_s, range_m = (
        argv[0],
        argv[1],
        argv[2],
        float(argv[3]),
        float(argv[4]),
    )
    session = open_config(quick_config(endpoint, mode))
    setting = {"range_m": range_m}
    stop = threading.Event()

    def read_commands() -> None:
        for line in sys.stdin:
            words = line.split()
            if words[:1] == ["range"]:
                setting["range_m"] = float(words[1])
        stop.set()  # stdin closed: the test is done

    threading.Thread(target=read_commands, daemon=True).start()
    print("ready", flush=True)
    key = keys.scan(robot)
    due = time.monotonic()
    last: float | None = None
    while not stop.is_set():
        now = time.monotonic()
        session.put(key, scan(time.monotonic_ns(), setting["range_m"]))
        if last is not None and now - last > 2 * period_s:
            print(f"gap {(now - last) * 1e3:.0f}", flush=True)
        last = now
        due = max(due + period_s, now + period_s / 2)  # after a stall: no burst to catch up
        stop.wait(max(0.0, due - time.monotonic()))
    session.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
