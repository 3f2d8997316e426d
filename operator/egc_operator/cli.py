"""``egc-teleop operator``: joystick in, commands out (DESIGN 1, 4, 7; issue 4).

Exactly one source: ``--joystick /dev/input/eventN`` (evdev gamepad), ``--joystick-file FILE``
(the recorded-joystick CSV of ``egc_common.joystick_file``) or ``--script NAME`` (a CSV shipped
in ``egc_operator/scripts/``; ``--script list`` lists them). A file or script ends with the
deadman released and the process exits 0 (``--loop`` repeats it instead, until stopped; a file
whose rows are all at one instant holds that row).

Shared mode's filter: ``--filter NAME`` (one of ``egc``, ``ek-egc``, ``assist``, ``dwa``,
``cbf``) is sent with every command unless the source picks one (the gamepad's filter button, a file's
``filter`` column); without it the robot runs its own default. Direct mode (no filter) is
``--mode direct`` or the mode button, not ``--filter none``.

Via points (DESIGN 7, ``egc_operator.via_route``): ``--goal X,Y`` (repeatable, in order;
``--goal -2,3`` works) or ``--route FILE`` (one ``x,y`` or ``x y`` per line), in
``--goal-frame odom|map`` (default odom); the gamepad's buttons skip the active one or clear
them all.

Fleets (DESIGN 15, ``egc_operator.fleet_session``): without ``--robot`` the operator lists the
robots it sees and drives the first listed (``--first ID``: that one), and switches at run time:
the gamepad's switch buttons (the D-pad left/right, ``robot_next`` / ``robot_prev``), a joystick
file's ``robot_next`` / ``robot_prev`` columns, or a line typed on the terminal (``robot NAME``,
``robot N``, ``next``, ``prev``, ``list``). The old robot is released and holds; the new one
needs a centred stick. With ``--robot ID`` it drives that robot only, as before.

Configuration: ``--config FILE`` (TOML) and ``--set key=value``, tables

    [operator]  rate_hz, deadzone, gamepad ("xbox" | "ps" | "generic")
    [joystick]  forward_axis, forward_invert, turn_axis, turn_invert, deadman, mode_toggle,
                estop, reset, filter_cycle, via_next, via_clear, robot_next, robot_prev,
                robot_axis (evdev code names such as "BTN_TL", or numbers)
"""

from __future__ import annotations

import argparse
import logging
import os
import re
import socket
import sys
import threading
import time
from typing import Any

from egc_common import config as config_mod
from egc_common import keys
from egc_common.clock_id import monotonic_clock_id
from egc_common.errors import UsageError
from egc_common.joystick_file import JoystickFileError
from egc_common.messages import FILTER_NAMES, GOAL_FRAMES
from egc_common.stop_flag import StopRequest, stop_on_signals
from egc_common.transport import (
    DEFAULT_ENDPOINT,
    add_zenoh_arguments,
    open_session,
    options_from_args,
)

from egc_operator.command_source import (
    CommandSource,
    TrackSource,
    load_file,
    load_script,
    script_names,
)
from egc_operator.fleet_session import FleetSession, SessionStatus
from egc_operator.joystick_evdev import PRESETS, ButtonMap, EvdevJoystick, open_device
from egc_operator.operator_node import OperatorNode, View
from egc_operator.status_line import FleetLine, StatusLine
from egc_operator.terminal_input import TerminalInput
from egc_operator.via_route import Route, RouteError, route_from_options
from egc_operator.viewer_target import add_view_arguments

log = logging.getLogger("egc.operator")

MAX_DURATION_S = 1e7  # about 116 days
MAX_CLOCK_OFFSET_S = 1e6  # the test hook's shift: hours are plenty; nan or inf are no shift

OPERATOR_KEYS = ("rate_hz", "deadzone", "gamepad")
JOYSTICK_KEYS = tuple(ButtonMap.__dataclass_fields__)


