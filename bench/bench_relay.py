"""Issue 9 benchmark: the overhead of ``egc-teleop link`` on loopback, TCP and UDP.

Round trips of small messages (64 bytes) to an echo server in its own process, directly and
through a real ``egc-teleop link`` process, in the same run: blocks of round trips alternate
between the two paths so that both see the same machine load. Three paths per protocol:

1. direct;
2. through the relay at delay 0 (its overhead: two passes per round trip);
3. through the relay at ``delay=5`` each way: the round trip should be 10 ms plus (2); the relay's
   own measure of its scheduling lateness (release time minus due time) comes from ``--stats``.

    python bench/bench_relay.py [--round-trips N] [--out FILE.json]

Targets: no round trip lost (1 s timeout); at delay 0 the relay adds at most 0.3 ms to the
round-trip p50 and 1 ms to its p99; delayed packets are released with a lateness p99 under 1 ms.
Exits non-zero when one is missed.
"""

from __future__ import annotations

import argparse
import json
import re
import select
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
from egc_experiments.bench_results import write_result

LINK = [sys.executable, "-m", "egc_app.cli", "link"]
MESSAGE = b"x" * 64
BLOCK = 250  # round trips per block; blocks alternate between the paths
GAP_S = 0.0005  # pause between round trips: small messages, not a flood
ADDED_P50_MS = 0.3
ADDED_P99_MS = 1.0
LATE_P99_MS = 1.0
DELAY_MS = 5.0


def echo_main(proto: str) -> None:
    """The echo server process: prints its port, echoes until killed."""
    if proto == "udp":
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind(("127.0.0.1", 0))
        print(sock.getsockname()[1], flush=True)
        while True:
            data, addr = sock.recvfrom(65536)
            sock.sendto(data, addr)
    server = socket.create_server(("127.0.0.1", 0))
    print(server.getsockname()[1], flush=True)

    def serve(conn: socket.socket) -> None:
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        with conn:
            while data := conn.recv(65536):
                conn.sendall(data)

    while True:
        conn, _ = server.accept()
        threading.Thread(target=serve, args=(conn,), daemon=True).start()


def start_echo(proto: str) -> tuple[subprocess.Popen[str], int]:
    proc = subprocess.Popen(
        [sys.executable, __file__, "--echo", proto], stdout=subprocess.PIPE, text=True
    )
    assert proc.stdout is not None
    return proc, int(proc.stdout.readline())


def start_link(
    proto: str, target: int, spec: str, stats: Path
) -> tuple[subprocess.Popen[str], int]:
    args = [f"--listen={proto}/127.0.0.1:0", f"--connect={proto}/127.0.0.1:{target}"]
    args += [f"--up={spec}", f"--down={spec}", f"--stats={stats}", "--quiet"]
    proc = subprocess.Popen([*LINK, *args], stderr=subprocess.PIPE, text=True)
    assert proc.stderr is not None
    ready, _, _ = select.select([proc.stderr], [], [], 10.0)
    line = proc.stderr.readline() if ready else ""
    match = re.search(r"listening on \w+/127\.0\.0\.1:(\d+) ", line)
    if match is None:
        proc.kill()
        raise SystemExit(f"egc-teleop link did not start: {line!r}")
    return proc, int(match.group(1))


def stop_link(proc: subprocess.Popen[str], stats: Path) -> dict[str, Any]:
    proc.send_signal(signal.SIGTERM)
    proc.communicate(timeout=10)
    result: dict[str, Any] = json.loads(stats.read_text())
    return result


class Client:
    """One path to the echo server: a connected socket doing blocking round trips."""

    def __init__(self, proto: str, port: int) -> None:
        if proto == "tcp":
            self.sock = socket.create_connection(("127.0.0.1", port))
            self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        else:
            self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            self.sock.connect(("127.0.0.1", port))
        self.sock.settimeout(1.0)
        self.rtts_us: list[float] = []
        self.timeouts = 0

    def round_trips(self, n: int, keep: bool = True) -> None:
        sock, clock = self.sock, time.perf_counter_ns
        for _ in range(n):
            t0 = clock()
            sock.send(MESSAGE)
            try:
                got = sock.recv(65536)
                while len(got) < len(MESSAGE):  # TCP may split; UDP never does
                    got += sock.recv(65536)
            except TimeoutError:  # a lost round trip: counted, and a missed target
                self.timeouts += 1
                if self.timeouts > 10:
                    raise
                continue
            if keep:
                self.rtts_us.append((clock() - t0) / 1000.0)
            time.sleep(GAP_S)


def summary(rtts_us: list[float]) -> dict[str, float]:
    a = np.asarray(rtts_us)
    return {
        "p50_ms": float(np.percentile(a, 50)) / 1000,
        "p99_ms": float(np.percentile(a, 99)) / 1000,
        "max_ms": float(a.max()) / 1000,
    }


