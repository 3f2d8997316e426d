"""A recorder next to the robot: every telemetry message, as JSON lines (emulated mode, DESIGN 10).

::

    python -m egc_experiments.watch --robot ID --connect tcp/127.0.0.1:7448 --out FILE.jsonl

It joins the robot's Zenoh network directly (in the robot's namespace, or on loopback), never
through the emulated link, so it sees the robot as the robot is, cycle by cycle, and writes one
line per telemetry message until SIGINT/SIGTERM. Keys (short, the file grows at 20-70 lines a
second): ``rx`` (arrival, monotonic ns), ``t`` (the robot's stamp, monotonic ns: the same clock
on one machine, whatever the namespace), ``state``, ``reason``, ``op`` (operator in control),
``pose`` ([x, y, yaw] or null), ``v``/``w`` (sent to the base), ``vr``/``wr`` (the operator's
command after eq. 4), ``lim`` (the limiter), ``age`` (command age, ms), ``gap`` (largest command
gap over the last second, ms), ``loss`` (link loss from seq gaps), ``tau`` (loop delay, ms),
``va`` (the operator's view age, ms), ``rej`` (rejected commands so far). It prints ``watch: ready`` on stderr once subscribed.
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
import time
from pathlib import Path
from typing import IO, Any

from egc_common import keys
from egc_common.messages import Rejection, Telemetry, decode_telemetry
from egc_common.stop_flag import stop_on_signals
from egc_common.transport import ZenohOptions, open_session, payload_bytes


def telemetry_line(rx_ns: int, t: Telemetry) -> dict[str, Any]:
    """The JSON line of one telemetry message (module docstring)."""
    return {
        "rx": rx_ns,
        "t": t.stamp_ns,
        "seq": t.seq,
        "state": t.state,
        "reason": t.reason,
        "op": t.operator,
        "pose": None if t.pose is None else [round(float(v), 5) for v in t.pose],
        "v": t.v_cmd,
        "w": t.w_cmd,
        "vr": t.v_ref,
        "wr": t.w_ref,
        "lim": t.limiter,
        "age": t.cmd_age_ms,
        "gap": t.cmd_gap_max_ms,
        "loss": t.link_loss,
        "tau": t.loop_delay_ms,
        "va": t.view_age_ms,
        "rej": t.rejected,
    }


class Writer:
    """Thread-safe line writer (Zenoh calls back from its own threads)."""

    def __init__(self, out: IO[str]) -> None:
        self._out = out
        self._lock = threading.Lock()
        self.lines = 0
        self.bad = 0

    def on_sample(self, sample: Any) -> None:
        rx = time.monotonic_ns()
        t = decode_telemetry(payload_bytes(sample))
        with self._lock:
            if isinstance(t, Rejection):
                self.bad += 1
                return
            self._out.write(json.dumps(telemetry_line(rx, t)) + "\n")
            self._out.flush()
            self.lines += 1


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m egc_experiments.watch", description=__doc__)
    parser.add_argument("--robot", default=keys.DEFAULT_ROBOT_ID, metavar="ID")
    parser.add_argument("--connect", required=True, metavar="ENDPOINT")
    parser.add_argument("--out", required=True, metavar="FILE.jsonl")
    args = parser.parse_args(argv)
    stop = stop_on_signals()  # not threading.Event: its set() can deadlock in a handler
    session = open_session(ZenohOptions(connect=(args.connect,)))
    with Path(args.out).open("w", encoding="utf-8") as out:
        writer = Writer(out)
        sub = session.declare_subscriber(keys.telemetry(args.robot), writer.on_sample)
        print("watch: ready", file=sys.stderr, flush=True)
        stop.wait()
        sub.undeclare()
        session.close()
    print(f"watch: {writer.lines} telemetry messages, {writer.bad} undecodable", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
