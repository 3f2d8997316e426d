"""``egc-teleop link`` as a real process between plain sockets: delay, byte order, loss,
outages, scenarios, stopping cleanly, and one clear line with exit 2 for each bad input."""

from __future__ import annotations

import itertools
import json
import re
import select
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
from egc_experiments import link_cli

from tests.experiments.subcommand import run_subcommand

pytestmark = [pytest.mark.integration, pytest.mark.timeout(30)]

LINK = [sys.executable, "-m", "egc_app.cli", "link"]
READY = re.compile(r"^link: listening on (tcp|udp)/127\.0\.0\.1:(\d+) -> ")


class Link:
    """A running ``egc-teleop link``; ``port`` is the one it listens on."""

    def __init__(self, *args: str) -> None:
        self.proc = subprocess.Popen(
            [*LINK, *args], stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True
        )
        assert self.proc.stderr is not None
        ready, _, _ = select.select([self.proc.stderr], [], [], 10.0)
        line = self.proc.stderr.readline() if ready else ""
        match = READY.match(line)
        if match is None:
            self.proc.kill()
            raise AssertionError(f"no ready line: {line!r} {self.proc.communicate()[1]!r}")
        self.ready_at = time.monotonic()
        self.port = int(match.group(2))
        t0 = re.search(r"t0 (\d+\.\d+) on CLOCK_MONOTONIC", line)
        assert t0 is not None, line
        self.t0 = float(t0.group(1))  # the relay's start, on the clock of time.monotonic()

    def stop(self, sig: signal.Signals = signal.SIGTERM) -> str:
        """Signal it, check it exits 0, and return what it printed after the ready line."""
        self.proc.send_signal(sig)
        _, err = self.proc.communicate(timeout=10)
        assert self.proc.returncode == 0, err
        return err


@contextmanager
def link(*args: str) -> Iterator[Link]:
    running = Link(*args)
    try:
        yield running
    finally:
        if running.proc.poll() is None:
            running.proc.kill()
            running.proc.wait()


@contextmanager
def tcp_echo() -> Iterator[int]:
    """A TCP echo server on a free port (one thread per connection)."""
    server = socket.create_server(("127.0.0.1", 0))

    def serve(conn: socket.socket) -> None:
        with conn:
            while data := conn.recv(65536):
                conn.sendall(data)

    def accept() -> None:
        while True:
            try:
                conn, _ = server.accept()
            except OSError:
                return
            threading.Thread(target=serve, args=(conn,), daemon=True).start()

    threading.Thread(target=accept, daemon=True).start()
    try:
        yield server.getsockname()[1]
    finally:
        server.close()


class UdpSink:
    """A UDP server on a free port recording (monotonic time, datagram); echoes when asked."""

    def __init__(self, echo: bool) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.port: int = self.sock.getsockname()[1]
        self.got: list[tuple[float, bytes]] = []
        self.echo = echo
        threading.Thread(target=self._run, daemon=True).start()

    def _run(self) -> None:
        while True:
            try:
                data, addr = self.sock.recvfrom(65536)
            except OSError:
                return
            self.got.append((time.monotonic(), data))
            if self.echo:
                self.sock.sendto(data, addr)

    def close(self) -> None:
        self.sock.close()


def tcp_round_trip_ms(sock: socket.socket, payload: bytes) -> float:
    start = time.monotonic()
    sock.sendall(payload)
    got = b""
    while len(got) < len(payload):
        got += sock.recv(65536)
    assert got == payload
    return (time.monotonic() - start) * 1000.0