def default_operator_id() -> str:
    host = re.sub(r"[^A-Za-z0-9_-]", "-", socket.gethostname())[:40] or "host"
    return f"{host}-{os.getpid()}"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--robot",
        default=None,
        metavar="ID",
        help="drive this robot only (default: list the robots seen, drive one, switch at run "
        "time with the gamepad's D-pad or typed commands)",
    )
    parser.add_argument(
        "--first",
        default=None,
        metavar="ID",
        help="without --robot: the robot to drive first, once it is seen (default: the first "
        "listed)",
    )
    parser.add_argument(
        "--operator-id", metavar="ID", help="this operator's id (default: HOST-PID)"
    )
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--joystick", metavar="DEVICE", help="evdev device, /dev/input/eventN")
    source.add_argument("--joystick-file", metavar="FILE", help="recorded joystick CSV")
    source.add_argument("--script", metavar="NAME", help="built-in script ('list' lists them)")
    parser.add_argument("--loop", action="store_true", help="repeat a file or script forever")
    parser.add_argument("--rate-hz", type=float, default=None, help="command rate (default: 50)")
    parser.add_argument(
        "--gamepad", choices=sorted(PRESETS), default=None, help="button preset (default: xbox)"
    )
    parser.add_argument("--deadzone", type=float, default=None, help="(default: 0.05)")
    parser.add_argument(
        "--mode",
        choices=("direct", "shared"),
        default="shared",
        help="initial mode of a gamepad; its mode button toggles it (default: shared)",
    )
    parser.add_argument(
        "--filter",
        choices=FILTER_NAMES,
        default=None,
        metavar="NAME",
        help="shared mode's filter, sent with every command unless the gamepad's filter button "
        "or a file's filter column picks one: egc, ek-egc, assist, dwa, cbf (default: the robot's)",
    )
    via = parser.add_argument_group("via points (sent to the robot, which goes to each in turn)")
    via.add_argument(
        "--goal",
        action="append",
        default=[],
        metavar="X,Y",
        help="a via point in metres (repeatable, in order; e.g. --goal -2,3 --goal 4,1)",
    )
    via.add_argument(
        "--route", metavar="FILE", help="via points from a file, one 'x,y' or 'x y' per line"
    )
    via.add_argument(
        "--goal-frame",
        choices=GOAL_FRAMES,
        default="odom",
        help="frame of the via points: odom (the base's odometry) or map (default: odom)",
    )
    parser.add_argument("--config", metavar="FILE", help="operator TOML configuration")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--duration", type=float, default=None, metavar="S", help="stop after S")
    parser.add_argument("--no-status", action="store_true", help="no terminal status line")
    parser.add_argument("--log-level", default="INFO", choices=("DEBUG", "INFO", "WARNING"))
    # Test hook: shift this process's clock to check clock sync across machines (issue 4).
    parser.add_argument("--clock-offset-s", type=float, default=0.0, help=argparse.SUPPRESS)
    add_view_arguments(parser, with_connect=False)
    parser.add_argument(
        "--connect",
        action=_ConnectAction,
        dest="connect",
        default=None,
        metavar="ENDPOINT|URL",
        help="a Zenoh endpoint to connect to (tcp/HOST:PORT, repeatable) or a running Rerun "
        "viewer to stream the view to (rerun+http://HOST:9876/proxy)",
    )
    add_zenoh_arguments(parser, default_connect=(DEFAULT_ENDPOINT,))


# A Zenoh locator is PROTOCOL/ADDRESS (tcp/10.0.0.2:7447, tls/host:7447, udp/..., quic/...);
# a viewer URL has a scheme (rerun+http://...). The two cannot be confused.
_ZENOH_LOCATOR = re.compile(r"^[a-z][a-z0-9-]*/[^/]")


class _ConnectAction(argparse.Action):
    """``--connect``: Zenoh endpoints (issue 4) and the viewer URL (issue 5) share one option."""

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: Any,
        option_string: str | None = None,
    ) -> None:
        value = str(values)
        if _ZENOH_LOCATOR.match(value):
            namespace.zenoh_connect = [*(getattr(namespace, "zenoh_connect", None) or []), value]
        elif "://" in value:
            if namespace.connect is not None:
                parser.error("--connect: only one viewer URL")
            namespace.connect = value
        else:
            parser.error(
                f"--connect {value!r}: expected a Zenoh endpoint like tcp/HOST:7447 or a viewer "
                "URL like rerun+http://HOST:9876/proxy"
            )


def _number(table: dict[str, Any], key: str, default: float) -> float:
    value = table.get(key, default)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise UsageError(f"config key {key} must be a number, got {value!r}")
    return float(value)


