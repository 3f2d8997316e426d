"""``egc-teleop replay LOG``: a recorded robot log through a filter of the family (DESIGN 11).

    egc-teleop replay LOG [--filter NAME] [--profile NAME|FILE.toml] [--scan-topic T] [--cmd-topic T]
                          [--cmd-timeout-s S] [--record FILE.rrd] [--summary FILE.json]

The arguments and their wiring only (DESIGN 2): the replay is ``egc_experiments.log_replay``
(which logs, which topics, damaged storage, stale commands, the summary's keys), the Rerun
recording ``egc_experiments.replay_recording``. This module prints the summary JSON on stdout
(and writes it to ``--summary``); a log that cannot be replayed, like a bad argument, is one
line on stderr and exit code 2.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path

from egc_common.cli_args import PROFILE_HELP, check_writable
from egc_common.errors import UsageError
from egc_common.profiles import get_profile
from egc_experiments.log_replay import log_file_in, replay
from egc_robot.pipeline import FILTERS
from egc_robot.replay_core import COMMAND_MAX_AGE_S, Replayer


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "log", metavar="LOG", help="ROS 1 .bag, ROS 2 bag directory, .db3 or .mcap file"
    )
    parser.add_argument(
        "--filter",
        default="egc",
        choices=FILTERS,
        metavar="NAME",
        help=f"filter to replay: {', '.join(FILTERS)} (default: egc)",
    )
    parser.add_argument(
        "--profile",
        default="pioneer3dx",
        metavar="NAME|FILE",
        help=f"{PROFILE_HELP} (default: pioneer3dx)",
    )
    parser.add_argument(
        "--scan-topic",
        metavar="T",
        help="LaserScan topic (default: the log's only one, or /scan)",
    )
    parser.add_argument(
        "--cmd-topic",
        metavar="T",
        help="Twist, TwistStamped or Odometry topic giving the commanded velocity (default: "
        "/cmd_vel or the log's only Twist topic, else its odometry differentiated)",
    )
    parser.add_argument(
        "--cmd-timeout-s",
        type=_timeout_s,
        default=COMMAND_MAX_AGE_S,
        metavar="S",
        help="a Twist is in effect this long after it was received, as a base stops when "
        f"cmd_vel falls silent; later scans have no command (default: {COMMAND_MAX_AGE_S}; "
        "'inf' holds each until the next)",
    )
    parser.add_argument("--record", metavar="FILE.rrd", help="save a Rerun recording")
    parser.add_argument("--summary", metavar="FILE.json", help="also write the summary here")


def _timeout_s(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not value > 0.0:
        raise argparse.ArgumentTypeError(f"{text!r} is not a time in seconds above 0")
    return value


def run(args: argparse.Namespace) -> int:
    try:
        profile = get_profile(args.profile)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    try:
        replayer = Replayer.for_filter(args.filter, profile)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    path = Path(args.log)
    if not path.exists():
        raise UsageError(f"{path}: no such file or directory")
    path = log_file_in(path)
    for option, out in (("--record", args.record), ("--summary", args.summary)):
        if out is not None and not Path(out).resolve().parent.is_dir():
            raise UsageError(f"{out}: its folder does not exist")
        if out is not None:  # a directory, /proc: one line now, not a traceback after the run
            check_writable(out, option)
    summary = replay(
        path,
        replayer,
        args.scan_topic,
        args.cmd_topic,
        args.record,
        cmd_timeout_s=args.cmd_timeout_s,
    )
    text = json.dumps(summary, indent=2)
    if args.summary:
        Path(args.summary).write_text(text + "\n")
    try:
        print(text, flush=True)
    except BrokenPipeError:  # the reader left (``| head``): no traceback, no second error at exit
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    if args.record:
        print(
            f"recording saved: {args.record} (open it with: rerun {args.record})", file=sys.stderr
        )
    return 0