def test_tcp_delay_applied_and_byte_order_kept(tmp_path: Path) -> None:
    stats_file = tmp_path / "stats.json"
    with tcp_echo() as port, link(
        "--listen", "tcp/127.0.0.1:0", "--connect", f"tcp/127.0.0.1:{port}",
        "--up", "delay=50", "--down", "delay=20,jitter=15", "--stats", str(stats_file),
    ) as relay:  # fmt: skip
        with socket.create_connection(("127.0.0.1", relay.port)) as sock:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            # Down jitter of 15 ms: the floor at 0 and the hold-back keep RTT above 50 ms.
            rtts = [tcp_round_trip_ms(sock, b"ping %d" % i) for i in range(5)]
            assert all(55.0 <= r < 1000.0 for r in rtts), rtts
            # Many small chunks with a jittery downlink: the byte stream must come back intact.
            sent = b"".join(b"<%05d>" % i for i in range(2000))
            chunks = [sent[i : i + 70] for i in range(0, len(sent), 70)]
            got = bytearray()
            sock.settimeout(5.0)
            for chunk in chunks:
                sock.sendall(chunk)
                time.sleep(0.0002)
            while len(got) < len(sent):
                got += sock.recv(65536)
            assert bytes(got) == sent
        err = relay.stop()
    assert re.search(r"link: up: forwarded \d+, dropped 0 \(0\.0%\), delay p50 \d+\.\d", err), err
    assert "link: down: forwarded" in err
    stats = json.loads(stats_file.read_text())
    assert stats["connections"] == 1
    # Measured by the relay: each packet's delay is the 50 ms applied plus its own lateness in
    # releasing it, so the percentiles differ by exactly 50 ms, however busy the machine is.
    up = stats["up"]
    assert up["p50_ms"] - up["late_p50_ms"] == pytest.approx(50.0, abs=0.01), up
    assert up["late_p99_ms"] < 500.0  # a runaway, not a busy machine (targets: bench relay)
    assert stats["down"]["dropped"] == 0 and stats["down"]["max_ms"] > 20.0


def udp_send(
    port: int, n: int, gap_s: float, size: int = 32, sent_at: list[float] | None = None
) -> socket.socket:
    """``n`` datagrams numbered 0.. in their first 6 bytes, ``gap_s`` apart (or more on a busy
    machine); ``sent_at`` gets each one's send time (``time.monotonic()``)."""
    client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    for i in range(n):
        if sent_at is not None:
            sent_at.append(time.monotonic())
        client.sendto(b"%06d" % i + b"x" * (size - 6), ("127.0.0.1", port))
        time.sleep(gap_s)
    return client


def test_udp_loss_rate_and_seeded_repeatability(tmp_path: Path) -> None:
    received: list[set[int]] = []
    for run in range(2):
        sink = UdpSink(echo=False)
        stats_file = tmp_path / f"stats{run}.json"
        with link(
            "--listen", "udp/127.0.0.1:0", "--connect", f"udp/127.0.0.1:{sink.port}",
            "--up", "loss=20", "--seed", "7", "--stats", str(stats_file), "--quiet",
        ) as relay:  # fmt: skip
            udp_send(relay.port, 1500, 0.0002).close()
            time.sleep(0.2)
            relay.stop(signal.SIGINT)
        sink.close()
        stats = json.loads(stats_file.read_text())
        got = {int(data[:6]) for _, data in sink.got}
        assert stats["up"]["forwarded"] + stats["up"]["dropped"] == 1500
        assert stats["up"]["forwarded"] == len(sink.got) == len(got)
        assert stats["up"]["loss_pct"] == pytest.approx(20.0, abs=3.0)
        received.append(got)
    assert received[0] == received[1]  # same seed, same datagrams lost


def test_udp_send_errors_are_counted_per_direction_and_printed(tmp_path: Path) -> None:
    """Outside check: datagrams to a target with nothing on its port (ECONNREFUSED from the ICMP
    port unreachable) were left out of the summary printed at exit (and counted, in the JSON
    only, for the wrong direction)."""
    from egc_common.transport import free_port

    closed = free_port("udp")  # nothing listens here
    stats_file = tmp_path / "stats.json"
    with link(
        "--listen", "udp/127.0.0.1:0", "--connect", f"udp/127.0.0.1:{closed}", "--udp-only",
        "--stats", str(stats_file), "--quiet",
    ) as relay:  # fmt: skip
        udp_send(relay.port, 40, 0.005).close()
        time.sleep(0.2)
        err = relay.stop()
    up = re.search(r"^link: up: forwarded (\d+), .*; send errors (\d+)$", err, re.MULTILINE)
    down = re.search(r"^link: down: .*; send errors (\d+)$", err, re.MULTILINE)
    assert up is not None and down is not None, err
    forwarded, errors = int(up.group(1)), int(up.group(2))
    assert errors >= 10 and forwarded + errors >= 40, err  # each refused once, ICMP or send
    assert int(down.group(1)) == 0, err
    stats = json.loads(stats_file.read_text())
    assert stats["up"]["send_errors"] == errors and stats["down"]["send_errors"] == 0
    assert stats["send_errors"] == {"up": errors, "down": 0}  # the earlier key, kept


