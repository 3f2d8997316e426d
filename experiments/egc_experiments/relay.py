"""The user-space link emulator of ``egc-teleop link`` (DESIGN 10): a TCP or UDP relay that sends
each chunk (TCP) or datagram (UDP) of each direction through that direction's ``LinkModel``.

``listen`` is the operator side, ``connect`` the robot side; ``up`` is listen -> connect
(operator -> robot), ``down`` the reverse. The relay is transparent to what it carries (a TCP byte
stream, UDP datagrams), so Zenoh's handshake and keep-alives pass like any other bytes.

Design, measured (the README's link section has the numbers): one thread running an asyncio
event loop. A UDP round trip through a prototype relay at delay 0 cost about 70 us with asyncio
against about 180 us with a reader thread per socket handing packets to a scheduler thread (two
thread wake-ups and GIL hand-offs per packet). Packets due at once (delay 0, empty queue) are
sent from the callback that read them; later ones wait in a per-lane heap with one loop timer for
its head. epoll sleeps in whole milliseconds, so the loop's selector first waits on the epoll
descriptor with ``select()``, which sleeps in microseconds: release times are kept to well under
a millisecond (the stats report the lateness measured).

Time is ``time.monotonic()`` here at the edge; the model sees seconds since the relay started
(the origin of outages, phases and traces). One model per direction per TCP connection or UDP
client address (seeded by ``flow_seed``), so a rate limit applies per connection.

Exactly one connection to the target per accepted client connection, and none of its own: a
single-client target (a serial or motor bridge, a test harness) takes the first connection it
accepts as its client, so a reachability probe at start-up took that place and every byte
relayed after it was lost. A target that refuses (or does not answer within
``CONNECT_TIMEOUT_S``) is found when a client arrives: that client's connection is closed, the
first refusal of a streak is one line on stderr, and every one is counted
(``Relay.connect_failures``). What the client sent meanwhile is held in its lane and counted in
flight, never as forwarded.
"""

from __future__ import annotations

import array
import asyncio
import contextlib
import ctypes
import heapq
import ipaddress
import os
import random
import select
import selectors
import socket
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Final

from egc_experiments.link_model import (
    TCP_LOSS_MESSAGE,
    DirectionStats,
    LinkModel,
    Schedule,
    SpecError,
    derive_seed,
)

PROTOCOLS: Final = ("tcp", "udp")
MAX_DATAGRAM: Final = 65535
RESERVOIR: Final = 200_000  # delay samples kept per direction for the percentiles
CONNECT_TIMEOUT_S: Final = 5.0
_READS_PER_WAKEUP: Final = 64
# TCP flow control: stop reading a sender while its lane holds this much (resume at half), so
# that a rate limit fills the sender's socket buffer as a real bottleneck would.
MAX_QUEUED_BYTES: Final = 4 * 1024 * 1024
MAX_BACKLOG_S: Final = 0.25  # serialization queued behind a rate limit
_PR_SET_TIMERSLACK: Final = 29


def flow_seed(seed: int, direction: str, number: int) -> int:
    """The model seed of one direction of the ``number``-th connection or UDP client (from 1).

    The first one uses ``derive_seed(seed, direction)``, as the simulated experiments do, so that
    one seed gives the same decisions in both modes; later ones get seeds of their own."""
    return derive_seed(seed, direction if number == 1 else f"{direction}/{number}")


class EndpointError(ValueError):
    """A malformed endpoint; the message is one line for the user."""