def _open_view(args: argparse.Namespace, robot_id: str | None) -> View | None:
    """The operator view (``egc_operator.view.open_view``); None with ``--no-view``, without
    loading the view module: rerun and pyarrow cost an operator ~1 s of a core to import and
    ~60 MB it never uses then (issue 31)."""
    if args.no_view:
        print("egc-teleop: operator view disabled (--no-view)", file=sys.stderr)
        return None
    from egc_operator.view import open_view

    if robot_id is None:
        return open_view(args, "fleet", fleet=True)
    return open_view(args, robot_id)


def _open_source(args: argparse.Namespace, cfg: dict[str, Any]) -> CommandSource:
    op_cfg = config_mod.section(cfg, "operator", OPERATOR_KEYS)
    try:
        if args.joystick_file is not None:
            return TrackSource(load_file(args.joystick_file), loop=args.loop)
        if args.script is not None:
            return TrackSource(load_script(args.script), loop=args.loop)
        preset = args.gamepad or str(op_cfg.get("gamepad", "xbox"))
        if preset not in PRESETS:
            raise UsageError(f"unknown gamepad preset {preset!r} ({', '.join(PRESETS)})")
        mapping = ButtonMap.from_table(
            config_mod.section(cfg, "joystick", JOYSTICK_KEYS), PRESETS[preset]
        )
        deadzone = args.deadzone if args.deadzone is not None else _number(op_cfg, "deadzone", 0.05)
        if not 0.0 <= deadzone < 1.0:
            raise UsageError("--deadzone must be in [0, 1)")
        path = args.joystick
        return EvdevJoystick(
            open_device(path, mapping),
            mapping,
            deadzone=deadzone,
            mode=args.mode,
            reopen=lambda: open_device(path, mapping),
            filter=args.filter,
        )
    except (JoystickFileError, ValueError) as exc:
        raise UsageError(str(exc)) from None


def _route(args: argparse.Namespace) -> Route | None:
    """The via points of --goal / --route in --goal-frame; None when there are none."""
    try:
        route = route_from_options(args.goal, args.route, args.goal_frame)
    except RouteError as exc:
        raise UsageError(str(exc)) from None
    return route if route.points else None


def check_arguments_alone(args: argparse.Namespace) -> None:
    """The checks of the arguments on their own (nothing read, opened or connected), raising
    UsageError: ``run`` makes them once it has read its configuration and via points, before
    it opens a joystick, a view or a session; ``python -m egc_app.parse_check`` makes them for
    the command lines in the documentation."""
    try:
        if args.robot is not None:
            keys.validate_id(args.robot)
        if args.first is not None:
            keys.validate_id(args.first, "--first robot id")
        if args.operator_id:
            keys.validate_id(args.operator_id, "operator id")
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    if args.robot is not None and args.first is not None:
        raise UsageError("--first is for an operator without --robot (which drives one robot)")
    if args.rate_hz is not None and not 1.0 <= args.rate_hz <= 1000.0:
        raise UsageError("--rate-hz must be within [1, 1000]")
    if args.duration is not None and not 0 < args.duration <= MAX_DURATION_S:
        # nan and inf too: a timer cannot wait that long (a traceback in its thread)
        raise UsageError(f"--duration must be positive, at most {MAX_DURATION_S:g} s")
    if not abs(args.clock_offset_s) <= MAX_CLOCK_OFFSET_S:  # nan too
        raise UsageError(
            f"--clock-offset-s must be a number of seconds within +-{MAX_CLOCK_OFFSET_S:g}, "
            f"got {args.clock_offset_s}"
        )
    if args.filter == "none":
        raise UsageError(
            "--filter none: 'none' is direct mode, chosen with --mode direct or the gamepad's "
            "mode button (a joystick file's mode column); --filter picks shared mode's filter"
        )
    if args.robot is None and (args.goal or args.route):
        raise UsageError(
            "--goal and --route need --robot: via points belong to one robot, and an operator "
            "without --robot may switch between several"
        )


