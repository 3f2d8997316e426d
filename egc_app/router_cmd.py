"""``egc-teleop router --listen ENDPOINT [--zenoh-config FILE]``: a Zenoh router in our own
process, for sites without ``zenohd`` (DESIGN 10, pinned command line).

The router holds one Zenoh session in ``router`` mode, listening on every ``--listen`` endpoint
(``tcp/``, ``udp/``, ``tls/``, ...), until SIGINT or SIGTERM; robots and operators join it as
clients (``--zenoh-mode client --connect ENDPOINT``, or ``deploy/robot.json5`` /
``deploy/operator.json5``) and it routes their data, queries and liveliness tokens.

Without ``--zenoh-config`` it is configured the way ``egc_common.transport`` configures every
process of the project (multicast scouting off, the project's lease and keep-alive, the same
UDP link settings), so a hung client is dropped on the same schedule as between peers. With a
file (TLS, access control, see ``deploy/router-tls-acl.json5``) the file decides everything
except the mode, which is always ``router``, and the listen endpoints, which ``--listen``
replaces.

It prints one ready line on stderr once it listens (``router: listening on ...``), then one
line per client that comes or goes; a port in use or a bad configuration is one clear error
line and exit code 2.
"""

from __future__ import annotations

import argparse
import logging
import sys
from typing import Any

import zenoh
from egc_common.errors import UsageError
from egc_common.stop_flag import stop_on_signals
from egc_common.transport import ZenohOptions, build_config, open_config

log = logging.getLogger("egc.router")


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--listen",
        action="append",
        required=True,
        metavar="ENDPOINT",
        help="endpoint to listen on, e.g. tcp/0.0.0.0:7447 or udp/0.0.0.0:7447 (repeatable)",
    )
    parser.add_argument(
        "--zenoh-config",
        metavar="FILE",
        help="Zenoh JSON5 configuration (TLS, access control, ...); the mode is always router "
        "and --listen replaces the file's listen endpoints",
    )
    parser.add_argument(
        "--quiet", action="store_true", help="no line per client that comes or goes"
    )


def _describe(event: Any) -> str:
    transport = event.transport
    kind = "joined" if event.kind == zenoh.SampleKind.PUT else "left"
    return f"{str(transport.whatami).split('.')[-1].lower()} {transport.zid} {kind}"


def run(args: argparse.Namespace) -> int:
    logging.basicConfig(level=logging.INFO, format="router: %(message)s", stream=sys.stderr)
    options = ZenohOptions(mode=None, listen=tuple(args.listen), config_file=args.zenoh_config)
    config = build_config(options)
    try:
        config.insert_json5("mode", '"router"')
    except Exception as exc:  # pragma: no cover - the literal is valid
        raise UsageError(f"zenoh config mode=router rejected: {exc}") from None
    session = open_config(config)
    stop = stop_on_signals()  # not threading.Event: its set() can deadlock in a handler
    listener = None
    if not args.quiet:
        listener = session.info.declare_transport_events_listener(
            lambda event: log.info("%s", _describe(event))
        )
    log.info("listening on %s (zid %s)", ", ".join(args.listen), session.info.zid())
    try:
        stop.wait()
    finally:
        if listener is not None:
            listener.undeclare()
        session.close()
        log.info("stopped")
    return 0
