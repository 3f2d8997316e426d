"""``egc-teleop`` entry point (DESIGN 2, pinned): one console script with subcommands.

Subcommand modules are imported lazily so that ``egc-teleop filter`` does not pay for Zenoh or
Rerun. Each module exposes ``configure(parser)`` and ``run(args) -> int``.
"""

from __future__ import annotations

import importlib
import os
import sys
from collections.abc import Sequence

from egc_common.cli_args import CliArgumentParser
from egc_common.errors import UsageError

# name -> (module, one-line help)
SUBCOMMANDS: dict[str, tuple[str, str]] = {
    "filter": (
        "egc_robot.filter_cli",
        "filter JSON-lines commands against scan points (stdin -> stdout)",
    ),
    "robot": ("egc_app.robot_cmd", "run the robot process (commands in, filtered velocity out)"),
    "operator": ("egc_operator.cli", "run the operator process (joystick in, commands out)"),
    "sim": ("egc_sim.bridge", "run the simulated robot as a remote driver over Zenoh"),
    "demo": ("egc_app.demo", "simulated robot + scripted operator + operator view on loopback"),
    "episode": ("egc_app.episode", "run one headless episode (or a batch) and print JSON"),
    "bench": ("egc_app.bench", "run the benchmarks in bench/"),
    "link": (
        "egc_experiments.link_cli",
        "user-space link emulator: a TCP/UDP relay adding delay, jitter, loss and outages",
    ),
    "experiment": (
        "egc_experiments.experiment_cli",
        "run a grid of network-delay experiments; runs.jsonl, report.md and plots out",
    ),
    "robots": ("egc_app.robots_cmd", "list the robots on the Zenoh network (DESIGN 15)"),
    "router": ("egc_app.router_cmd", "an embedded Zenoh router, for sites without zenohd"),
    "replay": (
        "egc_app.replay_cmd",
        "replay a recorded robot log (.bag, ROS 2 bag, .db3, .mcap) through a filter",
    ),
}


DESCRIPTION = (
    "Teleoperation of mobile robots with a shared-autonomy safety layer: operator, robot, "
    "simulator, network lab and tools, one subcommand each (egc-teleop COMMAND --help)."
)


def build_parser() -> CliArgumentParser:
    parser = CliArgumentParser(prog="egc-teleop", description=DESCRIPTION)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=CliArgumentParser)
    sub.required = True
    for name, (_, help_text) in SUBCOMMANDS.items():
        sub.add_parser(name, help=help_text, description=help_text)
    return parser


def _leaving(code: int) -> int:
    """``code``, or exit with it at once when a Zenoh session given up on is still opening
    (``egc_common.transport.still_opening``: a normal exit would abort the process)."""
    transport = sys.modules.get("egc_common.transport")
    if transport is not None and transport.still_opening():
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    return code


def main(argv: Sequence[str] | None = None) -> int:
    args_list = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    # Parse only the subcommand name first, then let its module define the rest.
    if not args_list:  # no command is a bad argument: the list on stderr, exit 2
        parser.print_help(sys.stderr)
        return 2
    if args_list[0] in ("-h", "--help"):
        parser.parse_args(args_list)
        return 0
    name = args_list[0]
    if name not in SUBCOMMANDS:
        parser.error(f"unknown command {name!r} (choose from {', '.join(SUBCOMMANDS)})")
    module = importlib.import_module(SUBCOMMANDS[name][0])
    sub = CliArgumentParser(prog=f"egc-teleop {name}", description=SUBCOMMANDS[name][1])
    module.configure(sub)
    args = sub.parse_args(args_list[1:])
    try:
        return int(module.run(args) or 0)
    except UsageError as exc:
        print(f"egc-teleop {name}: error: {exc}", file=sys.stderr)
        return _leaving(2)
    except KeyboardInterrupt:
        return _leaving(130)
    except BrokenPipeError:  # `egc-teleop episode ... | head`: the reader has gone, quietly
        # Python flushes stdout again at exit; point it at /dev/null so that raises nothing.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141  # 128 + SIGPIPE, as a shell tool killed by it


if __name__ == "__main__":
    raise SystemExit(main())