@dataclass(frozen=True, slots=True)
class Endpoint:
    """``tcp/HOST:PORT`` or ``udp/HOST:PORT`` (IPv6 hosts in brackets: ``tcp/[::1]:7447``)."""

    proto: str
    host: str
    port: int

    def __str__(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{self.proto}/{host}:{self.port}"


def parse_endpoint(text: str) -> Endpoint:
    """Parse ``PROTO/HOST:PORT``; raises ``EndpointError`` with one clear line.

    Zenoh metadata and configuration (``?rel=1;mixed_rel=1``, ``#...``) are accepted and ignored:
    the relay carries whatever the peers speak over that protocol."""
    proto, slash, rest = text.split("#", 1)[0].split("?", 1)[0].partition("/")
    if not slash or proto not in PROTOCOLS:
        raise EndpointError(f"endpoint {text!r} must look like tcp/HOST:PORT or udp/HOST:PORT")
    if rest.startswith("["):
        host, bracket, port_text = rest[1:].partition("]")
        if not bracket or not port_text.startswith(":"):
            raise EndpointError(f"endpoint {text!r}: an IPv6 host is written [ADDR]:PORT")
        port_text = port_text[1:]
    else:
        host, colon, port_text = rest.rpartition(":")
        if not colon or ":" in host:
            raise EndpointError(f"endpoint {text!r} must look like {proto}/HOST:PORT")
    if not host:
        raise EndpointError(f"endpoint {text!r} has no host")
    try:  # what resolving it would raise (a UnicodeError, not an OSError) for ``a..b``
        host.encode("idna")
    except UnicodeError:
        raise EndpointError(f"endpoint {text!r}: {host!r} is not a valid host name") from None
    if not port_text.isdigit() or not 0 <= int(port_text) <= 65535:
        raise EndpointError(f"endpoint {text!r}: the port must be a number in 0..65535")
    return Endpoint(proto, host, int(port_text))


def _family(host: str) -> socket.AddressFamily:
    try:
        return socket.AF_INET6 if ipaddress.ip_address(host).version == 6 else socket.AF_INET
    except ValueError:
        return socket.AF_INET


class PreciseSelector(selectors.EpollSelector):
    """An epoll selector that sleeps with microsecond precision.

    ``epoll_wait`` takes whole milliseconds (Python rounds up), which would release delayed
    packets up to 1 ms late. An epoll descriptor is itself pollable, so a ``select()`` on it with
    the exact timeout does the sleeping, then epoll collects the ready events without waiting.
    """

    def select(self, timeout: float | None = None) -> list[tuple[selectors.SelectorKey, int]]:
        if timeout is not None and timeout > 0:
            select.select([self.fileno()], [], [], timeout)
            timeout = 0
        return super().select(timeout)


def _tight_timer_slack() -> None:
    """Linux lets a sleeping thread wake up to 50 us late (its timer slack) so that wake-ups
    can be merged; ask for 1 us. Best effort: nothing happens where prctl is not available."""
    if not sys.platform.startswith("linux"):
        return
    with contextlib.suppress(OSError, AttributeError):
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_TIMERSLACK, ctypes.c_ulong(1000), 0, 0, 0)


def new_event_loop() -> asyncio.AbstractEventLoop:
    """The relay's event loop: asyncio on ``PreciseSelector`` where epoll exists, with a
    tight timer slack for the thread that runs it."""
    _tight_timer_slack()
    if hasattr(selectors, "EpollSelector"):
        return asyncio.SelectorEventLoop(PreciseSelector())
    return asyncio.new_event_loop()


class Recorder:
    """Per-direction counts and a uniform sample (reservoir) of delays and lateness, in ms.

    ``send_errors``: sends of this direction that failed (``DirectionStats``); on a connected
    UDP socket the kernel reports an ICMP error for an earlier datagram on the next send or
    receive, so the receive side counts those for the direction that sent through that socket.
    ``in_flight``: packets still held by a lane when it closed (relay stop, connection closed),
    never delivered. ``bytes``: payload bytes forwarded (DESIGN 12: what each direction carries).
    """

    def __init__(self, seed: int) -> None:
        self.forwarded = 0
        self.bytes = 0
        self.dropped = 0
        self.send_errors = 0
        self.in_flight = 0
        self.delays_ms = array.array("d")
        self.late_ms = array.array("d")
        self.max_delay_ms = 0.0
        self.max_late_ms = 0.0
        self._rng = random.Random(seed)

    def record(self, delay_s: float, late_s: float, nbytes: int = 0) -> None:
        """One packet of ``nbytes`` released ``delay_s`` after it was read, ``late_s`` after it
        was due."""
        self.forwarded += 1
        self.bytes += nbytes
        delay_ms, late_ms = delay_s * 1000.0, late_s * 1000.0
        self.max_delay_ms = max(self.max_delay_ms, delay_ms)
        self.max_late_ms = max(self.max_late_ms, late_ms)
        if len(self.delays_ms) < RESERVOIR:
            self.delays_ms.append(delay_ms)
            self.late_ms.append(late_ms)
        else:
            i = self._rng.randrange(self.forwarded)
            if i < RESERVOIR:
                self.delays_ms[i] = delay_ms
                self.late_ms[i] = late_ms

    def stats(self) -> DirectionStats:
        """The summary; the maxima are exact even when the reservoir is full."""
        s = DirectionStats.from_samples(
            self.forwarded,
            self.dropped,
            self.delays_ms,
            self.late_ms,
            self.send_errors,
            self.in_flight,
            self.bytes,
        )
        if not self.forwarded:
            return s
        return DirectionStats(
            s.forwarded,
            s.dropped,
            s.p50_ms,
            s.p90_ms,
            s.p99_ms,
            self.max_delay_ms,
            s.late_p50_ms,
            s.late_p99_ms,
            self.max_late_ms,
            self.send_errors,
            self.in_flight,
            self.bytes,
        )


