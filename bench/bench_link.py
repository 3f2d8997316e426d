"""Issue 4 benchmark: the operator -> robot -> base link over Zenoh on loopback.

Processes: the robot is its own process (``egc-teleop robot --driver zenoh``). This process
plays both ends around it, so that both ends read one clock (CLOCK_MONOTONIC is shared by all
processes of a machine): a test-harness operator publishing pinned OperatorCommands at 50 Hz
(stamped with the robot clock obtained from its clock queryable) and the remote driver,
publishing 720-point scans at 20 Hz and receiving ``base/cmd``. The scans show a corridor with a
box 0.75 m ahead, so that the EGC filter expands the guide circle and modifies the command in
nearly every driving cycle (the run prints the share).

1. Latency from the operator's publish to the base receiving the filtered command: the robot
   runs a control cycle on each accepted command (and at its 20 Hz rate); its telemetry tells
   which cycle (``cycle``, the base command's ``seq``) used which command (``seq``), so each
   command is matched to the first base command computed from it. Targets: p50 <= 1 ms,
   p99 <= 5 ms.

   Its baseline, in the same run: a bare Zenoh echo (``bench/zenoh_echo.py``, its own Python
   process with the product's session configuration, listening on its own loopback endpoint)
   over the same two hops. This process publishes to it at the same 50 Hz, with the same
   publisher QoS as the operator's commands and a session connected the same way, payloads the
   size of an OperatorCommand; the echo republishes each at once, cut to the size of a
   BaseCommand, with the robot's base-command QoS. Half the run's length before the product's
   latency run and half after it (the scans and the robot's 20 Hz cycle go on throughout), so
   that drift of the machine touches both. The product's p50 and p99 are reported as ratios to
   the echo's. Target: p50 <= 1.3x the echo's.
2. Operator SIGKILL: a real ``egc-teleop operator`` process drives at full speed and is killed;
   time from the kill to the first zero command at the base. Target: <= 100 ms + v / decel.
3. Operator SIGSTOP (hung, TCP link open): time to the first braking command (the watchdog's
   HOLD) and to the zero command. Target: HOLD <= command_timeout + 100 ms.

    python bench/bench_link.py [--seconds S] [--trials N] [--out FILE.json]

The load average (``os.getloadavg``) before and after the latency runs goes into the results.

Exits non-zero when a target is missed.
"""

from __future__ import annotations

import argparse
import functools
import math
import os
import select
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from pathlib import Path
from typing import Any

import msgpack
import numpy as np
import numpy.typing as npt
import zenoh
from egc_common import keys
from egc_common.messages import (
    BaseCommand,
    Rejection,
    ScanMessage,
    decode_base_command,
    decode_clock_reply,
    decode_telemetry,
)
from egc_common.profiles import PIONEER3DX
from egc_common.transport import ZenohOptions, free_tcp_port, loopback_endpoint, open_session
from egc_experiments.bench_results import write_result
from egc_operator.clock_sync import ClockSync

ROBOT = "bench"
MS = 1_000_000
BEAMS = 720
COMMAND_TIMEOUT_MS = 250.0
BOX_M = 0.75  # the latency run: close enough that EGC modifies every command
OPEN_BOX_M = 1.5  # the dropout trials: far enough for full speed
STOP_MS = PIONEER3DX.v_max_mps / PIONEER3DX.decel_max_mps2 * 1000
ECHO_SCRIPT = Path(__file__).resolve().with_name("zenoh_echo.py")
ECHO_ROBOT = "bench-echo"  # the echo's keys have the product's shapes: .../cmd -> .../base/cmd
ECHO_TARGET = 1.3  # product p50 <= 1.3x the bare echo's


