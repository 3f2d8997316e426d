"""``egc-teleop link``: the user-space link emulator (DESIGN 10, pinned command line).

    egc-teleop link --listen ENDPOINT --connect ENDPOINT [--up SPEC] [--down SPEC] [--seed N]
                    [--scenario FILE] [--stats FILE.json] [--duration S] [--quiet]

Prints a ready line on stderr once listening, and per-direction counts when it stops (SIGINT,
SIGTERM or ``--duration``; exit 0): forwarded, dropped, delay percentiles, in flight (held by
the relay when it stopped or the connection closed, never delivered) and send errors (sends the
system refused, e.g. ECONNREFUSED from a target with nothing on its UDP port, or no route);
``--stats`` writes the same as JSON (``in_flight`` and ``send_errors`` in each direction, and
``send_errors`` at the top level by direction). Bad input, ``--stats`` included, gives one line
on stderr and exit 2 before anything runs.

The relay makes exactly one connection to the target per client connection, and none at
start-up (``relay`` module docstring: a probe took a single-client target's one place). So a
target that is not there is not a start-up error: the first client's connection is closed, one
line on stderr says why (``cannot connect to ENDPOINT (Connection refused)``; printed even with
``--quiet``, once per streak of refusals), and the stop summary and ``--stats``
(``connect_failures``) count every connection that could not reach it. A host that does not
resolve is still refused at start-up (exit 2).

Our ``udp/`` transport is two links on one port number (``egc_common.transport``): best-effort
datagrams on UDP and Zenoh's reliable control traffic on TCP. So a ``udp/`` relay also relays
TCP between the same port numbers (the *companion*), with the same delay, jitter, rate and
outages, on the same clock, but without loss or reordering (TCP retransmits what a lossy path
drops: only the delay remains). ``--udp-only`` turns the companion off. When nothing accepts
TCP at the target yet (a relay started before the robot), the companion closes the client's
tries (Zenoh retries; the first is one line on stderr, ``link: tcp connection N: cannot
connect ...``) and relays each one once the target accepts it.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import errno
import gc
import json
import signal
import sys
import time
from pathlib import Path

from egc_common.cli_args import check_writable
from egc_common.errors import UsageError

from egc_experiments.link_model import Schedule, SpecError, load_scenario, parse_spec
from egc_experiments.relay import (
    Endpoint,
    EndpointError,
    Relay,
    check_resolvable,
    new_event_loop,
    parse_endpoint,
)

SPEC_HELP = (
    "comma-separated: delay=MS, jitter=MS (standard deviation), dist=normal|uniform|pareto, "
    "loss=PERCENT and burst=N (Gilbert-Elliott mean burst length; udp/ only), rate=KBITPS, "
    "outage=START_S+DURATION_S (seconds after the relay started; repeatable), reorder=1 "
    "(udp/ only). Empty: a perfect link"
)


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--listen",
        required=True,
        metavar="ENDPOINT",
        help="operator side, tcp/HOST:PORT or udp/HOST:PORT (port 0: any free port)",
    )
    parser.add_argument(
        "--connect",
        required=True,
        metavar="ENDPOINT",
        help="robot side, same protocol as --listen, e.g. tcp/127.0.0.1:7447",
    )
    parser.add_argument("--up", default="", metavar="SPEC", help=f"operator -> robot: {SPEC_HELP}")
    parser.add_argument("--down", default="", metavar="SPEC", help="robot -> operator, as --up")
    parser.add_argument("--seed", type=int, default=0, metavar="N", help="seed (default 0)")
    parser.add_argument(
        "--scenario",
        metavar="FILE",
        help="TOML file of timed phases ([[phase]] start_s=, up=, down= or both=) or a trace "
        '(trace = "FILE.csv" with columns t_s,delay_ms,loss); replaces --up/--down',
    )
    parser.add_argument("--stats", metavar="FILE.json", help="write the final counts as JSON")
    parser.add_argument("--duration", type=float, metavar="S", help="stop after S seconds")
    parser.add_argument(
        "--quiet",
        action="store_true",
        help="no per-connection log lines (a target that refuses is still reported, once per "
        "streak of refusals)",
    )
    parser.add_argument(
        "--udp-only",
        action="store_true",
        help="udp/: do not also relay TCP on the same ports (the reliable half of our udp/ "
        "transport, see the module docstring)",
    )


def _endpoint(option: str, text: str) -> Endpoint:
    try:
        return parse_endpoint(text)
    except EndpointError as exc:
        raise UsageError(f"{option}: {exc}") from None


def link_schedules(up: str, down: str, scenario: str | None) -> tuple[Schedule, Schedule]:
    """The up and down schedules of ``--up``/``--down`` SPECs or a ``--scenario`` file (also
    the demo's, checked before it starts anything); a bad one is a UsageError naming it."""
    if scenario is not None:
        if up or down:
            raise UsageError("--scenario gives both directions; leave out --up and --down")
        try:
            return load_scenario(scenario)
        except SpecError as exc:
            raise UsageError(f"--scenario: {exc}") from None
    schedules = []
    for option, text in (("--up", up), ("--down", down)):
        try:
            schedules.append(Schedule.constant(parse_spec(text)))
        except SpecError as exc:
            raise UsageError(f"{option} {text!r}: {exc}") from None
    return schedules[0], schedules[1]


EPHEMERAL_TRIES = 20


def _reason(exc: OSError) -> str:
    return exc.strerror or str(exc) or type(exc).__name__


def build_relay(args: argparse.Namespace) -> Relay:
    """Check every input (raising ``UsageError``) and build the relay, not yet started."""
    listen = _endpoint("--listen", args.listen)
    connect = _endpoint("--connect", args.connect)
    if listen.proto != connect.proto:
        raise UsageError(
            f"--listen {listen} and --connect {connect} must use the same protocol (tcp or udp)"
        )
    if connect.port == 0:
        raise UsageError(f"--connect {connect}: port 0 is not a target")
    if args.duration is not None and not args.duration > 0:
        raise UsageError(f"--duration must be > 0 seconds, got {args.duration}")
    if args.stats is not None:  # a directory or an unwritable path: now, not after the run
        check_writable(args.stats, "--stats")
    up, down = link_schedules(args.up, args.down, args.scenario)
    log = (lambda line: None) if args.quiet else None
    try:
        relay = Relay(listen, connect, up, down, seed=args.seed, log=log)
    except (SpecError, EndpointError) as exc:
        raise UsageError(str(exc)) from None
    try:  # resolve only: no connection before a client's (module docstring)
        check_resolvable(connect)
    except OSError as exc:
        raise UsageError(f"cannot resolve --connect {connect}: {_reason(exc)}") from None
    return relay


async def start_pair(relay: Relay, args: argparse.Namespace) -> tuple[Endpoint, Relay | None, str]:
    """Start ``relay`` and, beside a ``udp/`` one, its TCP companion on the same port number.

    With port 0 the kernel picks a free UDP port, whose number may be taken for TCP: CI run
    136 failed so, with another suite beside it. Then both close and another port is tried
    (``EPHEMERAL_TRIES`` in all); a port the user named is reported at once."""
    for attempt in range(1, EPHEMERAL_TRIES + 1):
        try:
            bound = await relay.start()
        except OSError as exc:
            raise UsageError(f"cannot listen on {relay.listen}: {_reason(exc)}") from None
        companion, note = _companion(relay, args, bound.port)
        if companion is None:
            return bound, None, note
        try:
            await companion.start()
        except OSError as exc:
            await relay.close()
            ephemeral = relay.listen.port == 0 and exc.errno == errno.EADDRINUSE
            if ephemeral and attempt < EPHEMERAL_TRIES:
                continue
            raise UsageError(
                f"cannot listen on {companion.listen} (the TCP half of a udp/ link; "
                f"--udp-only relays UDP alone): {_reason(exc)}"
            ) from None
        companion.t0 = relay.t0  # one clock for outages and phases in both
        return bound, companion, note
    raise AssertionError("unreachable")  # the last attempt returns or raises


async def _serve(relay: Relay, args: argparse.Namespace, companions: list[Relay]) -> float:
    bound, companion, note = await start_pair(relay, args)
    if companion is not None:
        companions.append(companion)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    gc.collect()
    gc.freeze()  # keep collections short while relaying
    print(
        f"link: listening on {bound} -> {relay.connect} "
        f"{note}"
        f"(up: {relay.up.describe()}, down: {relay.down.describe()}, seed {relay.seed}; "
        f"t0 {relay.t0:.6f} on CLOCK_MONOTONIC: outages and phases count from it)",
        file=sys.stderr,
        flush=True,
    )
    started = time.monotonic()
    with contextlib.suppress(TimeoutError):
        await asyncio.wait_for(stop.wait(), args.duration)
    elapsed = time.monotonic() - started
    for companion in companions:
        await companion.close()
    await relay.close()
    return elapsed


def _companion(relay: Relay, args: argparse.Namespace, port: int) -> tuple[Relay | None, str]:
    """The TCP relay beside a ``udp/`` one (module docstring), or None and why not."""
    if relay.listen.proto != "udp":
        return None, ""
    if args.udp_only:
        return None, "UDP only "
    target = Endpoint("tcp", relay.connect.host, relay.connect.port)
    log = (lambda line: None) if args.quiet else None
    return Relay(
        Endpoint("tcp", relay.listen.host, port),
        target,
        relay.up.without_loss(),
        relay.down.without_loss(),
        seed=relay.seed,
        log=log,
        label="tcp connection",
    ), "and tcp (control link, no loss) "


def _connections(relay: Relay) -> str:
    text = f"{relay.connections} connection(s)"
    if relay.connect_failures:
        text += f", {relay.connect_failures} could not reach {relay.connect}"
    return text


def run(args: argparse.Namespace) -> int:
    relay = build_relay(args)
    companions: list[Relay] = []
    with asyncio.Runner(loop_factory=new_event_loop) as runner:
        elapsed = runner.run(_serve(relay, args, companions))
    stats = relay.stats()
    lines = [f"link: stopped after {elapsed:.1f} s, {_connections(relay)}"]
    lines += [f"link: {s.line(name, elapsed)}" for name, s in stats.items()]
    for companion in companions:
        lines.append(f"link: tcp: {_connections(companion)}")
        lines += [f"link: tcp {s.line(name, elapsed)}" for name, s in companion.stats().items()]
    print("\n".join(lines), file=sys.stderr, flush=True)
    if args.stats:
        report = {
            "listen": str(relay.listen),
            "connect": str(relay.connect),
            "seed": relay.seed,
            "duration_s": elapsed,
            "connections": relay.connections,
            "connect_failures": relay.connect_failures,
            **{name: s.to_dict() for name, s in stats.items()},
            "send_errors": {name: r.send_errors for name, r in relay.recorders.items()},
        }
        for companion in companions:
            report["tcp"] = {
                "connections": companion.connections,
                "connect_failures": companion.connect_failures,
                **{name: s.to_dict() for name, s in companion.stats().items()},
            }
        try:
            Path(args.stats).write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
        except OSError as exc:
            print(f"link: cannot write --stats {args.stats}: {_reason(exc)}", file=sys.stderr)
            return 1
    return 0