class Lane:
    """One direction of one flow: the model decides, a heap holds packets until they are due.

    ``send`` delivers bytes; ``None`` in the heap is a TCP end of stream, delivered in order
    after the data before it, which calls ``on_eof``. A lane made ``held`` releases nothing
    (packets wait in the heap, their delays running) until ``resume()``: a TCP client's bytes
    while the connection to the target is being made.
    """

    def __init__(
        self,
        loop: asyncio.AbstractEventLoop,
        model: LinkModel,
        t0: float,
        send: Callable[[bytes], object],
        recorder: Recorder,
        on_eof: Callable[[], None] | None = None,
        on_pressure: Callable[[bool], None] | None = None,
        held: bool = False,
    ) -> None:
        self._loop = loop
        self._model = model
        self._t0 = t0
        self._send = send
        self._rec = recorder
        self._on_eof = on_eof
        self._on_pressure = on_pressure
        self._pressed = False
        self.queued_bytes = 0
        self._heap: list[tuple[float, int, float, bytes | None]] = []
        self._seq = 0
        self._timer: asyncio.TimerHandle | None = None
        self._timer_at = 0.0
        self.held = held
        self.closed = False

    def push(self, data: bytes, now: float) -> None:
        """A packet read at monotonic time ``now``. With ``on_pressure``, calls it with True when
        the lane holds too much (``MAX_QUEUED_BYTES``, ``MAX_BACKLOG_S``), False once it drained
        to half of that."""
        arrival = self._model.transit(now - self._t0, len(data))
        if arrival is None:
            self._rec.dropped += 1
            return
        due = arrival + self._t0
        if due <= now and not self._heap and not self.held:
            if self._deliver(data):
                self._rec.record(0.0, 0.0, len(data))
            return
        self._enqueue(due, now, data)
        self.queued_bytes += len(data)
        if self._on_pressure is not None and not self._pressed and self._full(now, 1.0):
            self._pressed = True
            self._on_pressure(True)

    def _full(self, now: float, share: float) -> bool:
        return (
            self.queued_bytes > MAX_QUEUED_BYTES * share
            or self._model.backlog_s(now - self._t0) > MAX_BACKLOG_S * share
        )

    def push_eof(self, now: float) -> None:
        """The sender closed: close the other end once what was sent before has arrived."""
        arrival = self._model.transit(now - self._t0, 0)
        self._enqueue(now if arrival is None else arrival + self._t0, now, None)

    def _enqueue(self, due: float, now: float, data: bytes | None) -> None:
        self._seq += 1
        heapq.heappush(self._heap, (due, self._seq, now, data))
        if not self.held and (self._timer is None or due < self._timer_at):
            self._arm(due)

    def resume(self) -> None:
        """Stop holding: deliver, in order, what is due and schedule the rest."""
        self.held = False
        if self._heap and not self.closed:
            self._release()

    def _arm(self, due: float) -> None:
        if self._timer is not None:
            self._timer.cancel()
        self._timer_at = due
        self._timer = self._loop.call_at(due, self._release)

    def _release(self) -> None:
        self._timer = None
        heap = self._heap
        now = time.monotonic()
        while heap and heap[0][0] <= now:
            due, _, read_at, data = heapq.heappop(heap)
            if data is None:
                self._discard()
                if self._on_eof is not None:
                    self._on_eof()
                return
            self.queued_bytes -= len(data)
            if self._deliver(data):
                self._rec.record(now - read_at, now - due, len(data))
        if self._pressed and not self._full(now, 0.5):
            self._pressed = False
            assert self._on_pressure is not None
            self._on_pressure(False)
        if heap:
            self._arm(heap[0][0])

    def _deliver(self, data: bytes) -> bool:
        """Send ``data``; False (and a send error counted) when the system refuses it."""
        try:
            self._send(data)
        except OSError:
            self._rec.send_errors += 1
            return False
        return True

    def _discard(self) -> None:
        """Empty the heap, counting the packets in it as in flight (never delivered)."""
        self._rec.in_flight += sum(1 for entry in self._heap if entry[3] is not None)
        self._heap.clear()
        self.queued_bytes = 0

    def close(self) -> None:
        """Forget what is queued (counted in flight: never delivered) and stop the timer."""
        self.closed = True
        self._discard()
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None