def test_what_is_still_delayed_at_stop_is_counted_in_flight(tmp_path: Path) -> None:
    """Outside check: delay=5000, 50 datagrams, SIGTERM at 4.4 s printed 'up: forwarded 0,
    dropped 0' (and the same JSON). What the relay still held is now counted, per direction."""
    stats_file = tmp_path / "stats.json"
    sink = UdpSink(echo=True)
    try:
        with link(
            "--listen", "udp/127.0.0.1:0", "--connect", f"udp/127.0.0.1:{sink.port}",
            "--up", "delay=3000", "--down", "delay=100", "--stats", str(stats_file),
            "--udp-only", "--quiet",
        ) as relay, socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as client:  # fmt: skip
            for _ in range(20):
                client.sendto(b"ping", ("127.0.0.1", relay.port))
                time.sleep(0.01)
            time.sleep(0.5)
            err = relay.stop()
    finally:
        sink.close()
    assert sink.got == [], err
    assert re.search(r"^link: up: forwarded 0, dropped 0 .*; in flight at stop 20; ", err, re.M)
    assert re.search(r"^link: down: forwarded 0, .*; in flight at stop 0; ", err, re.M), err
    stats = json.loads(stats_file.read_text())
    assert (stats["up"]["forwarded"], stats["up"]["dropped"], stats["up"]["in_flight"]) == (
        0,
        0,
        20,
    )
    assert stats["down"]["in_flight"] == 0 and stats["send_errors"] == {"up": 0, "down": 0}


SLACK_S = 0.05  # from a datagram's send to the relay's receive, on a busy machine


def test_udp_outage_drops_and_tcp_outage_delays() -> None:
    sink = UdpSink(echo=False)
    with link(
        "--listen", "udp/127.0.0.1:0", "--connect", f"udp/127.0.0.1:{sink.port}",
        "--up", "outage=0.4+0.4",
    ) as relay:  # fmt: skip
        sent_at: list[float] = []
        udp_send(relay.port, 120, 0.01, sent_at=sent_at).close()  # 1.2 s at 100 Hz, or slower
        time.sleep(0.1)
        err = relay.stop()
    sink.close()
    times = [t for t, _ in sink.got]
    gaps = [b - a for a, b in itertools.pairwise(times)]
    assert max(gaps) == pytest.approx(0.4, abs=0.08)  # nothing arrived during the outage
    assert times[-1] - times[0] > 1.0  # and traffic resumed after it
    dropped = int(re.search(r"up: forwarded \d+, dropped (\d+)", err).group(1))  # type: ignore[union-attr]
    assert dropped == 120 - len(sink.got)
    # Which ones: one run of consecutive datagrams, the ones sent in the outage (t0 + 0.4 s to
    # t0 + 0.8 s), not a count that assumes the sender's pace (a busy run sent 29 in it, not 30+).
    # A datagram reaches the relay a little after it is sent: SLACK_S on either edge.
    lost = sorted(set(range(120)) - {int(data[:6]) for _, data in sink.got})
    assert lost == list(range(lost[0], lost[-1] + 1)), lost
    start, end = relay.t0 + 0.4, relay.t0 + 0.8
    assert start - SLACK_S <= sent_at[lost[0]] and sent_at[lost[-1]] < end, [
        round(sent_at[i] - relay.t0, 3) for i in lost
    ]
    assert sent_at[lost[0] - 1] < start and sent_at[lost[-1] + 1] >= end - SLACK_S  # all of it

    # TCP: outage=1+1 holds what is sent in it until it ends (t0 + 2 s), then the 10 ms delay.
    # Times against the relay's t0 (its ready line, CLOCK_MONOTONIC as time.monotonic()): the
    # ready line may be read late on a busy machine. Upper bounds are a second, never tight.
    with tcp_echo() as port, link(
        "--listen", "tcp/127.0.0.1:0", "--connect", f"tcp/127.0.0.1:{port}",
        "--up", "delay=10,outage=1+1",
    ) as relay, socket.create_connection(("127.0.0.1", relay.port)) as sock:  # fmt: skip
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        end = relay.t0 + 2.0
        tcp_round_trip_ms(sock, b"before")
        assert time.monotonic() < end  # not held by the outage
        time.sleep(max(0.0, relay.t0 + 1.2 - time.monotonic()))
        sent_at = time.monotonic()
        tcp_round_trip_ms(sock, b"during the outage")
        back_at = time.monotonic()
        # Sent in the outage (t0 + 1.2 s): it leaves when the link is back (t0 + 2 s) + 10 ms.
        assert sent_at < end and end + 0.0099 <= back_at < end + 1.0, (sent_at, back_at, end)
        assert 10.0 <= tcp_round_trip_ms(sock, b"after") < 1000.0
        relay.stop()


