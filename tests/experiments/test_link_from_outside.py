"""``egc-teleop link`` checked from outside with plain sockets (issue 31): exactly one connection
to the target per client connection and none of its own, the bytes in order with the delay
asked, an outage holding them, and a target that refuses reported when a client arrives.

The outside check that found it: a single-client server (as a serial or motor bridge) took the
relay's start-up reachability probe as its one client, and every TCP byte relayed after it was
lost while the relay's own figures said all were forwarded. Here the target is a plain
``socket`` server that counts what it accepts and timestamps what it reads, the client a plain
socket, and the relay the real process. Delays are checked against a floor the relay must keep
(nothing leaves before it is due) and a ceiling of a second that a busy machine cannot break.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import select
import socket
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
from egc_common.transport import free_tcp_port
from egc_experiments.link_model import LinkModel, Schedule, parse_spec
from egc_experiments.relay import Lane, Recorder

from tests.experiments.test_link_cli import Link, link

pytestmark = [pytest.mark.integration, pytest.mark.timeout(60)]

RECORD = 16  # bytes per message: b"c<client:2> <seq:6> ...\n"
WAIT_S = 15.0  # a generous deadline for what must happen


class CountingServer:
    """A plain TCP server: counts the connections it accepts and keeps, per connection, each
    chunk read with the ``time.monotonic()`` it was read at. It never writes.

    ``single``: a single-client server, as a serial or motor bridge: it accepts one connection,
    serves it until its end, and then stops listening (a second client is refused)."""

    def __init__(self, single: bool = False) -> None:
        self.sock = socket.create_server(("127.0.0.1", 0))
        self.port: int = self.sock.getsockname()[1]
        self.single = single
        self.accepted = 0
        self.chunks: list[list[tuple[float, bytes]]] = []
        self.ended: list[bool] = []
        self._lock = threading.Lock()
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self) -> None:
        while True:
            try:
                conn, _ = self.sock.accept()
            except OSError:
                return
            with self._lock:
                self.accepted += 1
                index = len(self.chunks)
                self.chunks.append([])
                self.ended.append(False)
            if self.single:
                self._serve(conn, index)
                self.sock.close()
                return
            threading.Thread(target=self._serve, args=(conn, index), daemon=True).start()

    def _serve(self, conn: socket.socket, index: int) -> None:
        with conn:
            while True:
                try:
                    data = conn.recv(65536)
                except OSError:
                    break
                if not data:
                    break
                self.chunks[index].append((time.monotonic(), data))
        self.ended[index] = True

    def stream(self, index: int) -> bytes:
        return b"".join(data for _, data in self.chunks[index])

    def arrivals(self, index: int) -> list[tuple[bytes, float]]:
        """Each message of connection ``index`` with the time its last byte was read."""
        out, pending = [], b""
        for at, data in self.chunks[index]:
            pending += data
            while len(pending) >= RECORD:
                out.append((pending[:RECORD], at))
                pending = pending[RECORD:]
        return out

    def wait_ended(self, n: int) -> None:
        deadline = time.monotonic() + WAIT_S
        while sum(self.ended) < n and time.monotonic() < deadline:
            time.sleep(0.01)
        assert sum(self.ended) >= n, f"{sum(self.ended)} of {n} connections ended"

    def close(self) -> None:
        self.sock.close()


@contextmanager
def counting_server(single: bool = False) -> Iterator[CountingServer]:
    server = CountingServer(single)
    try:
        yield server
    finally:
        server.close()


def message(client: int, seq: int) -> bytes:
    text = b"c%02d %06d" % (client, seq)
    return text + b"." * (RECORD - 1 - len(text)) + b"\n"


def send_messages(
    port: int, client: int, count: int, gap_s: float, sent: dict[bytes, float]
) -> None:
    """One plain client connection: ``count`` messages ``gap_s`` apart, each sent time kept in
    ``sent``; then it closes (its end of stream ends the target's connection)."""
    with socket.create_connection(("127.0.0.1", port), timeout=WAIT_S) as sock:
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        for seq in range(count):
            data = message(client, seq)
            sent[data] = time.monotonic()
            sock.sendall(data)
            time.sleep(gap_s)


def stop_and_read_stats(relay: Link, stats_file: Path) -> tuple[str, dict[str, object]]:
    err = relay.stop()
    return err, json.loads(stats_file.read_text())


@pytest.mark.parametrize(
    ("clients", "concurrent"), [(1, False), (3, False), (3, True)], ids=["1", "3-seq", "3-conc"]
)
def test_one_target_connection_per_client_with_the_delay_asked(
    tmp_path: Path, clients: int, concurrent: bool
) -> None:
    stats_file = tmp_path / "stats.json"
    sent: dict[bytes, float] = {}
    with counting_server() as server, link(
        "--listen", "tcp/127.0.0.1:0", "--connect", f"tcp/127.0.0.1:{server.port}",
        "--up", "delay=100", "--stats", str(stats_file),
    ) as relay:  # fmt: skip
        jobs = [(relay.port, c, 10, 0.01, sent) for c in range(clients)]
        if concurrent:
            threads = [threading.Thread(target=send_messages, args=job) for job in jobs]
            for thread in threads:
                thread.start()
            for thread in threads:
                thread.join(WAIT_S)
        else:
            for job in jobs:
                send_messages(*job)
        server.wait_ended(clients)
        err, stats = stop_and_read_stats(relay, stats_file)
    # Exactly one target connection per client connection, none of the relay's own.
    assert server.accepted == clients, err
    assert stats["connections"] == clients and stats["connect_failures"] == 0, stats
    assert f"{clients} connection(s)" in err and "could not reach" not in err, err
    # Each target connection carries one client's bytes, whole and in order.
    streams = sorted(server.stream(i) for i in range(clients))
    assert streams == [b"".join(message(c, s) for s in range(10)) for c in range(clients)]
    # Each message arrives no sooner than 100 ms after it was sent, and within a second.
    for i in range(clients):
        for data, at in server.arrivals(i):
            assert 0.0999 <= at - sent[data] < 1.0, (data, at - sent[data])


def test_a_single_client_target_gets_every_byte(tmp_path: Path) -> None:
    """The outside check itself: a server that takes one client and no other receives all of
    the client's bytes through the relay (the start-up probe used to be that one client)."""
    stats_file = tmp_path / "stats.json"
    sent: dict[bytes, float] = {}
    with counting_server(single=True) as server, link(
        "--listen", "tcp/127.0.0.1:0", "--connect", f"tcp/127.0.0.1:{server.port}",
        "--up", "delay=20", "--stats", str(stats_file),
    ) as relay:  # fmt: skip
        send_messages(relay.port, 7, 50, 0.002, sent)
        server.wait_ended(1)
        err, stats = stop_and_read_stats(relay, stats_file)
    assert server.accepted == 1
    assert server.stream(0) == b"".join(message(7, s) for s in range(50)), err
    assert stats["connect_failures"] == 0, stats
    up = stats["up"]
    assert isinstance(up, dict) and up["in_flight"] == 0 and up["forwarded"] >= 1, up


def test_an_outage_holds_the_bytes_until_it_ends(tmp_path: Path) -> None:
    """``outage=2+1`` (seconds after the relay's t0, printed on its ready line in
    CLOCK_MONOTONIC, the clock of ``time.monotonic()``): a TCP link loses nothing; what is sent
    during the outage arrives once it is over (plus the 20 ms delay), in order."""
    start_s, length_s, delay_s = 2.0, 1.0, 0.02
    stats_file = tmp_path / "stats.json"
    sent: dict[bytes, float] = {}
    with counting_server() as server, link(
        "--listen", "tcp/127.0.0.1:0", "--connect", f"tcp/127.0.0.1:{server.port}",
        "--up", f"delay={delay_s * 1000:g},outage={start_s:g}+{length_s:g}",
        "--stats", str(stats_file),
    ) as relay:  # fmt: skip
        t0 = relay.t0
        end = t0 + start_s + length_s
        count = max(1, round((end + 0.5 - time.monotonic()) / 0.05))
        send_messages(relay.port, 1, count, 0.05, sent)
        server.wait_ended(1)
        err, _ = stop_and_read_stats(relay, stats_file)
    assert server.accepted == 1
    assert server.stream(0) == b"".join(message(1, s) for s in range(count)), err
    during = [(data, at) for data, at in server.arrivals(0) if t0 + start_s <= sent[data] < end]
    assert len(during) >= 5, f"only {len(during)} messages sent in the outage (started late?)"
    for data, at in during:
        assert end + delay_s - 1e-4 <= at < end + 1.0, (data, at - end)
    for data, at in server.arrivals(0):
        assert at - sent[data] >= delay_s - 1e-4, (data, at - sent[data])


def test_a_refusing_target_closes_the_client_and_says_why(tmp_path: Path) -> None:
    """No server at the target: the relay starts (no start-up probe, so no start-up error),
    closes each client's connection when its connection to the target is refused, says so on
    stderr (the first of a streak even with --quiet) and counts every one."""
    dead = free_tcp_port()
    stats_file = tmp_path / "stats.json"
    with link(
        "--listen", "tcp/127.0.0.1:0", "--connect", f"tcp/127.0.0.1:{dead}", "--quiet",
        "--stats", str(stats_file),
    ) as relay:  # fmt: skip
        assert relay.proc.stderr is not None
        for _ in range(2):
            with socket.create_connection(("127.0.0.1", relay.port), timeout=WAIT_S) as sock:
                sock.sendall(b"hello")
                with contextlib.suppress(ConnectionResetError):  # closed, or reset: unread
                    assert sock.recv(1) == b""  # closed by the relay
        ready, _, _ = select.select([relay.proc.stderr], [], [], WAIT_S)
        said = relay.proc.stderr.readline() if ready else ""
        err, stats = stop_and_read_stats(relay, stats_file)
    assert said == (
        f"link: connection 1: cannot connect to tcp/127.0.0.1:{dead} (Connection refused); "
        "closing the client connection\n"
    ), said
    assert "connection 2" not in err, err  # --quiet: once per streak
    assert f"2 connection(s), 2 could not reach tcp/127.0.0.1:{dead}" in err, err
    assert stats["connections"] == 2 and stats["connect_failures"] == 2, stats
    up = stats["up"]
    assert isinstance(up, dict) and up["forwarded"] == 0, up  # nothing counted as delivered


def test_a_held_lane_delivers_nothing_until_resumed_and_counts_what_it_held() -> None:
    """The relay's TCP up lane is held while the connection to the target is being made: the
    client's bytes wait (their delay running) and leave in order once it is there; if it never
    is, they are counted in flight, never as forwarded (they were, before)."""
    loop = asyncio.new_event_loop()
    try:
        for resume in (True, False):
            recorder, sent = Recorder(seed=0), []
            model = LinkModel(Schedule.constant(parse_spec("")), seed=1, ordered=True)
            lane = Lane(loop, model, 0.0, sent.append, recorder, held=True)
            for i in range(3):
                lane.push(b"%d" % i, 0.0)  # due at once: a lane not held would send them now
            assert sent == [] and recorder.forwarded == 0
            if resume:
                lane.resume()
                assert sent == [b"0", b"1", b"2"] and recorder.forwarded == 3
                lane.push(b"3", 0.0)
                assert sent[-1] == b"3"  # and from then on, at once
            lane.close()
            stats = recorder.stats()
            assert (stats.forwarded, stats.in_flight) == ((4, 0) if resume else (0, 3))
    finally:
        loop.close()