def run(args: argparse.Namespace) -> int:
    logging.basicConfig(level=args.log_level, format="operator: %(message)s", stream=sys.stderr)
    if args.script == "list":
        print("\n".join(script_names()))
        return 0
    try:
        # --robot, --first and --operator-id are checked with the rest (check_arguments_alone)
        operator_id = args.operator_id or keys.validate_id(default_operator_id(), "operator id")
        cfg = config_mod.load(args.config, args.set, ("operator", "joystick"))
        op_cfg = config_mod.section(cfg, "operator", OPERATOR_KEYS)
    except ValueError as exc:  # includes ConfigError
        raise UsageError(str(exc)) from None
    route = _route(args)  # a via point that is no number, or a --route file that can't be read
    check_arguments_alone(args)
    robot_id: str | None = args.robot
    first: str | None = args.first
    rate_hz = args.rate_hz if args.rate_hz is not None else _number(op_cfg, "rate_hz", 50.0)
    if not 1.0 <= rate_hz <= 1000.0:
        raise UsageError("[operator] rate_hz must be within [1, 1000]")
    source = _open_source(args, cfg)
    # The view first: a --save file that cannot be written or a --serve-web port in use is a
    # usage error (exit 2) before anything connects or drives.
    try:
        view = _open_view(args, robot_id)
    except BaseException:
        source.close()
        raise
    try:
        session = open_session(options_from_args(args), give_up_s=args.duration)
    except BaseException:
        if view is not None:
            view.close()
        source.close()
        raise
    stop = stop_on_signals()  # not threading.Event: its set() can deadlock in a handler
    if args.duration is not None:
        timer = threading.Timer(args.duration, stop.set)
        timer.daemon = True
        timer.start()
    offset_ns = round(args.clock_offset_s * 1e9)

    def local_clock() -> int:
        return time.monotonic_ns() + offset_ns

    clock_id = monotonic_clock_id() if offset_ns == 0 else None
    if robot_id is None:
        return _run_fleet(
            args, session, source, view, stop, operator_id, first, rate_hz, local_clock, clock_id
        )
    node = OperatorNode(
        session,
        robot_id,
        operator_id,
        source,
        rate_hz=rate_hz,
        local_clock=local_clock,
        clock_id=clock_id,
        view=view,
        status=None if args.no_status else StatusLine(sys.stdout),
        route=route,
        filter_default=args.filter,
    )
    log.info("operator %r driving robot %r at %.0f Hz", operator_id, robot_id, rate_hz)
    if route is not None:
        log.info("via points: %d in %s", len(route.points), route.frame)
    try:
        node.run(stop)
    finally:
        node.close()
        source.close()
        session.close()
        log.info("stopped after %d commands", node.published)
    return 0


def _run_fleet(
    args: argparse.Namespace,
    session: Any,
    source: CommandSource,
    view: View | None,
    stop: StopRequest,
    operator_id: str,
    first: str | None,
    rate_hz: float,
    local_clock: Any,
    clock_id: str | None,
) -> int:
    """Without --robot: the fleet session (DESIGN 15, ``egc_operator.fleet_session``)."""
    fleet_line: list[Any] = []  # the session's, once it exists (the status line asks for it)

    def line() -> FleetLine | None:
        return fleet_line[0]() if fleet_line else None

    status = None if args.no_status else SessionStatus(sys.stdout, fleet=line)

    def make_node(robot: str, node_source: CommandSource, robot_view: View | None) -> OperatorNode:
        return OperatorNode(
            session,
            robot,
            operator_id,
            node_source,
            rate_hz=rate_hz,
            local_clock=local_clock,
            clock_id=clock_id,
            view=robot_view,
            status=status,
            filter_default=args.filter,
        )

    fleet = FleetSession(
        session,
        operator_id,
        source,
        make_node,
        clock=local_clock,
        status=status,
        view=view,  # type: ignore[arg-type]
        first=first,
    )
    fleet_line.append(fleet.fleet_line)
    log.info("operator %r: looking for robots (%.0f Hz)", operator_id, rate_hz)
    typing = None
    if TerminalInput.wanted(sys.stdin):
        typing = TerminalInput(sys.stdin, fleet.typed)
        typing.start()
    try:
        fleet.run(stop)
    finally:
        if typing is not None:
            typing.stop()
        if status is not None:
            status.finish()
        if view is not None:
            view.close()
        source.close()
        session.close()
        if fleet.switches:
            ms = sorted(s.ms for s in fleet.switches)
            log.info(
                "switches: %d, press to first accepted command p50 %.1f ms, max %.1f ms",
                len(ms),
                ms[len(ms) // 2],
                ms[-1],
            )
        log.info("stopped after %d commands", fleet.published)
    return 0