def command_message(seq: int, stamp_ns: int, x: float, y: float) -> dict[str, Any]:
    """The harness operator's command (msgpack map of an OperatorCommand)."""
    msg: dict[str, Any] = {"v": 1, "seq": seq, "stamp_ns": stamp_ns, "x": x, "y": y}
    msg |= {"mode": "shared", "deadman": True, "estop": False, "reset": False}
    msg |= {"op": "bench"}
    return msg


# Payload sizes of the echo: an OperatorCommand out (as the harness sends it mid-run), a
# BaseCommand back (as the robot sends it mid-run).
COMMAND_BYTES = len(msgpack.packb(command_message(1000, time.monotonic_ns(), 0.5, 0.2)))
BASE_BYTES = len(BaseCommand(time.monotonic_ns(), 1000, 0.25, 0.1).encode())


def operator_publisher(session: zenoh.Session, key: str) -> zenoh.Publisher:
    """The harness operator's command publisher; the echo's requests use the same QoS."""
    return session.declare_publisher(
        key,
        priority=zenoh.Priority.INTERACTIVE_HIGH,
        express=True,
        congestion_control=zenoh.CongestionControl.DROP,
    )


@functools.cache
def corridor_ranges(box_m: float) -> npt.NDArray[np.float32]:
    """A 2.4 m wide corridor with a box ``box_m`` ahead, slightly right, 720 beams (m)."""
    a = np.linspace(-math.pi, math.pi, BEAMS, endpoint=False)
    s, c = np.sin(a), np.cos(a)
    with np.errstate(divide="ignore"):
        r = np.where(s != 0, 1.2 / np.abs(s), np.inf)
    box = np.abs(a + 0.08) < 0.15
    r[box] = np.minimum(r[box], box_m / np.maximum(c[box], 1e-3))
    ranges = np.minimum(r, 12.0).astype(np.float32)
    ranges.flags.writeable = False
    return ranges


def corridor_scan(stamp_ns: int, box_m: float) -> bytes:
    """The corridor scan stamped ``stamp_ns``; the ranges are computed once per box distance, so
    the harness holds the GIL as little as possible while the robot's replies come in."""
    ranges = corridor_ranges(box_m)
    return ScanMessage(stamp_ns, -math.pi, 2 * math.pi / BEAMS, 0.05, 10.0, ranges).encode()


