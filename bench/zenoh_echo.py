"""A bare Zenoh echo: the baseline of bench/bench_link.py (issue 9).

A Zenoh peer in its own process, with the product's session configuration
(``open_session``: peer mode, no multicast scouting, the same lease), listening on one endpoint.
It subscribes to one key and republishes each payload at once on another key, with the QoS the
robot uses for base commands (``command_publisher``), cut or zero-padded to ``--reply-bytes``
(the size of a base command). Nothing else: no decoding, no lock, no logging on the path. So
publish -> echo receipt in the bench process measures the product's two Zenoh hops through
another Python process, without the robot's work between them.

    python bench/zenoh_echo.py --listen tcp/127.0.0.1:PORT --sub KEY --pub KEY [--reply-bytes N]

Prints ``ready`` on stdout once the subscriber and the publisher are declared; runs until
SIGTERM or SIGINT.
"""

from __future__ import annotations

import argparse

import zenoh
from egc_common.stop_flag import stop_on_signals
from egc_common.transport import ZenohOptions, command_publisher, open_session


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--listen", required=True, metavar="ENDPOINT")
    ap.add_argument("--sub", required=True, metavar="KEY", help="key to echo from")
    ap.add_argument("--pub", required=True, metavar="KEY", help="key to echo on")
    ap.add_argument(
        "--reply-bytes",
        type=int,
        default=None,
        metavar="N",
        help="cut or zero-pad each reply to N bytes (default: the payload as received)",
    )
    args = ap.parse_args()
    stop = stop_on_signals()

    session = open_session(ZenohOptions(listen=(args.listen,)))
    publisher = command_publisher(session, args.pub)
    n = args.reply_bytes

    def echo(sample: zenoh.Sample) -> None:
        payload = sample.payload.to_bytes()
        publisher.put(payload if n is None else payload[:n].ljust(n, b"\0"))

    subscriber = session.declare_subscriber(args.sub, echo)
    print("ready", flush=True)
    stop.wait()
    subscriber.undeclare()  # no sample arrives after this; then the publisher can go
    session.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