class _Side(asyncio.Protocol):
    """One TCP end of a pipe: bytes read go into ``lane``; write pressure pauses the other end."""

    def __init__(self, pipe: _TcpPipe, name: str) -> None:
        self.pipe = pipe
        self.name = name
        self.transport: asyncio.Transport | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport
        self.pipe.side_ready(self)

    def data_received(self, data: bytes) -> None:
        self.pipe.lane_from(self).push(data, time.monotonic())

    def eof_received(self) -> bool:
        self.pipe.side_closed(self)
        return True  # keep our write half open until the end of stream has arrived

    def connection_lost(self, exc: Exception | None) -> None:
        self.pipe.side_closed(self)

    def pause_writing(self) -> None:
        self.pipe.pause(self.pipe.other(self), "write buffer", True)

    def resume_writing(self) -> None:
        self.pipe.pause(self.pipe.other(self), "write buffer", False)


class _TcpPipe:
    """One accepted client connection and its connection to the target."""

    def __init__(self, relay: Relay, number: int) -> None:
        self.relay = relay
        self.number = number
        self.client = _Side(self, "client")
        self.server = _Side(self, "server")
        self._closing: set[str] = set()
        self._paused: dict[str, set[str]] = {"client": set(), "server": set()}
        loop, t0, seed = relay.loop, relay.t0, relay.seed
        self.up = Lane(
            loop,
            LinkModel(relay.up, flow_seed(seed, "up", number), ordered=True),
            t0,
            self._to_server,
            relay.recorders["up"],
            self.close,
            lambda on: self.pause(self.client, "link queue", on),
            held=True,  # until the connection to the target is made
        )
        self.down = Lane(
            loop,
            LinkModel(relay.down, flow_seed(seed, "down", number), ordered=True),
            t0,
            self._to_client,
            relay.recorders["down"],
            self.close,
            lambda on: self.pause(self.server, "link queue", on),
        )
        self.closed = False

    def pause(self, side: _Side, reason: str, on: bool) -> None:
        """Stop or resume reading from ``side``; it reads again once no reason is left."""
        reasons = self._paused[side.name]
        before = bool(reasons)
        if on:
            reasons.add(reason)
        else:
            reasons.discard(reason)
        transport = side.transport
        if transport is None or transport.is_closing() or before == bool(reasons):
            return
        if reasons:
            transport.pause_reading()
        else:
            transport.resume_reading()

    def other(self, side: _Side) -> _Side:
        return self.server if side is self.client else self.client

    def lane_from(self, side: _Side) -> Lane:
        return self.up if side is self.client else self.down

    def side_ready(self, side: _Side) -> None:
        if side is self.client:
            self.relay.loop.create_task(self._connect())
        elif self.closed:  # the client went (or the relay stopped) while connecting
            assert side.transport is not None
            side.transport.close()
        else:
            self.relay.target_reached()
            self.up.resume()

    async def _connect(self) -> None:
        """The one connection to the target for this client (module docstring)."""
        target = self.relay.connect
        try:
            await asyncio.wait_for(
                self.relay.loop.create_connection(lambda: self.server, target.host, target.port),
                CONNECT_TIMEOUT_S,
            )
        except TimeoutError:
            self.relay.target_failed(self.number, f"no answer in {CONNECT_TIMEOUT_S:g} s")
            self.close()
        except OSError as exc:
            # asyncio's strerror is "Connect call failed (ADDR)"; the errno says why.
            reason = os.strerror(exc.errno) if exc.errno else str(exc) or type(exc).__name__
            self.relay.target_failed(self.number, reason)
            self.close()

    def _to_server(self, data: bytes) -> None:
        transport = self.server.transport
        assert transport is not None  # the up lane is held until it is there
        if not transport.is_closing():  # an end that went away: its bytes have nowhere to go
            transport.write(data)

    def _to_client(self, data: bytes) -> None:
        transport = self.client.transport
        assert transport is not None
        if not transport.is_closing():
            transport.write(data)

    def side_closed(self, side: _Side) -> None:
        """An end closed or sent EOF: the other end closes once the bytes before it arrived."""
        if side.name in self._closing or self.closed:
            return
        self._closing.add(side.name)
        self.lane_from(side).push_eof(time.monotonic())

    def close(self) -> None:
        """Close both ends now (flushing what was already released to them)."""
        if self.closed:
            return
        self.closed = True
        self.up.close()
        self.down.close()
        for side in (self.client, self.server):
            if side.transport is not None:
                side.transport.close()
        self.relay.pipe_closed(self)

    def abort(self) -> None:
        """Stop at once (relay shutdown)."""
        for side in (self.client, self.server):
            if side.transport is not None:
                side.transport.abort()
        self.close()