def test_scenario_phases_change_the_delay(tmp_path: Path) -> None:
    scenario = tmp_path / "s.toml"
    scenario.write_text(
        '[[phase]]\nstart_s = 0\nboth = "delay=5"\n[[phase]]\nstart_s = 1.5\nup = "delay=300"\n'
    )
    with tcp_echo() as port, link(
        "--listen", "tcp/127.0.0.1:0", "--connect", f"tcp/127.0.0.1:{port}",
        "--scenario", str(scenario),
    ) as relay, socket.create_connection(("127.0.0.1", relay.port)) as sock:  # fmt: skip
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        first = tcp_round_trip_ms(sock, b"a")
        assert time.monotonic() < relay.t0 + 1.5  # in the first phase (t0: the ready line)
        time.sleep(max(0.0, relay.t0 + 1.6 - time.monotonic()))
        second = tcp_round_trip_ms(sock, b"b")
        relay.stop()
    # 5 ms each way, then 300 ms up and a perfect link down; above: time a busy machine adds.
    assert 9.9 <= first < 300.0
    assert 299.9 <= second < 1300.0


def test_tcp_rate_limit_gives_that_throughput() -> None:
    size = 400_000  # bytes, up at 4000 kbit/s = 500 kB/s: 0.8 s on the wire
    with tcp_echo() as port, link(
        "--listen", "tcp/127.0.0.1:0", "--connect", f"tcp/127.0.0.1:{port}", "--up", "rate=4000",
    ) as relay, socket.create_connection(("127.0.0.1", relay.port)) as sock:  # fmt: skip
        sock.settimeout(10.0)
        payload = bytes(range(256)) * (size // 256) + bytes(size % 256)
        start = time.monotonic()
        threading.Thread(target=sock.sendall, args=(payload,), daemon=True).start()
        got = bytearray()
        while len(got) < size:
            got += sock.recv(65536)
        elapsed = time.monotonic() - start
        assert bytes(got) == payload
        relay.stop()
    # No faster than the rate allows (0.8 s on the wire); slower only by what a busy machine adds.
    assert 0.8 * 0.95 <= elapsed < 0.8 * 4, elapsed


def test_client_closing_closes_the_target_side() -> None:
    server = socket.create_server(("127.0.0.1", 0))
    port = server.getsockname()[1]
    with server, link(
        "--listen", "tcp/127.0.0.1:0", "--connect", f"tcp/127.0.0.1:{port}", "--up", "delay=30",
    ) as relay:  # fmt: skip
        client = socket.create_connection(("127.0.0.1", relay.port))
        conn, _ = server.accept()
        conn.settimeout(5.0)
        client.sendall(b"last words")
        client.close()
        got = b""
        while data := conn.recv(100):  # the bytes first, then end of stream
            got += data
        assert got == b"last words"
        conn.close()
        assert "1 connection(s)" in relay.stop()


def test_an_end_that_goes_away_mid_stream_leaves_no_noise_in_the_log() -> None:
    """The bytes still on their way to an end that has gone are dropped quietly (asyncio used to
    print 'socket.send() raised exception.' for each, dozens of lines as an operator exits)."""
    server = socket.create_server(("127.0.0.1", 0))
    port = server.getsockname()[1]
    with server, link(
        "--listen", "tcp/127.0.0.1:0", "--connect", f"tcp/127.0.0.1:{port}",
        "--up", "delay=200", "--down", "delay=200",
    ) as relay:  # fmt: skip
        client = socket.create_connection(("127.0.0.1", relay.port))
        conn, _ = server.accept()
        with conn:
            for _ in range(30):  # 300 ms of a stream towards the client
                conn.sendall(b"x" * 100)
                time.sleep(0.01)
            # The client goes (as an operator process that exits) while 200 ms of the stream
            # are still in the link, and its end of stream takes 200 ms to reach the target.
            client.close()
            for _ in range(30):
                try:
                    conn.sendall(b"x" * 100)
                except OSError:
                    break
                time.sleep(0.01)
            time.sleep(0.3)
        err = relay.stop()
    assert "raised exception" not in err, err
    assert "1 connection(s)" in err


def one_line_exit_2(*args: str) -> str:
    proc = subprocess.run([*LINK, *args], capture_output=True, text=True, timeout=15)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    return lines[0]


def one_line_exit_2_here(capsys: pytest.CaptureFixture[str], *args: str) -> str:
    """``one_line_exit_2`` in this process (``tests.experiments.subcommand``)."""
    assert run_subcommand(link_cli, "link", [*args, "--duration", "1"]) == 2
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert len(lines) == 1 and out == "", err
    return lines[0]


def test_bad_inputs_exit_2_with_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad_toml = tmp_path / "bad.toml"
    bad_toml.write_text("[[phase]\n")
    with tcp_echo() as port:
        target = f"tcp/127.0.0.1:{port}"
        ok = ["--listen", "tcp/127.0.0.1:0", "--connect", target]
        cases = {
            "is not a number": [*ok, "--up", "delay=abc"],
            "unknown SPEC key 'latency'": [*ok, "--down", "latency=3"],
            "loss is not possible on a TCP link: a TCP connection retransmits": [
                *ok,
                "--up",
                "loss=5",
            ],
            "must look like tcp/HOST:PORT": ["--listen", "tcp/127.0.0.1", "--connect", target],
            "or udp/HOST:PORT": ["--listen", "http/1.2.3.4:80", "--connect", target],
            "must use the same protocol": ["--listen", "udp/127.0.0.1:0", "--connect", target],
            "'a..b' is not a valid host name": [*ok[:3], "tcp/a..b:7447"],  # was a traceback
            "scenario file .*nope.toml does not exist": [*ok, "--scenario", "nope.toml"],
            "not valid TOML": [*ok, "--scenario", str(bad_toml)],
            "leave out --up and --down": [*ok, "--scenario", str(bad_toml), "--up", "delay=1"],
            "the following arguments are required: --connect": ["--listen", "tcp/127.0.0.1:0"],
            # Outside check: a directory as --stats ran the whole session and failed at exit.
            f"--stats {tmp_path}: is a directory": [*ok, "--stats", str(tmp_path)],
            "--stats .*/no/s.json: directory .* does not exist": [
                *ok,
                "--stats",
                str(tmp_path / "no" / "s.json"),
            ],
            # Outside check: absurd sizes were taken, then nothing was forwarded.
            r"--up 'delay=1e308': delay=1e308 ms is more than 600000 ms \(10 minutes\)": [
                *ok,
                "--up",
                "delay=1e308",
            ],
            "--down 'delay=1e15': delay=1e15 ms is more than 600000 ms": [
                *ok,
                "--down",
                "delay=1e15",
            ],
            "jitter=1e308 ms is more than 600000 ms": [*ok, "--up", "jitter=1e308"],
            "rate=1e-300 kbit/s is below 1 kbit/s": [*ok, "--up", "rate=1e-300"],
        }
        # One through the console script; the rest through the subcommand's parser and run in
        # this process (--duration: a bad input let through ends in a second, exit 0).
        message, args = next(iter(cases.items()))
        assert re.search(message, one_line_exit_2(*args)), (message, args)
        for message, args in cases.items():
            assert re.search(message, one_line_exit_2_here(capsys, *args)), (message, args)
        with socket.create_server(("127.0.0.1", 0)) as taken:
            busy = taken.getsockname()[1]
            line = one_line_exit_2_here(
                capsys, "--listen", f"tcp/127.0.0.1:{busy}", "--connect", target
            )
            assert re.search(r"cannot listen on tcp/127.0.0.1:\d+: .*in use", line), line
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        busy = taken.getsockname()[1]
        line = one_line_exit_2_here(
            capsys, "--listen", f"udp/127.0.0.1:{busy}", "--connect", "udp/127.0.0.1:9"
        )
        assert "in use" in line, line


@pytest.mark.parametrize("proto", ["udp", "tcp"])
def test_zenoh_sessions_talk_through_the_relay(proto: str) -> None:
    """Zenoh's handshake, keep-alives and pub/sub pass the relay (udp/: QUIC, mixed reliability,
    as egc_common.transport configures it)."""
    from egc_common.transport import ZenohOptions, open_session

    kind = socket.SOCK_DGRAM if proto == "udp" else socket.SOCK_STREAM
    with socket.socket(socket.AF_INET, kind) as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    robot = open_session(ZenohOptions(listen=(f"{proto}/127.0.0.1:{port}",)))
    try:
        with link(
            "--listen", f"{proto}/127.0.0.1:0", "--connect", f"{proto}/127.0.0.1:{port}",
            "--up", "delay=15", "--down", "delay=15",
        ) as relay:  # fmt: skip
            operator = open_session(ZenohOptions(connect=(f"{proto}/127.0.0.1:{relay.port}",)))
            try:
                up: list[bytes] = []
                down: list[bytes] = []
                robot.declare_subscriber("t/up", lambda s: up.append(s.payload.to_bytes()))
                operator.declare_subscriber("t/down", lambda s: down.append(s.payload.to_bytes()))
                deadline = time.monotonic() + 10
                while not list(operator.info.peers_zid()) and time.monotonic() < deadline:
                    time.sleep(0.05)
                time.sleep(0.3)  # the subscribers' declarations cross the link
                for i in range(5):
                    operator.put("t/up", b"u%d" % i)
                    robot.put("t/down", b"d%d" % i)
                    time.sleep(0.02)
                while (len(up) < 5 or len(down) < 5) and time.monotonic() < deadline:
                    time.sleep(0.05)
            finally:
                operator.close()
            err = relay.stop()
    finally:
        robot.close()
    assert up == [b"u%d" % i for i in range(5)]
    assert down == [b"d%d" % i for i in range(5)]
    p50 = re.search(r"up: forwarded [1-9]\d*, dropped 0 .* delay p50 (\d+\.\d)", err)
    assert p50 is not None and 14.9 <= float(p50.group(1)) < 1000.0, err


def test_a_udp_relay_also_relays_tcp_on_the_same_ports_without_loss(tmp_path):
    """Our udp/ transport is a TCP + UDP pair on one port number (egc_common.transport): the
    relay carries both, the TCP half with the delay but no loss."""
    import socket
    import threading

    from egc_common.transport import free_port

    target = free_port("udp")
    server = socket.create_server(("127.0.0.1", target))
    udp_target = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    udp_target.bind(("127.0.0.1", target))

    def echo() -> None:
        while True:
            try:
                conn, _ = server.accept()
            except OSError:
                return
            with conn:
                while data := conn.recv(4096):
                    conn.sendall(data)

    threading.Thread(target=echo, daemon=True).start()
    listen = free_port("udp")
    stats = tmp_path / "stats.json"
    proc = subprocess.Popen(
        [sys.executable, "-m", "egc_app.cli", "link", "--listen", f"udp/127.0.0.1:{listen}",
         "--connect", f"udp/127.0.0.1:{target}", "--up", "delay=40,loss=50", "--stats", str(stats)],
        stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        ready = proc.stderr.readline()
        assert "and tcp (control link, no loss)" in ready, ready
        with socket.create_connection(("127.0.0.1", listen), timeout=5) as c:
            for i in range(20):
                sent = time.monotonic()
                c.sendall(b"%02d" % i)
                assert c.recv(2) == b"%02d" % i  # nothing lost
                assert time.monotonic() - sent >= 0.035  # the up delay applies
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.communicate(timeout=10)
        server.close()
        udp_target.close()
    assert proc.returncode == 0
    report = json.loads(stats.read_text())
    assert report["tcp"]["up"]["forwarded"] >= 20 and report["tcp"]["up"]["dropped"] == 0


def test_a_udp_relay_started_before_its_target_relays_tcp_once_the_target_is_up():
    """Outside check: started before the robot, the udp/ relay left its TCP half out for good,
    so a Zenoh session over it never opened (a udp/ session opens on TCP first). A try while the
    target is down is closed, and stderr says why."""
    import socket

    from egc_common.transport import free_port

    target, listen = free_port("udp"), free_port("udp")
    proc = subprocess.Popen(
        [sys.executable, "-m", "egc_app.cli", "link", "--listen", f"udp/127.0.0.1:{listen}",
         "--connect", f"udp/127.0.0.1:{target}", "--up", "delay=20"],
        stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    server = None
    try:
        ready = proc.stderr.readline()
        assert "and tcp (control link, no loss)" in ready, ready
        with socket.create_connection(("127.0.0.1", listen), timeout=5) as early:
            early.settimeout(5)
            assert early.recv(1) == b""  # the relay closes a try while the target is down
        said = proc.stderr.readline()
        assert said.startswith(
            f"link: tcp connection 1: cannot connect to tcp/127.0.0.1:{target} ("
        ), said
        server = socket.create_server(("127.0.0.1", target))
        with socket.create_connection(("127.0.0.1", listen), timeout=5) as c:
            conn, _ = server.accept()
            with conn:
                c.sendall(b"hello")
                conn.settimeout(5)
                assert conn.recv(5) == b"hello"
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.communicate(timeout=10)
        if server is not None:
            server.close()
    assert proc.returncode == 0


def test_an_ephemeral_udp_port_taken_for_tcp_is_traded_for_another(monkeypatch) -> None:
    """CI run 136: ``--listen udp/127.0.0.1:0`` got a UDP port whose number another suite held
    for TCP, and the link exited. It now closes both and takes another port."""
    import argparse
    import asyncio
    import errno

    real_start = link_cli.Relay.start
    refused: list[int] = []

    async def start(self):
        if self.label == "tcp connection" and not refused:
            refused.append(self.listen.port)
            raise OSError(errno.EADDRINUSE, "Address already in use")
        return await real_start(self)

    monkeypatch.setattr(link_cli.Relay, "start", start)
    parser = argparse.ArgumentParser()
    link_cli.configure(parser)
    args = parser.parse_args(["--listen", "udp/127.0.0.1:0", "--connect", "udp/127.0.0.1:9"])

    async def pair():
        relay = link_cli.build_relay(args)
        bound, companion, _ = await link_cli.start_pair(relay, args)
        assert companion is not None
        try:
            return bound.port, companion.listen.port
        finally:
            await companion.close()
            await relay.close()

    udp_port, tcp_port = asyncio.run(pair())
    assert len(refused) == 1 and udp_port == tcp_port and udp_port != 0
    # A port the user named is not traded: the same refusal is reported.
    refused.clear()
    named = parser.parse_args(
        ["--listen", f"udp/127.0.0.1:{udp_port}", "--connect", "udp/127.0.0.1:9"]
    )
    with pytest.raises(link_cli.UsageError, match="the TCP half of a udp/ link"):
        asyncio.run(link_cli.start_pair(link_cli.build_relay(named), named))