class Harness:
    """Operator + driver in this process (see the module docstring)."""

    def __init__(self, endpoint: str) -> None:
        self.session = open_session(ZenohOptions(connect=(endpoint,)))
        self.lock = threading.Lock()
        self.base: list[tuple[int, int, float, float]] = []  # rx_ns, cycle, v, w
        self.base_stamp: dict[int, int] = {}  # cycle -> the robot's clock when the cycle ran
        self.cycle_seq: dict[int, int] = {}  # robot cycle -> command seq it used
        self.limiters: Counter[str] = Counter()  # what limited the command, while DRIVING
        self.published: dict[int, int] = {}  # command seq -> publish time
        self.stop = threading.Event()
        self.box_m = BOX_M
        s = self.session
        self.subs = [
            s.declare_subscriber(keys.base_cmd(ROBOT), self._on_base),
            s.declare_subscriber(keys.telemetry(ROBOT), self._on_telemetry),
        ]
        self.cmd_pub = operator_publisher(s, keys.cmd(ROBOT))
        self.threads = [threading.Thread(target=self._scans, daemon=True)]
        self.threads[0].start()

    def _on_base(self, sample: zenoh.Sample) -> None:
        now = time.monotonic_ns()
        b = decode_base_command(sample.payload.to_bytes())
        if not isinstance(b, Rejection):
            with self.lock:
                self.base.append((now, b.seq, b.linear_mps, b.angular_radps))
                self.base_stamp[b.seq] = b.stamp_ns

    def _on_telemetry(self, sample: zenoh.Sample) -> None:
        t = decode_telemetry(sample.payload.to_bytes())
        if not isinstance(t, Rejection):
            with self.lock:
                self.cycle_seq[t.cycle] = t.seq
                if t.state == "DRIVING":
                    self.limiters[t.limiter] += 1

    def _scans(self) -> None:
        period = 50 * MS
        deadline = time.monotonic_ns()
        while not self.stop.is_set():
            self.session.put(keys.scan(ROBOT), corridor_scan(time.monotonic_ns(), self.box_m))
            deadline += period
            time.sleep(max(0, deadline - time.monotonic_ns()) / 1e9)

    def robot_offset_ns(self) -> int:
        """Offset of the robot's clock from ours: the operator's own min-RTT estimator."""
        sync = ClockSync(window=10)
        for _ in range(10):
            sent = time.monotonic_ns()
            for reply in self.session.get(keys.clock(ROBOT), timeout=2.0):
                received = time.monotonic_ns()
                stamp = decode_clock_reply(reply.ok.payload.to_bytes())
                if isinstance(stamp, int):
                    sync.add(sent, stamp, received)
        if sync.best is None:
            raise SystemExit("bench: the robot's clock queryable did not answer")
        return sync.best.offset_ns

    def drive(self, seconds: float) -> None:
        """The harness operator: 50 Hz, centred for 0.5 s, then half forward, a little left."""
        offset = self.robot_offset_ns()
        period = 20 * MS
        start = deadline = time.monotonic_ns()
        seq = 0
        while (now := time.monotonic_ns()) - start < seconds * 1e9:
            seq += 1
            x, y = (0.0, 0.0) if now - start < 500 * MS else (0.5, 0.2)
            msg = command_message(seq, now + offset, x, y)
            payload = msgpack.packb(msg)
            t_pub = time.monotonic_ns()
            self.cmd_pub.put(payload)
            with self.lock:
                self.published[seq] = t_pub
            deadline += period
            time.sleep(max(0, deadline - time.monotonic_ns()) / 1e9)
        # release the deadman so the next phase starts from HOLD
        for _ in range(10):
            seq += 1
            msg |= {"seq": seq, "stamp_ns": time.monotonic_ns() + offset, "deadman": False}
            self.cmd_pub.put(msgpack.packb(msg))
            time.sleep(0.02)

    def latencies_ms(self) -> tuple[list[float], list[float]]:
        """Publish -> base receipt per command, and the part of it before the robot's cycle ran.

        Both ends and the robot read CLOCK_MONOTONIC of this machine, so the base command's
        stamp (the robot's clock when its cycle started) splits each latency into "publish ->
        cycle start" (Zenoh hop, decode, checks) and "cycle start -> base receipt" (pipeline,
        encode, Zenoh hop).
        """
        with self.lock:
            base_rx = {cycle: rx for rx, cycle, _, _ in self.base}
            first_cycle: dict[int, int] = {}
            for cycle in sorted(self.cycle_seq):
                first_cycle.setdefault(self.cycle_seq[cycle], cycle)
            total, before_cycle = [], []
            for seq, t_pub in self.published.items():
                cycle = first_cycle.get(seq)
                if cycle is not None and cycle in base_rx:
                    total.append((base_rx[cycle] - t_pub) / MS)
                    before_cycle.append((self.base_stamp[cycle] - t_pub) / MS)
        return total, before_cycle

    def base_since(self, since_ns: int) -> list[tuple[int, int, float, float]]:
        with self.lock:
            return [b for b in self.base if b[0] >= since_ns]

    def close(self) -> None:
        self.stop.set()
        for t in self.threads:
            t.join(2)
        for sub in self.subs:
            sub.undeclare()
        self.session.close()