def bench_protocol(proto: str, n: int, workdir: Path) -> dict[str, Any]:
    echo, echo_port = start_echo(proto)
    links = {
        "relay": start_link(proto, echo_port, "", workdir / f"{proto}-0.json"),
        "relay_delay": start_link(
            proto, echo_port, f"delay={DELAY_MS:g}", workdir / f"{proto}-5.json"
        ),
    }
    try:
        clients = {"direct": Client(proto, echo_port)}
        clients |= {name: Client(proto, port) for name, (_, port) in links.items()}
        for c in clients.values():
            c.round_trips(50, keep=False)  # warm up
        for _ in range(max(1, n // BLOCK)):
            for c in clients.values():
                c.round_trips(BLOCK)
        for c in clients.values():
            c.sock.close()
        stats = {
            name: stop_link(proc, workdir / f"{proto}-{'0' if name == 'relay' else '5'}.json")
            for name, (proc, _) in links.items()
        }
    finally:
        for proc, _ in links.values():
            if proc.poll() is None:
                proc.kill()
        echo.kill()
        echo.wait()
    out: dict[str, Any] = {name: summary(c.rtts_us) for name, c in clients.items()}
    direct, relay, delayed = out["direct"], out["relay"], out["relay_delay"]
    out["round_trips"] = len(clients["direct"].rtts_us)
    out["timeouts"] = {name: c.timeouts for name, c in clients.items()}
    out["added_p50_ms"] = relay["p50_ms"] - direct["p50_ms"]
    out["added_p99_ms"] = relay["p99_ms"] - direct["p99_ms"]
    out["ratio_p50"] = relay["p50_ms"] / direct["p50_ms"]
    out["ratio_p99"] = relay["p99_ms"] / direct["p99_ms"]
    out["delay_excess_p50_ms"] = delayed["p50_ms"] - 2 * DELAY_MS
    out["relay_stats_delay0"] = stats["relay"]
    out["relay_stats_delay5"] = stats["relay_delay"]
    late = [stats["relay_delay"][d] for d in ("up", "down")]
    out["late_p50_ms"] = max(s["late_p50_ms"] for s in late)
    out["late_p99_ms"] = max(s["late_p99_ms"] for s in late)
    out["late_max_ms"] = max(s["late_max_ms"] for s in late)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--round-trips", type=int, default=2000, help="per path and protocol")
    ap.add_argument("--out", help="JSON file (default bench/results/relay.json)")
    ap.add_argument("--echo", choices=("tcp", "udp"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.echo:
        echo_main(args.echo)
        return 0
    workdir = Path(tempfile.mkdtemp(prefix="egc-bench-relay-"))
    results: dict[str, Any] = {
        proto: bench_protocol(proto, args.round_trips, workdir) for proto in ("tcp", "udp")
    }
    results["python"] = sys.version
    targets = {}
    print(f"round trips of {len(MESSAGE)}-byte messages, loopback, ms (p50 / p99 / max):")
    for proto in ("tcp", "udp"):
        r = results[proto]
        print(f"  {proto.upper()}, {r['round_trips']} per path")
        for name, label in (
            ("direct", "direct"),
            ("relay", "relay, delay 0"),
            ("relay_delay", f"relay, delay {DELAY_MS:g} each way"),
        ):
            s = r[name]
            print(f"    {label:<24} {s['p50_ms']:7.3f} / {s['p99_ms']:7.3f} / {s['max_ms']:7.3f}")
        print(
            f"    relay adds p50 {r['added_p50_ms']:.3f} ms (x{r['ratio_p50']:.1f}), "
            f"p99 {r['added_p99_ms']:.3f} ms (x{r['ratio_p99']:.1f}); at delay "
            f"{DELAY_MS:g}: excess p50 {r['delay_excess_p50_ms']:.3f} ms, lateness p50 "
            f"{r['late_p50_ms']:.3f} p99 {r['late_p99_ms']:.3f} max {r['late_max_ms']:.3f} ms"
        )
        targets[f"{proto}: relay adds <= {ADDED_P50_MS} ms to p50"] = (
            r["added_p50_ms"] <= ADDED_P50_MS
        )
        targets[f"{proto}: relay adds <= {ADDED_P99_MS} ms to p99"] = (
            r["added_p99_ms"] <= ADDED_P99_MS
        )
        targets[f"{proto}: lateness p99 < {LATE_P99_MS} ms"] = r["late_p99_ms"] < LATE_P99_MS
        targets[f"{proto}: no round trip lost"] = not any(r["timeouts"].values())
        if any(r["timeouts"].values()):
            print(f"    round trips lost (1 s timeout): {r['timeouts']}")
    results["targets"] = targets
    for name, ok in targets.items():
        print(f"  [{'ok' if ok else 'MISSED'}] {name}")
    out = write_result("relay", results, args.out)
    print(f"wrote {out}")
    return 0 if all(targets.values()) else 1


if __name__ == "__main__":
    raise SystemExit(main())