class _UdpFlow:
    """One client address: a socket of its own towards the target, one lane per direction."""

    def __init__(self, relay: Relay, number: int, client: tuple[object, ...]) -> None:
        assert relay.udp_sock is not None
        self.relay = relay
        self.client = client
        target = relay.connect
        self.sock = socket.socket(_family(target.host), socket.SOCK_DGRAM)
        self.sock.setblocking(False)
        self.sock.connect((target.host, target.port))
        listen_sock = relay.udp_sock

        def to_client(data: bytes) -> None:
            listen_sock.sendto(data, client)

        loop, t0, seed = relay.loop, relay.t0, relay.seed
        self.up = Lane(
            loop,
            LinkModel(relay.up, flow_seed(seed, "up", number), ordered=False),
            t0,
            self.sock.send,
            relay.recorders["up"],
        )
        self.down = Lane(
            loop,
            LinkModel(relay.down, flow_seed(seed, "down", number), ordered=False),
            t0,
            to_client,
            relay.recorders["down"],
        )
        loop.add_reader(self.sock.fileno(), self._readable)

    def _readable(self) -> None:
        recv, push = self.sock.recv, self.down.push
        for _ in range(_READS_PER_WAKEUP):
            try:
                data = recv(MAX_DATAGRAM)
            except BlockingIOError:
                return
            except OSError:
                # ICMP port unreachable (or another error) for a datagram sent up to the
                # target through this connected socket: an up send error, nothing to forward.
                self.relay.recorders["up"].send_errors += 1
                return
            push(data, time.monotonic())

    def close(self) -> None:
        self.up.close()
        self.down.close()
        self.relay.loop.remove_reader(self.sock.fileno())
        self.sock.close()