class Echo:
    """The baseline: this process <-> ``bench/zenoh_echo.py`` (see the module docstring)."""

    def __init__(self, log: Path) -> None:
        self.endpoint = loopback_endpoint(free_tcp_port())
        args = ["--listen", self.endpoint, "--reply-bytes", str(BASE_BYTES)]
        args += ["--sub", keys.cmd(ECHO_ROBOT), "--pub", keys.base_cmd(ECHO_ROBOT)]
        with log.open("ab") as err:
            self.proc = subprocess.Popen(
                [sys.executable, str(ECHO_SCRIPT), *args],
                stdout=subprocess.PIPE,
                stderr=err,
                stdin=subprocess.DEVNULL,
            )
        try:
            assert self.proc.stdout is not None
            ready, _, _ = select.select([self.proc.stdout], [], [], 30.0)
            if not ready or self.proc.stdout.readline().strip() != b"ready":
                raise SystemExit(f"bench: {ECHO_SCRIPT.name} did not start (see {log})")
            self.session = open_session(ZenohOptions(connect=(self.endpoint,)))
        except BaseException:
            self.proc.kill()
            self.proc.wait()
            raise
        self.lock = threading.Lock()
        self.replies: dict[int, int] = {}  # seq -> receipt time
        self.seq = 0
        self.pub = operator_publisher(self.session, keys.cmd(ECHO_ROBOT))
        self.sub = self.session.declare_subscriber(keys.base_cmd(ECHO_ROBOT), self._on_reply)
        self.closed = False

    def _on_reply(self, sample: zenoh.Sample) -> None:
        now = time.monotonic_ns()
        seq = int.from_bytes(sample.payload.to_bytes()[:8], "little")
        with self.lock:
            self.replies.setdefault(seq, now)

    def _payload(self) -> bytes:
        self.seq += 1
        return self.seq.to_bytes(8, "little").ljust(COMMAND_BYTES, b"\0")

    def wait_ready(self) -> None:
        """Probe until the echo answers (the declarations have crossed both ways)."""
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            self.pub.put(self._payload())
            time.sleep(0.02)
            with self.lock:
                if self.replies:
                    return
        raise SystemExit("bench: the Zenoh echo did not answer")

    def run(self, seconds: float) -> tuple[list[float], int]:
        """Publish at 50 Hz for ``seconds``, like ``Harness.drive``; publish -> echo receipt (ms)
        of each request answered, and the number of requests sent."""
        published: dict[int, int] = {}
        period = 20 * MS
        start = deadline = time.monotonic_ns()
        while time.monotonic_ns() - start < seconds * 1e9:
            payload = self._payload()
            t_pub = time.monotonic_ns()
            self.pub.put(payload)
            with self.lock:
                published[self.seq] = t_pub
            deadline += period
            time.sleep(max(0, deadline - time.monotonic_ns()) / 1e9)
        time.sleep(0.3)
        with self.lock:
            lat = [(self.replies[s] - t) / MS for s, t in published.items() if s in self.replies]
        return lat, len(published)

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        self.sub.undeclare()
        self.session.close()
        self.proc.send_signal(signal.SIGTERM)
        try:
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


def start(args: list[str], log: Path) -> subprocess.Popen[bytes]:
    with log.open("ab") as out:
        return subprocess.Popen(
            [sys.executable, "-m", "egc_app.cli", *args],
            stdout=out,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
        )


def wait_until(predicate: Any, timeout_s: float, what: str) -> Any:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(0.005)
    raise SystemExit(f"bench: timed out waiting for {what}")


