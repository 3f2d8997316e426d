"""The one thin Zenoh adapter shared by the robot, the operator and the sim bridge (DESIGN 1, 7).

Everything that decides how a process joins the Zenoh network lives here, so that the three
processes and the tests agree on it:

- Peer mode by default, with **multicast scouting off** and explicit endpoints: a process only
  talks to the endpoints it is told about (``--connect``/``--listen``), so tests on loopback can
  run in parallel on free ports without finding each other. Client mode (``--zenoh-mode client``)
  connects to a router (``deploy/``).
- ``--zenoh-config FILE`` loads a full Zenoh JSON5 configuration (TLS, access control, ...);
  ``--zenoh-mode``, ``--connect`` and ``--listen`` given on the command line still override it.
- Lease 2 s with 4 keep-alives per lease (one every 500 ms): a hung peer (SIGSTOP, its TCP
  link still open) is declared dead within 2 s (the SIGSTOP integration test checks it), which
  drops its liveliness tokens (DESIGN 8: operator lost -> release control, centre again). The
  robot's watchdog holds after ``command_timeout`` (250 ms) regardless; the lease equals the
  short-gap ``resume_window`` so that a link outage shorter than it keeps the operator's session
  and its liveliness token (a 1 s outage resumes without re-centring, DESIGN 8).
  Each side advertises its own lease, so every process of this project uses the same value.
- Two planes (DESIGN 12). **Control** (``command_publisher``, ``control_publisher``,
  ``CONTROL_REPLY``): commands at REAL_TIME, state, clock queries and replies at
  INTERACTIVE_HIGH, all express (sent at once, never batched behind anything). **View**
  (``view_publisher``): telemetry at DATA, the camera at DATA_LOW, congestion control DROP.
  Zenoh keeps one transmission queue per priority and always sends from the highest non-empty
  one, so view data can never hold a control message back *inside Zenoh*. Control messages are
  published with DROP too, on purpose: the robot's control loop and Zenoh's callbacks must never
  block on a dead link (BLOCK would stall the watchdog for up to ``wait_before_close``); their own
  queues (``QUEUE_SIZE``: 4 batches at REAL_TIME and INTERACTIVE_HIGH, each up to 64 kB) hold
  seconds of these small messages, so they are dropped only when the link carries nothing at all.
  The view queues hold one batch each, so a view message that cannot go out is dropped after
  ``wait_before_drop`` (Zenoh's 1 ms) instead of waiting: latest-only. Every data publisher is
  **best effort**: a fresh command or telemetry message makes the one before it worthless, so
  none is ever retransmitted or waited for (DESIGN 9). Declarations, liveliness tokens and
  queries (the clock, the map) are Zenoh's reliable traffic.
  What priorities cannot do: reorder bytes already handed to the kernel's socket buffer or
  queued in a link's own buffer (a cellular uplink, ``egc-teleop link``'s ``rate=``). There,
  keep-alives, clock replies and state wait behind whatever view data went before them; a
  standing queue longer than the lease even closes the session. The cure is to send less view
  data than the link carries, adaptively: the robot's downlink budget (``egc_common.view_budget``).
- UDP (DESIGN 9 "Transport"): a ``udp/HOST:PORT`` endpoint given on the command line
  (``--connect``, ``--listen``) without ``rel=`` metadata becomes two links of one Zenoh
  transport (``transport/unicast/max_links`` 2): ``tcp/HOST:PORT`` for Zenoh's reliable traffic
  (the handshake, declarations, liveliness tokens, queries such as the clock and the map) and
  ``udp/HOST:PORT?rel=0`` for the best-effort traffic, which is all our data (commands,
  telemetry, state, scans). Zenoh sends each message on the link whose reliability matches, so a
  lost datagram is never retransmitted or waited for and never holds a later one back (no
  head-of-line blocking), and nothing on the data path is congestion-controlled into a queue.
  Measured through ``egc-teleop link`` at 100 ms +- 20 ms with 5 % loss each way
  (docs/transport.md): this keeps the operator's view 116 ms old (p50) and the demo at full
  speed, where Zenoh's mixed-reliability QUIC over UDP (``?rel=1;mixed_rel=1``, whose datagrams
  are congestion-controlled) let the view fall 7.5 s behind, so the latency governor slowed the
  robot to 17 % of its loopback distance; plain UDP alone (``?rel=0`` only) loses declarations
  and breaks sessions (1 of 2 tries at 5 % loss). Both sides must agree, and a firewall or relay
  must pass TCP and UDP on that port. An endpoint that already says ``rel=`` is used as given.
  A connecting process opens the TCP link first (``_tcp_first``), so that the declarations
  never travel on UDP; its ``zenoh.open`` then waits until the peer's TCP port accepts. What
  Zenoh 1.10 does not do: re-add the UDP link after the transport was lost and reopened (an
  outage longer than the lease) or after the UDP link alone was lost; the data then goes over
  TCP for the rest of the session (it still drives, with TCP's head-of-line blocking). A client
  of a router opens a single link: the TCP one.

Only this module and the process adapters import ``zenoh``; the cores never do (DESIGN 2).
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import re
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import zenoh

from egc_common.errors import UsageError

MODES = ("peer", "client")
DEFAULT_PORT = 7447
DEFAULT_ENDPOINT = f"tcp/127.0.0.1:{DEFAULT_PORT}"
LEASE_MS = 2000
KEEP_ALIVES_PER_LEASE = 4
RECONNECT_PERIOD_MS = (250, 1000)  # first retry, longest retry
UDP_HANDSHAKE_TIMEOUT_MS = 4000
MAX_LINKS = 2  # a TCP and a UDP link to the same peer may form one transport (docs/transport.md)
# Batches per priority queue (Zenoh's default is 2 each): more room for the control plane, one
# for the view plane so that its data is dropped, not queued, when the link is busy (DESIGN 12).
QUEUE_SIZE = {
    "control": 2,
    "real_time": 4,
    "interactive_high": 4,
    "interactive_low": 2,
    "data_high": 2,
    "data": 1,
    "data_low": 1,
    "background": 1,
}


@dataclass(frozen=True, slots=True)
class ZenohOptions:
    """How one process joins the Zenoh network."""

    mode: str | None = None
    connect: tuple[str, ...] = ()
    listen: tuple[str, ...] = ()
    config_file: str | None = None
    lease_ms: int | None = None

    def __post_init__(self) -> None:
        if self.mode is not None and self.mode not in MODES:
            raise UsageError(f"zenoh mode must be one of {', '.join(MODES)}, got {self.mode!r}")
        for endpoint in (*self.connect, *self.listen):
            if "/" not in endpoint:
                raise UsageError(f"zenoh endpoint {endpoint!r} must look like tcp/HOST:PORT")
        if self.lease_ms is not None and not 100 <= self.lease_ms <= 600_000:
            raise UsageError("--lease-ms must be within [100, 600000]")


def add_zenoh_arguments(
    parser: argparse.ArgumentParser,
    default_listen: Sequence[str] = (),
    default_connect: Sequence[str] = (),
) -> None:
    """Add --zenoh-config, --zenoh-mode, --connect, --listen and --lease-ms to a subcommand.

    ``--connect``/``--listen`` are also spelled ``--zenoh-connect``/``--zenoh-listen``; where a
    subcommand already defines the short spelling (the operator's ``--connect`` takes Zenoh
    endpoints and its view's URL alike), only the ``--zenoh-`` spelling is added.
    """
    taken = set(parser._option_string_actions)

    def spellings(name: str) -> list[str]:
        return [s for s in (f"--{name}", f"--zenoh-{name}") if s not in taken]

    group = parser.add_argument_group("zenoh")
    group.add_argument(
        "--zenoh-config",
        metavar="FILE",
        help="Zenoh JSON5 configuration file (TLS, access control, router, ...); "
        "--zenoh-mode/--connect/--listen still override it",
    )
    group.add_argument(
        "--zenoh-mode",
        choices=MODES,
        default=None,
        help="peer, or client of a router (default: peer, or the file's)",
    )
    group.add_argument(
        *spellings("connect"),
        dest="zenoh_connect",
        action="append",
        metavar="ENDPOINT",
        help="endpoint to connect to, e.g. tcp/192.168.1.10:7447 (repeatable; default: "
        f"{', '.join(default_connect) or 'none'})",
    )
    group.add_argument(
        *spellings("listen"),
        dest="zenoh_listen",
        action="append",
        metavar="ENDPOINT",
        help=f"endpoint to listen on (repeatable; default: {', '.join(default_listen) or 'none'})",
    )
    group.add_argument(
        "--lease-ms",
        type=int,
        default=None,
        metavar="MS",
        help=f"transport lease; a silent peer is dropped after it (default: {LEASE_MS})",
    )
    parser.set_defaults(
        _zenoh_default_listen=tuple(default_listen), _zenoh_default_connect=tuple(default_connect)
    )


def options_from_args(args: argparse.Namespace) -> ZenohOptions:
    """The options given on the command line; role defaults apply only without a config file."""
    from_file = args.zenoh_config is not None
    connect = args.zenoh_connect or ([] if from_file else list(args._zenoh_default_connect))
    # A client accepts no sessions: the role's default listen endpoint would only collide with
    # a router on the same machine (the robot's default port is the router's).
    no_default_listen = from_file or args.zenoh_mode == "client"
    listen = args.zenoh_listen or ([] if no_default_listen else list(args._zenoh_default_listen))
    return ZenohOptions(
        mode=args.zenoh_mode,
        connect=tuple(connect),
        listen=tuple(listen),
        config_file=args.zenoh_config,
        lease_ms=args.lease_ms,
    )


def build_config(options: ZenohOptions) -> zenoh.Config:
    """A Zenoh configuration for ``options`` (see the module docstring for the rules)."""
    if options.config_file is not None:
        path = Path(options.config_file)
        if not path.is_file():
            raise UsageError(f"zenoh config file not found: {path}")
        try:
            config = zenoh.Config.from_file(str(path))
        except Exception as exc:  # zenoh raises its own ZError with the parser's message
            raise UsageError(f"invalid zenoh config {path}: {_one_line(exc)}") from None
    else:
        config = zenoh.Config()
        _insert(config, "mode", "peer")
        _insert(config, "scouting/multicast/enabled", False)
        _insert(config, "listen/endpoints", [])
        _insert(config, "transport/link/tx/lease", LEASE_MS)
        _insert(config, "transport/link/tx/keep_alive", KEEP_ALIVES_PER_LEASE)
        _insert(config, "transport/unicast/max_links", MAX_LINKS)
        _insert(config, "transport/link/tx/queue/size", QUEUE_SIZE)
        first, longest = RECONNECT_PERIOD_MS
        _insert(
            config,
            "connect/retry",
            {"period_init_ms": first, "period_max_ms": longest, "period_increase_factor": 2},
        )
    if options.mode is not None:
        _insert(config, "mode", options.mode)
    connect = [link for e in options.connect for link in _tcp_first(expand_endpoint(e))]
    listen = [link for e in options.listen for link in expand_endpoint(e)]
    if connect:
        _insert(config, "connect/endpoints", connect)
    if listen:
        _insert(config, "listen/endpoints", listen)
    if len(connect) > len(options.connect) or len(listen) > len(options.listen):
        _insert(config, "transport/unicast/max_links", 2)
        # A lost handshake datagram on the UDP link would otherwise keep it closed for Zenoh's
        # default 10 s (the data then takes the TCP link meanwhile, head-of-line blocking and
        # all); 4 s still covers two round trips of a 500 ms +- 100 ms satellite link.
        _insert(config, "transport/unicast/open_timeout", UDP_HANDSHAKE_TIMEOUT_MS)
        _insert(config, "transport/unicast/accept_timeout", UDP_HANDSHAKE_TIMEOUT_MS)
    if options.lease_ms is not None:
        _insert(config, "transport/link/tx/lease", options.lease_ms)
    return config


def _insert(config: zenoh.Config, key: str, value: Any) -> None:
    try:
        config.insert_json5(key, json.dumps(value))
    except Exception as exc:
        raise UsageError(f"zenoh config {key}={value!r} rejected: {_one_line(exc)}") from None


def expand_endpoint(endpoint: str) -> tuple[str, ...]:
    """``udp/HOST:PORT`` -> ``(tcp/HOST:PORT, udp/HOST:PORT?rel=0)`` (module docstring, "UDP").

    Other protocols, and UDP endpoints that already say ``rel=``, are returned alone and
    unchanged; other metadata (``?iface=...``) and the configuration part (``#...``) are kept on
    both links.
    """
    if not endpoint.startswith("udp/"):
        return (endpoint,)
    locator, hash_, config_part = endpoint.partition("#")
    address, _, metadata = locator.partition("?")
    items = [m for m in metadata.split(";") if m]
    if any(m.split("=", 1)[0] == "rel" for m in items):
        return (endpoint,)
    tail = f"{hash_}{config_part}"
    tcp_meta = f"?{';'.join(items)}" if items else ""
    tcp = "tcp/" + address.removeprefix("udp/") + tcp_meta + tail
    udp = f"{address}?{';'.join([*items, 'rel=0'])}{tail}"
    return (tcp, udp)


def _tcp_first(links: tuple[str, ...]) -> tuple[str, ...]:
    """The TCP half of a connecting ``udp/`` pair is opened first (module docstring, "UDP").

    Zenoh opens the connect endpoints of a peer in parallel, and the first link to finish its
    handshake opens the transport and carries the declarations at once; UDP's handshake usually
    wins, so they went out unreliably and were lost (at 5 % loss 3 of 30 sessions never saw the
    other side's liveliness token or never got data). ``exit_on_failure=true`` in the TCP
    endpoint's configuration makes Zenoh connect it (retrying) before it starts the UDP one:
    0 of 30 at 5 % and 0 of 15 at 20 % loss. The price: ``zenoh.open`` returns only once the
    TCP endpoint has accepted (a process connecting to a peer that is not up yet waits for it).
    """
    if len(links) != 2:
        return links
    tcp, udp = links
    locator, _, config_part = tcp.partition("#")
    config_part = ";".join([c for c in config_part.split(";") if c] + ["exit_on_failure=true"])
    return (f"{locator}#{config_part}", udp)


def _one_line(exc: BaseException | str) -> str:
    """Zenoh's error text without its source locations and internal endpoint wrappers, on one
    line: ``Unable to connect to any of [Single(tls/h:1#exit_on_failure=true)]!`` reads
    ``Unable to connect to any of tls/h:1``."""
    text = re.sub(r"\s+at \S+\.rs:\d+\.?", "", str(exc))
    text = re.sub(r"#[^,\]\s)]*", "", text)  # an endpoint's configuration part
    text = re.sub(r"\[((?:Single\([^)]*\)(?:, )?)+)\]!?", _endpoint_list, text)
    return " ".join(text.split()) or type(exc).__name__


def _endpoint_list(match: re.Match[str]) -> str:
    return ", ".join(re.findall(r"Single\(([^)]*)\)", match.group(1)))


_ANSI = re.compile(r"\x1b\[[0-9;]*m")
# "Can not create a new TLS link bound to IpAddress(...): " / "... TCP link bound to
# tcp/h:1: [h:1: ": Zenoh's framing around the cause.
_LINK_PREFIX = re.compile(
    r"^Can not create a new \S+ link bound to [^:]*(?::\d+)?: \[?(?:\S+:\d+: )?"
)
_REASON_PROBE = """import sys, zenoh
zenoh.init_log_from_env_or("warn")
try:
    zenoh.open(zenoh.Config.from_json5(sys.stdin.read())).close()
except Exception:
    pass
"""


def zenoh_reason(config: zenoh.Config, timeout_s: float = 10.0) -> str | None:
    """Why Zenoh could not connect, in its own words, or None.

    Zenoh keeps the cause of a failed connection (a TLS certificate not valid for the name
    connected to, an expired one, a refused connection) in its log, not in the error it raises,
    and its log goes to stdout once turned on, where it would mix with a process's own output.
    So the same configuration is opened once more in a child process with Zenoh's log at warn
    level, and the first "Unable to connect to X! reason" line is returned as "X: reason".
    """
    try:
        probe = subprocess.run(
            [sys.executable, "-c", _REASON_PROBE],
            input=str(config),
            capture_output=True,
            text=True,
            timeout=timeout_s,
            env={k: v for k, v in os.environ.items() if k != "RUST_LOG"},
        )
    except (OSError, subprocess.SubprocessError):
        return None
    for line in _ANSI.sub("", probe.stdout).splitlines():
        found = re.search(r"Unable to connect to (?!any of)(\S+)! (.+)", line)
        if found:
            reason = _LINK_PREFIX.sub("", _one_line(found.group(2))).strip("[]. ")
            return f"{_one_line(found.group(1))}: {reason}"
    return None


_OPEN_NOTICE_S = 2.0
_OPENER_NAME = "zenoh-open"


def still_opening() -> bool:
    """True while a session given up on (``open_config``'s ``give_up_s``, or Ctrl-C) is still
    inside ``zenoh.open`` in its helper thread. Such a process must leave with ``os._exit``:
    at interpreter shutdown that native call is torn down mid-way and the process aborts
    ("FATAL: exception not rethrown", exit 134) after it already said why it stops."""
    return any(t.name == _OPENER_NAME and t.is_alive() for t in threading.enumerate())


def open_config(config: zenoh.Config, give_up_s: float | None = None) -> zenoh.Session:
    """Open a session on ``config``; a failure (e.g. a port in use) is one UsageError line.

    ``zenoh.open`` blocks while a ``udp/`` connect waits for its TCP half (``_tcp_first``), and
    Python handles Ctrl-C only between bytecodes of the main thread: a process connecting to a
    peer that was not up sat silent and deaf to Ctrl-C. So it opens in a helper thread while
    this one waits in short steps (Ctrl-C ends the wait) and says, once, what it waits for.
    ``give_up_s``: stop waiting after that long (a run with a ``--duration`` must not outlive
    it waiting for a peer that never came: an outside check waited 12 minutes) with a UsageError.
    """
    result: list[zenoh.Session | BaseException] = []

    def open_it() -> None:
        try:
            result.append(zenoh.open(config))
        except BaseException as exc:
            result.append(exc)

    opener = threading.Thread(target=open_it, name=_OPENER_NAME, daemon=True)
    started = time.monotonic()
    opener.start()
    opener.join(_OPEN_NOTICE_S if give_up_s is None else min(_OPEN_NOTICE_S, give_up_s))
    if opener.is_alive():
        try:
            endpoints = json.loads(config.get_json("connect/endpoints"))
            peers = ", ".join(str(e).partition("#")[0] for e in endpoints) or "?"
            udp_pair = "exit_on_failure=true" in str(endpoints)
        except Exception:
            peers, udp_pair = "?", False
        logging.getLogger("egc.transport").warning(
            "waiting for the peer to accept at %s (%sis the other side up?); Ctrl-C to stop",
            peers,
            "a udp/ endpoint opens on TCP first; " if udp_pair else "",
        )
        while opener.is_alive():
            if give_up_s is not None and time.monotonic() - started >= give_up_s:
                raise UsageError(
                    f"gave up after {give_up_s:g} s: the peer at {peers} never accepted"
                )
            opener.join(0.1)
    outcome = result[0]
    if isinstance(outcome, BaseException):
        message = f"cannot open zenoh session: {_one_line(outcome)}"
        if "Unable to connect" in message and (reason := zenoh_reason(config)) is not None:
            message += f" ({reason})"
        raise UsageError(message) from None
    return outcome


def open_session(options: ZenohOptions, give_up_s: float | None = None) -> zenoh.Session:
    """Open a session; a failure (e.g. a port in use) becomes one clear UsageError line."""
    return open_config(build_config(options), give_up_s)


def command_publisher(session: zenoh.Session, key: str) -> zenoh.Publisher:
    """Operator commands and base commands, control plane (DESIGN 12): REAL_TIME, express, best
    effort (a lost one is never retransmitted or waited for; over UDP they take the datagram
    link), never queued behind data."""
    return session.declare_publisher(
        key,
        priority=zenoh.Priority.REAL_TIME,
        express=True,
        congestion_control=zenoh.CongestionControl.DROP,
        reliability=zenoh.Reliability.BEST_EFFORT,
    )


def control_publisher(session: zenoh.Session, key: str) -> zenoh.Publisher:
    """The robot's state (on change and at 1 Hz), control plane (DESIGN 12): INTERACTIVE_HIGH,
    express, best effort (the next one repeats it), DROP so that the control loop never blocks
    (module docstring: its queue empties unless the link carries nothing)."""
    return session.declare_publisher(
        key,
        priority=zenoh.Priority.INTERACTIVE_HIGH,
        express=True,
        congestion_control=zenoh.CongestionControl.DROP,
        reliability=zenoh.Reliability.BEST_EFFORT,
    )


# Options of a reply to a control-plane query (the robot's clock): like ``control_publisher``.
CONTROL_REPLY: dict[str, Any] = {
    "priority": zenoh.Priority.INTERACTIVE_HIGH,
    "express": True,
    "congestion_control": zenoh.CongestionControl.DROP,
}


def view_publisher(
    session: zenoh.Session, key: str, priority: zenoh.Priority = zenoh.Priority.DATA
) -> zenoh.Publisher:
    """View plane (DESIGN 12): telemetry at DATA, the camera at DATA_LOW; best effort, DROP,
    latest-only (a message that cannot go out is dropped, the next one replaces it)."""
    return session.declare_publisher(
        key,
        priority=priority,
        congestion_control=zenoh.CongestionControl.DROP,
        reliability=zenoh.Reliability.BEST_EFFORT,
    )


def data_publisher(session: zenoh.Session, key: str) -> zenoh.Publisher:
    """A remote driver's scans and odometry (robot <-> simulator): best effort, dropped under
    congestion, never blocking (the next message replaces a lost one)."""
    return session.declare_publisher(
        key,
        priority=zenoh.Priority.DATA,
        congestion_control=zenoh.CongestionControl.DROP,
        reliability=zenoh.Reliability.BEST_EFFORT,
    )


def serve_static(session: zenoh.Session, key: str, payload: bytes) -> zenoh.Queryable[None]:
    """A queryable that answers every query on ``key`` with the same payload (e.g. the map)."""

    def reply(query: zenoh.Query) -> None:
        try:
            query.reply(key, payload)
        except Exception as exc:  # a querier that went away must not kill the callback
            logging.getLogger("egc.transport").debug("reply on %s failed: %s", key, exc)

    return session.declare_queryable(key, reply)


def payload_bytes(sample: zenoh.Sample) -> bytes:
    """The raw payload of a sample (the strict decoders of ``messages`` take it from here)."""
    data: bytes = sample.payload.to_bytes()
    return data


def free_tcp_port(host: str = "127.0.0.1") -> int:
    """A TCP port that was free a moment ago (tests: one per robot so they run in parallel)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        port: int = s.getsockname()[1]
        return port


def free_port(proto: str = "tcp", host: str = "127.0.0.1") -> int:
    """A port free a moment ago for ``proto`` (``tcp``/``tls``: TCP; ``udp``: UDP *and* TCP,
    since a ``udp/`` endpoint of ours is a TCP and a UDP link on one port number)."""
    if proto != "udp":
        return free_tcp_port(host)
    for _ in range(100):
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.bind((host, 0))
            port: int = s.getsockname()[1]
            with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as t:
                try:
                    t.bind((host, port))
                except OSError:
                    continue
                return port
    raise OSError("no port free for both UDP and TCP")


def loopback_endpoint(port: int, proto: str = "tcp") -> str:
    return f"{proto}/127.0.0.1:{port}"