class Relay:
    """The relay between ``listen`` (operator side) and ``connect`` (robot side).

    ``await start()`` binds and returns the endpoint actually listened on (port 0 picks one);
    ``close()`` stops everything; ``stats()`` summarises each direction. ``connections`` counts
    the client connections (TCP) or client addresses (UDP), ``connect_failures`` the TCP ones
    whose connection to the target failed. ``log`` takes the per-connection lines, ``warn``
    the first refusal of each streak (both default to stderr); ``label`` names a connection in
    them.
    """

    def __init__(
        self,
        listen: Endpoint,
        connect: Endpoint,
        up: Schedule,
        down: Schedule,
        seed: int = 0,
        log: Callable[[str], None] | None = None,
        warn: Callable[[str], None] | None = None,
        label: str = "connection",
    ) -> None:
        if listen.proto != connect.proto:
            raise EndpointError(
                f"--listen {listen} and --connect {connect} must use the same protocol"
            )
        if listen.proto == "tcp":
            if up.has_loss or down.has_loss:
                raise SpecError(TCP_LOSS_MESSAGE)
            if any(p.spec.reorder for s in (up, down) for p in s.phases):
                raise SpecError("reorder=1 is for udp/ links: a TCP connection delivers in order")
        self.listen = listen
        self.connect = connect
        self.up = up
        self.down = down
        self.seed = seed
        self.log = log or _to_stderr
        self.warn = warn or _to_stderr
        self.label = label
        self.recorders = {
            "up": Recorder(derive_seed(seed, "stats/up")),
            "down": Recorder(derive_seed(seed, "stats/down")),
        }
        self.connections = 0
        self.connect_failures = 0
        self._failing = False  # the last connection to the target failed
        self.t0 = 0.0
        self._loop: asyncio.AbstractEventLoop | None = None
        self._server: asyncio.Server | None = None
        self._pipes: set[_TcpPipe] = set()
        self.udp_sock: socket.socket | None = None
        self._flows: dict[tuple[object, ...], _UdpFlow] = {}

    @property
    def loop(self) -> asyncio.AbstractEventLoop:
        assert self._loop is not None, "start() first"
        return self._loop

    async def start(self) -> Endpoint:
        """Bind the listen endpoint (``OSError`` if it cannot) and start relaying."""
        self._loop = asyncio.get_running_loop()
        self.t0 = time.monotonic()
        if self.listen.proto == "tcp":
            self._server = await self.loop.create_server(
                self._accept, self.listen.host, self.listen.port, reuse_address=True
            )
            port = self._server.sockets[0].getsockname()[1]
        else:
            sock = socket.socket(_family(self.listen.host), socket.SOCK_DGRAM)
            try:
                sock.bind((self.listen.host, self.listen.port))
            except OSError:
                sock.close()
                raise
            sock.setblocking(False)
            self.udp_sock = sock
            self.loop.add_reader(sock.fileno(), self._udp_readable)
            port = sock.getsockname()[1]
        return Endpoint(self.listen.proto, self.listen.host, port)

    def _accept(self) -> asyncio.Protocol:
        self.connections += 1
        pipe = _TcpPipe(self, self.connections)
        self._pipes.add(pipe)
        return pipe.client

    def pipe_closed(self, pipe: _TcpPipe) -> None:
        self._pipes.discard(pipe)

    def target_failed(self, number: int, reason: str) -> None:
        """Connection ``number`` could not reach the target: counted; the first of a streak is
        a warning, the rest (a client retrying every second) per-connection lines."""
        self.connect_failures += 1
        line = (
            f"link: {self.label} {number}: cannot connect to {self.connect} ({reason}); "
            "closing the client connection"
        )
        if self._failing:
            self.log(line)
        else:
            self._failing = True
            self.warn(line)

    def target_reached(self) -> None:
        self._failing = False

    def _udp_readable(self) -> None:
        sock = self.udp_sock
        assert sock is not None
        flows = self._flows
        for _ in range(_READS_PER_WAKEUP):
            try:
                data, client = sock.recvfrom(MAX_DATAGRAM)
            except BlockingIOError:
                return
            except OSError:
                # An error queued on the listen socket concerns what it sent: the down
                # direction's datagrams to a client.
                self.recorders["down"].send_errors += 1
                return
            flow = flows.get(client)
            if flow is None:
                self.connections += 1
                try:
                    flow = flows[client] = _UdpFlow(self, self.connections, client)
                except OSError as exc:
                    self.log(f"link: cannot open a socket towards {self.connect}: {exc}")
                    return
            flow.up.push(data, time.monotonic())

    async def close(self) -> None:
        """Stop listening and drop every connection and queued packet."""
        if self._server is not None:
            self._server.close()
        for pipe in list(self._pipes):
            pipe.abort()
        for flow in self._flows.values():
            flow.close()
        self._flows.clear()
        if self.udp_sock is not None:
            self.loop.remove_reader(self.udp_sock.fileno())
            self.udp_sock.close()
            self.udp_sock = None
        if self._server is not None:
            with contextlib.suppress(Exception):
                await asyncio.wait_for(self._server.wait_closed(), 1.0)

    def stats(self) -> dict[str, DirectionStats]:
        """Per direction: forwarded, dropped and the delays applied (ms), with lateness."""
        return {name: rec.stats() for name, rec in self.recorders.items()}


def check_resolvable(target: Endpoint) -> None:
    """Resolve the target's host (``OSError`` when it cannot be); never connects to it (module
    docstring: a probe would take a single-client target's one place)."""
    kind = socket.SOCK_STREAM if target.proto == "tcp" else socket.SOCK_DGRAM
    socket.getaddrinfo(target.host, target.port, type=kind)


def _to_stderr(line: str) -> None:
    print(line, file=sys.stderr, flush=True)