def operator_trial(
    h: Harness, endpoint: str, workdir: Path, sig: int, trial: int
) -> dict[str, float]:
    """Start a real operator at full speed, send it ``sig``, time the robot's reaction."""
    js = workdir / "forward.csv"
    # Centred for 3 s: longer than the release of the previous operator (2 s, DESIGN 8).
    js.write_text("t_s,x,y,deadman\n0,0,0,1\n3,1,0,1\n600,1,0,1\n")
    op_id = f"op{trial}-{sig}"
    args = ["operator", "--robot", ROBOT, "--operator-id", op_id, "--joystick-file", str(js)]
    args += ["--no-view", "--no-status", "--zenoh-connect", endpoint]
    proc = start(args, workdir / "operators.log")
    try:
        began = time.monotonic_ns()
        v_max = PIONEER3DX.v_max_mps

        def full_speed() -> bool:
            recent = h.base_since(began)
            return len(recent) > 5 and all(b[2] >= v_max - 1e-9 for b in recent[-5:])

        wait_until(full_speed, 15, "full speed")
        time.sleep(0.3)
        t0 = time.monotonic_ns()
        proc.send_signal(sig)
        after = lambda: h.base_since(t0)  # noqa: E731
        zero = wait_until(
            lambda: next((b[0] for b in after() if b[2] == 0.0 and b[3] == 0.0), None),
            5,
            "a zero command",
        )
        braking = next(b[0] for b in after() if b[2] < v_max - 1e-9)
        return {"brake_ms": (braking - t0) / MS, "zero_ms": (zero - t0) / MS}
    finally:
        proc.kill()
        proc.wait()
        time.sleep(0.3)


def pct(values: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(values), q))


