"""``egc-teleop robots [--connect ENDPOINT] [--zenoh-config FILE] [--json] [--wait S]``
(DESIGN 15, pinned): the robots on this Zenoh network.

For S seconds (default 2) it follows the robots' liveliness tokens (``egc/*/alive/robot``, with
history, so robots already there are seen at once) and asks each new one for its
``egc/<robot>/info``; then it prints the robots whose token is still there, one line each, or
one JSON object per line with ``--json``. A robot that did not answer its info query in time
is still listed (state ``?``): it is alive, it said nothing more. Exit 0 also when there are
none; a bad argument or an unreachable endpoint is one line and exit 2.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from typing import Any

from egc_common.errors import UsageError
from egc_common.robot_info import RobotInfo
from egc_common.transport import add_zenoh_arguments, open_session, options_from_args
from egc_operator.fleet_watch import FleetWatch


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="one JSON object per robot and line")
    parser.add_argument(
        "--wait",
        type=float,
        default=2.0,
        metavar="S",
        help="how long to look for robots, in seconds (default: 2)",
    )
    add_zenoh_arguments(parser, default_connect=("tcp/127.0.0.1:7447",))


def robot_line(robot: str, info: RobotInfo | None) -> str:
    if info is None:
        return f"{robot}  ?  (alive; no info reply)"
    return (
        f"{robot}  {info.state}  driver {info.driver}, profile {info.profile}, filter "
        f"{info.filter}, camera {info.camera}, operator {info.operator or '-'}"
    )


def robot_json(robot: str, info: RobotInfo | None) -> dict[str, Any]:
    if info is None:
        return {
            "robot": robot,
            "state": None,
            "driver": None,
            "profile": None,
            "filter": None,
            "camera": None,
            "operator": None,
        }
    return info.as_json()


def run(args: argparse.Namespace) -> int:
    logging.basicConfig(level=logging.WARNING, format="robots: %(message)s")
    if not 0 < args.wait <= 3600:
        raise UsageError("--wait must be within (0, 3600] seconds")
    session = open_session(options_from_args(args), give_up_s=args.wait + 5.0)
    try:
        watch = FleetWatch(session)
        time.sleep(args.wait)
        robots = watch.snapshot()
        for robot, why in watch.refused().items():
            print(f"robots: {robot}: info refused ({why})", file=sys.stderr)
        watch.close()
    finally:
        session.close()  # type: ignore[no-untyped-call]
    for robot, info in robots:
        if args.json:
            print(json.dumps(robot_json(robot, info)))
        else:
            print(robot_line(robot, info))
    if not robots and not args.json:
        print(f"no robots seen within {args.wait:g} s", file=sys.stderr)
    return 0