def summary(values: list[float], sent: int) -> dict[str, Any]:
    return {
        "sent": sent,
        "matched": len(values),
        "p50": pct(values, 50),
        "p90": pct(values, 90),
        "p99": pct(values, 99),
        "max": max(values),
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=20.0, help="latency run length")
    ap.add_argument("--trials", type=int, default=5, help="SIGKILL and SIGSTOP trials each")
    ap.add_argument("--out", help="JSON file (default bench/results/link.json)")
    args = ap.parse_args()
    workdir = Path(tempfile.mkdtemp(prefix="egc-bench-link-"))
    endpoint = loopback_endpoint(free_tcp_port())
    robot_args = ["robot", "--robot", ROBOT, "--driver", "zenoh", "--listen", endpoint]
    robot = start(robot_args, workdir / "robot.log")
    h = Harness(endpoint)
    echo: Echo | None = None
    try:
        echo = Echo(workdir / "echo.log")
        wait_until(lambda: h.cycle_seq, 30, "the robot's first telemetry")
        echo.wait_ready()
        load_before = os.getloadavg()
        echo_before, echo_sent_before = echo.run(args.seconds / 2)
        h.drive(args.seconds)
        time.sleep(0.3)
        echo_after, echo_sent_after = echo.run(args.seconds / 2)
        load_after = os.getloadavg()
        echo.close()
        lat, before_cycle = h.latencies_ms()
        sent = len(h.published)
        limiters = dict(h.limiters)
        h.box_m = OPEN_BOX_M
        kills = [
            operator_trial(h, endpoint, workdir, signal.SIGKILL, i) for i in range(args.trials)
        ]
        stops = [
            operator_trial(h, endpoint, workdir, signal.SIGSTOP, i) for i in range(args.trials)
        ]
    finally:
        if echo is not None:
            echo.close()
        h.close()
        robot.send_signal(signal.SIGTERM)
        robot.wait(10)

    kill_zero = [k["zero_ms"] for k in kills]
    stop_brake = [s["brake_ms"] for s in stops]
    stop_zero = [s["zero_ms"] for s in stops]
    echo_all = echo_before + echo_after
    echo_r = summary(echo_all, echo_sent_before + echo_sent_after)
    echo_r |= {
        "before": summary(echo_before, echo_sent_before),
        "after": summary(echo_after, echo_sent_after),
        "payload_bytes_out": COMMAND_BYTES,
        "payload_bytes_back": BASE_BYTES,
    }
    results = {
        "latency_ms": {
            "commands": sent,
            "matched": len(lat),
            "p50": pct(lat, 50),
            "p90": pct(lat, 90),
            "p99": pct(lat, 99),
            "max": max(lat),
            "publish_to_cycle_start_p50": pct(before_cycle, 50),
            "limiter_while_driving": limiters,
            "p50_vs_echo": pct(lat, 50) / echo_r["p50"],
            "p99_vs_echo": pct(lat, 99) / echo_r["p99"],
        },
        "echo_ms": echo_r,
        "load_average_before": list(load_before),
        "load_average_after": list(load_after),
        "sigkill_to_zero_ms": kill_zero,
        "sigstop_to_hold_ms": stop_brake,
        "sigstop_to_zero_ms": stop_zero,
        "stop_from_full_speed_ms": STOP_MS,
        "python": sys.version,
    }
    targets = {
        "latency p50 <= 1 ms": results["latency_ms"]["p50"] <= 1.0,
        "latency p99 <= 5 ms": results["latency_ms"]["p99"] <= 5.0,
        f"latency p50 <= {ECHO_TARGET}x the bare Zenoh echo": results["latency_ms"]["p50_vs_echo"]
        <= ECHO_TARGET,
        f"SIGKILL -> zero <= 100 ms + v/decel ({100 + STOP_MS:.0f} ms)": max(kill_zero)
        <= 100 + STOP_MS,
        f"SIGSTOP -> HOLD <= command_timeout + 100 ms ({COMMAND_TIMEOUT_MS + 100:.0f} ms)": max(
            stop_brake
        )
        <= COMMAND_TIMEOUT_MS + 100,
    }
    results["targets"] = targets
    lat_r = results["latency_ms"]
    print(f"operator publish -> base command, {lat_r['matched']}/{sent} commands, 720-point scans")
    print(
        f"  p50 {lat_r['p50']:.3f} ms  p90 {lat_r['p90']:.3f} ms  p99 {lat_r['p99']:.3f} ms"
        f"  max {lat_r['max']:.3f} ms"
    )
    print(
        f"  of which publish -> robot cycle start p50 {lat_r['publish_to_cycle_start_p50']:.3f} ms,"
        f" cycle start -> base p50 {lat_r['p50'] - lat_r['publish_to_cycle_start_p50']:.3f} ms"
    )
    print(
        f"bare Zenoh echo over the same two hops ({ECHO_SCRIPT.name}, {COMMAND_BYTES} B out,"
        f" {BASE_BYTES} B back), {echo_r['matched']}/{echo_r['sent']} requests,"
        f" {args.seconds / 2:g} s before and {args.seconds / 2:g} s after the product"
    )
    b, a = echo_r["before"], echo_r["after"]
    print(
        f"  p50 {echo_r['p50']:.3f} ms (before {b['p50']:.3f}, after {a['p50']:.3f})"
        f"  p90 {echo_r['p90']:.3f} ms"
        f"  p99 {echo_r['p99']:.3f} ms (before {b['p99']:.3f}, after {a['p99']:.3f})"
        f"  max {echo_r['max']:.3f} ms"
    )
    print(
        f"  product / echo: p50 {lat_r['p50_vs_echo']:.2f}x  p99 {lat_r['p99_vs_echo']:.2f}x"
        f"  (load average {load_before[0]:.2f} before, {load_after[0]:.2f} after)"
    )
    driving = sum(limiters.values())
    print(
        f"  the EGC filter modified {limiters.get('egc', 0)}/{driving} driving cycles"
        f" (limiters: {limiters})"
    )
    print(f"operator SIGKILL -> zero command (stop from full speed takes {STOP_MS:.0f} ms):")
    print("  " + "  ".join(f"{v:.0f}" for v in kill_zero) + " ms")
    print("operator SIGSTOP -> first braking command (HOLD) / zero command:")
    print(
        "  "
        + "  ".join(f"{b:.0f}/{z:.0f}" for b, z in zip(stop_brake, stop_zero, strict=True))
        + " ms"
    )
    for name, ok in targets.items():
        print(f"  [{'ok' if ok else 'MISSED'}] {name}")
    out = write_result("link", results, args.out)
    print(f"wrote {out}")
    return 0 if all(targets.values()) else 1


if __name__ == "__main__":
    raise SystemExit(main())
