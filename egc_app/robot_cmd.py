"""``egc-teleop robot``: the robot process (DESIGN 1, 7, 8; issue 4).

Wires the pure ``RobotController`` to a driver and a Zenoh session and runs the
``RobotNode`` loop until SIGINT/SIGTERM. Drivers: ``sim`` runs sim_robot in this process
(``SimDriver`` below; egc_robot may not import egc_sim, the entry point may), ``zenoh`` talks
to a base-and-sensor process over ``scan`` / ``base/cmd`` / ``base/odom`` (``egc-teleop sim``),
``ros2`` makes this process the ROS 2 node ``egc_teleop`` on a ROS 2 robot's ``/scan``, ``/odom``
and ``/cmd_vel`` (``egc_robot.ros2_driver``, DESIGN 11).

Configuration: defaults < ``--config FILE`` (TOML) < ``--set section.key=value`` < explicit
flags. Tables and keys (units in the names):

    [robot]    rate_hz, telemetry_scan_decimation, telemetry_hz, downlink_kbps (a number of
               kbit/s or "auto"; DESIGN 12; flags --telemetry-hz, --downlink-kbps)
    [safety]   max_command_age_s (direct mode), max_command_age_filtered_s, command_timeout_s,
               scan_timeout_s, release_timeout_s, centre_tolerance, require_clock_sync
    [link]     link_aware, resume_window_s, reaction_time_s, blind_time_direct_s,
               blind_time_filtered_s, latency_turn_cap (DESIGN 8 short-gap resume, DESIGN 9
               latency governor; latency_turn_cap = false caps the speed alone)
    [pipeline] horizon_s, gamma_v, gamma_w, no_return_is_free
    [sim]      scan_hz, beams, seed
    [dwa], [assist], [cbf]  the filters' parameters (DESIGN 6, 13; defaults from the profile:
               ``DwaParams``, ``AssistParams``, ``CbfParams`` say why each default is what it is)
    [ros2]     scan, odom, cmd, cmd_type, namespace, laser_pose ("X,Y,YAW" or [x, y, yaw]),
               laser_upside_down (flags --ros-scan ... --laser-upside-down override them)
    [camera]   source ("sim", "ros2:TOPIC", "none"), size ("WxH"), fps, codec ("h264", "jpeg")
               (DESIGN 12; flags --camera, --camera-size, --camera-fps, --camera-codec)

Command sources and locks (DESIGN 14; ``egc_robot.source_config`` documents the keys):
``[[source]]`` tables (``name``, ``kind`` operator | zenoh | ros2, ``priority``, ``timeout_s``;
``topic`` and ``cmd_type`` for ros2), ``[[lock]]`` tables (``name``, ``priority``,
``timeout_s``; ``kind = "ros2"`` and ``topic`` for a ``std_msgs/Bool`` topic) and ``[[operator]]``
tables (``id``, ``priority``). Without ``[[source]]`` tables the robot is as before: one operator
source. ``ros2`` sources and locks need ``--driver ros2`` (docs/ros2-sources.md).

``pipeline.no_return_is_free`` unset (the default): each scan's sensor says whether a beam with no
return means free. The simulator's lidar says so, the ROS 2 driver says so for REP 117 scans
(``+inf`` means nothing within range_max; a scan without any information is never delivered,
``egc_robot.ros2_core``), an ``egc/<robot>/scan`` message carries the flag. Set it to force one
reading for every scan.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import gc
import json
import logging
import math
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from egc_common import config as config_mod
from egc_common import keys
from egc_common.cli_args import PROFILE_HELP, check_writable
from egc_common.clock_id import monotonic_clock_id
from egc_common.errors import UsageError
from egc_common.joystick import JoystickMapping
from egc_common.messages import BaseCommand
from egc_common.profiles import get_profile
from egc_common.robot_info import RobotInfo
from egc_common.stop_flag import stop_on_signals
from egc_common.transport import (
    DEFAULT_ENDPOINT,
    LEASE_MS,
    add_zenoh_arguments,
    open_session,
    options_from_args,
    serve_static,
)
from egc_common.view_budget import BudgetConfig
from egc_robot.camera_config import CAMERA_KEYS, CameraConfig, camera_config
from egc_robot.controller import ControllerConfig, RobotController
from egc_robot.drivers import Driver, SensorUpdate
from egc_robot.filters.assist import AssistParams
from egc_robot.filters.cbf import CbfParams
from egc_robot.filters.dwa import DwaParams
from egc_robot.info_server import InfoServer
from egc_robot.pipeline import FILTERS, PipelineConfig
from egc_robot.ros2_core import CMD_TYPES, ROS2_KEYS, Ros2Settings, ros2_settings
from egc_robot.run_stats import RunStats
from egc_robot.safety import MAX_CONTROL_PERIOD_S, SweepParams
from egc_robot.source_config import mux_config, operator_priorities
from egc_robot.source_mux import MuxConfig
from egc_robot.zenoh_node import Recorder, RobotNode

if TYPE_CHECKING:  # imported where a camera opens: a robot without one never loads PIL
    from egc_robot.camera_stream import CameraStreamer

log = logging.getLogger("egc.robot")

SECTIONS: dict[str, tuple[str, ...]] = {
    "robot": ("rate_hz", "telemetry_scan_decimation", "telemetry_hz", "downlink_kbps"),
    "safety": (
        "max_command_age_s",
        "max_command_age_filtered_s",
        "command_timeout_s",
        "scan_timeout_s",
        "release_timeout_s",
        "centre_tolerance",
        "require_clock_sync",
    ),
    "link": (
        "link_aware",
        "resume_window_s",
        "reaction_time_s",
        "blind_time_direct_s",
        "blind_time_filtered_s",
        "latency_turn_cap",
    ),
    "pipeline": ("horizon_s", "gamma_v", "gamma_w", "no_return_is_free"),
    "sim": ("scan_hz", "beams", "seed"),
    "ros2": ROS2_KEYS,
    "camera": CAMERA_KEYS,
}
# [dwa], [assist] and [cbf] are checked by their params; [[source]], [[lock]], [[operator]]
# (DESIGN 14) by egc_robot.source_config.
ROBOT_TABLES = (*SECTIONS, "dwa", "assist", "cbf", "source", "lock", "operator")


class SimDriver:
    """sim_robot in this process, stepped in real time on every poll."""

    def __init__(self, rt: Any, map_server: Any = None, map_id: str | None = None) -> None:
        self._rt = rt
        self._map_server = map_server  # the queryable egc/<robot>/map, for the operator view
        self.map_id = map_id  # the map frame's id in egc/<robot>/info (DESIGN 15)

    def poll(self, now_ns: int) -> SensorUpdate:
        self._rt.advance(now_ns)
        scan = self._rt.scan_if_due(now_ns)
        return SensorUpdate(scan=scan, scan_rx_ns=now_ns, odometry=self._rt.odometry(now_ns))

    def send(self, command: BaseCommand) -> None:
        self._rt.set_command(command.linear_mps, command.angular_radps)

    def camera_source(self, width_px: int, height_px: int) -> Any:
        """``--camera sim``: a callable rendering the forward camera from the simulator's pose
        now (DESIGN 12), stamped with the robot's monotonic clock; for the camera's thread."""
        from egc_sim.camera import CameraModel, CameraRenderer

        renderer = CameraRenderer(self._rt.sim.world, CameraModel(width_px, height_px))

        def grab() -> tuple[Any, int]:
            stamp = time.monotonic_ns()
            return renderer.render(self._rt.sim.pose), stamp

        return grab

    def close(self) -> None:
        if self._map_server is not None:
            self._map_server.undeclare()


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--robot",
        default=keys.DEFAULT_ROBOT_ID,
        metavar="ID",
        help=f"robot id in the key expressions egc/ID/... (default: {keys.DEFAULT_ROBOT_ID})",
    )
    parser.add_argument(
        "--driver",
        choices=("sim", "zenoh", "ros2"),
        default="sim",
        help="sim: the simulator in this process; zenoh: a base-and-sensor process over "
        "scan, base/cmd, base/odom, e.g. 'egc-teleop sim'; ros2: a ROS 2 robot's LaserScan, "
        "Odometry and cmd_vel, this process being the node egc_teleop (default: sim)",
    )
    parser.add_argument(
        "--map", default="hallway", metavar="SPEC", help="world for --driver sim (default: hallway)"
    )
    parser.add_argument(
        "--profile",
        default="pioneer3dx",
        metavar="NAME|FILE",
        help=f"{PROFILE_HELP} (default: pioneer3dx)",
    )
    parser.add_argument(
        "--filter", choices=FILTERS, default="egc", help="filter of shared mode (default: egc)"
    )
    parser.add_argument("--rate-hz", type=float, default=None, help="control rate (default: 20)")
    parser.add_argument(
        "--no-link-aware",
        dest="link_aware",
        action="store_false",
        default=None,
        help="turn link-aware driving off (one max command age, no short-gap resume, no latency "
        "governor), for comparisons; same as --set link.link_aware=false",
    )
    parser.add_argument(
        "--telemetry-hz",
        type=float,
        default=None,
        metavar="HZ",
        help="telemetry rate to the operators (DESIGN 12; default: 20; the downlink budget may "
        "lower it to 5)",
    )
    parser.add_argument(
        "--downlink-kbps",
        default=None,
        metavar="N|auto",
        help="the view plane's budget in kbit/s (telemetry and camera), or auto: estimated from "
        "what the operator reports (DESIGN 12; default: auto)",
    )
    parser.add_argument("--start", metavar="X,Y,YAW", help="start pose for --driver sim")
    parser.add_argument("--config", metavar="FILE", help="robot TOML configuration")
    parser.add_argument(
        "--set", action="append", default=[], metavar="KEY=VALUE", help="override a config key"
    )
    parser.add_argument("--record", metavar="FILE.rrd", help="keep a Rerun black box")
    parser.add_argument(
        "--record-scan-every", type=int, default=1, metavar="N", help="black box: every Nth scan"
    )
    parser.add_argument("--summary", metavar="FILE.json", help="write run statistics at exit")
    parser.add_argument("--log-level", default="INFO", choices=("DEBUG", "INFO", "WARNING"))
    ros = parser.add_argument_group(
        "ROS 2 (--driver ros2; same keys in the config's [ros2] table; ROS_DOMAIN_ID and "
        "RMW_IMPLEMENTATION as ROS 2 reads them)"
    )
    ros.add_argument("--ros-scan", metavar="TOPIC", help="sensor_msgs/LaserScan (default: /scan)")
    ros.add_argument("--ros-odom", metavar="TOPIC", help="nav_msgs/Odometry (default: /odom)")
    ros.add_argument("--ros-cmd", metavar="TOPIC", help="velocity commands (default: /cmd_vel)")
    ros.add_argument(
        "--ros-cmd-type",
        choices=CMD_TYPES,
        default=None,
        help="geometry_msgs/Twist or TwistStamped (default: twist)",
    )
    ros.add_argument("--ros-namespace", metavar="NS", help="the node's namespace (default: none)")
    ros.add_argument(
        "--laser-pose",
        metavar="X,Y,YAW",
        help="the laser in the base frame, metres and radians (default: [ros2] laser_pose, else "
        "the profile's laser_pose, else 0,0,0)",
    )
    ros.add_argument(
        "--laser-upside-down",
        action="store_true",
        default=None,
        help="the laser is mounted upside down (mirrors its sweep)",
    )
    cam = parser.add_argument_group("camera (DESIGN 12; same keys in the config's [camera] table)")
    cam.add_argument(
        "--camera",
        metavar="SOURCE",
        help="sim (the simulator renders a forward camera; the default with --driver sim), "
        "ros2:TOPIC (sensor_msgs/Image or CompressedImage, with --driver ros2) or none "
        "(the default otherwise)",
    )
    cam.add_argument("--camera-size", metavar="WxH", help="largest picture sent (default 320x240)")
    cam.add_argument(
        "--camera-fps", type=float, metavar="N", help="most frames a second (default 10)"
    )
    cam.add_argument(
        "--camera-codec", choices=("h264", "jpeg"), default=None, help="(default: h264)"
    )
    add_zenoh_arguments(parser, default_listen=(DEFAULT_ENDPOINT,))


def _camera_config(args: argparse.Namespace, cfg: dict[str, Any]) -> CameraConfig:
    """``[camera]`` and the --camera flags, checked before anything opens (one line if bad)."""
    flags = {
        "source": args.camera,
        "size": args.camera_size,
        "fps": args.camera_fps,
        "codec": args.camera_codec,
    }
    try:
        return camera_config(config_mod.section(cfg, "camera", CAMERA_KEYS), flags, args.driver)
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def _open_camera(
    config: CameraConfig, robot: str, session: Any, driver: Driver
) -> tuple[CameraStreamer, Any] | None:
    """The camera stream on ``egc/<robot>/camera`` (DESIGN 12), started, and the liveliness
    subscriber that gives each new operator a keyframe at once; None for ``none``."""
    if not config.enabled:
        return None
    from egc_robot.camera_stream import (
        CameraStreamer,
        camera_publisher,
        keyframe_for_new_operators,
    )

    if isinstance(driver, SimDriver):
        source = driver.camera_source(config.width_px, config.height_px)
    else:
        source = driver.newest_image  # type: ignore[attr-defined]  # the Ros2Driver's
    publisher = camera_publisher(session, keys.camera(robot))
    streamer = CameraStreamer(source, publisher.put, config)
    viewers = keyframe_for_new_operators(session, robot, streamer)
    streamer.start()
    what = config.source if config.topic is None else f"ros2 topic {config.topic}"
    log.info(
        "camera: %s, up to %dx%d at %g frames/s, %s",
        what,
        config.width_px,
        config.height_px,
        config.max_fps,
        config.codec,
    )
    return streamer, viewers


def _close_camera(streamer: CameraStreamer | None, viewers: Any) -> None:
    if viewers is not None:
        viewers.undeclare()
    if streamer is not None:
        streamer.close()


def _number(table: dict[str, Any], key: str, default: float) -> float:
    value = table.get(key, default)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise UsageError(f"config key {key} must be a number, got {value!r}")
    if not math.isfinite(value) or abs(value) > 1e9:
        raise UsageError(
            f"config key {key} must be a finite number of sensible size, got {value!r}"
        )
    return float(value)


def _flag(table: dict[str, Any], key: str, default: bool) -> bool:
    value = table.get(key, default)
    if not isinstance(value, bool):
        raise UsageError(f"config key {key} must be true or false, got {value!r}")
    return value


def build_controller_config(args: argparse.Namespace, cfg: dict[str, Any]) -> ControllerConfig:
    try:
        robot = config_mod.section(cfg, "robot", SECTIONS["robot"])
        safety = config_mod.section(cfg, "safety", SECTIONS["safety"])
        link = config_mod.section(cfg, "link", SECTIONS["link"])
        pipe = config_mod.section(cfg, "pipeline", SECTIONS["pipeline"])
        # [ros2] is checked whatever the driver: a file that is wrong fails now, not on the
        # day the robot first runs on --driver ros2.
        ros2_settings(config_mod.section(cfg, "ros2", SECTIONS["ros2"]), {})
        profile = get_profile(args.profile)
        horizon = pipe.get("horizon_s")
        # Unset: each scan's sensor declares it (the simulator's lidar and the ROS 2 driver's
        # REP 117 scans do; an egc/<robot>/scan message carries the flag).
        free_setting = (
            None if "no_return_is_free" not in pipe else _flag(pipe, "no_return_is_free", False)
        )
        dwa_table = cfg.get("dwa", {})
        assist_table = cfg.get("assist", {})
        cbf_table = cfg.get("cbf", {})
        if not all(isinstance(t, dict) for t in (dwa_table, assist_table, cbf_table)):
            raise UsageError("[dwa], [assist] and [cbf] must be tables")

        def pipeline_config(free: bool) -> PipelineConfig:
            filter_tables = {"no_return_is_free": free}
            return PipelineConfig(
                profile=profile,
                mapping=JoystickMapping(
                    gamma_v=_number(pipe, "gamma_v", 1.0), gamma_w=_number(pipe, "gamma_w", 1.0)
                ),
                filter=args.filter,
                horizon_s=None if horizon is None else _number(pipe, "horizon_s", 0.0),
                no_return_is_free=free,
                # The sweep's one period at the command before braking: the loop's period
                # (cycles also run on each command and scan, never further apart than this).
                sweep=SweepParams(period_s=1.0 / rate_hz),
                dwa=DwaParams.from_mapping(filter_tables | dwa_table, profile),
                assist=AssistParams.from_mapping(filter_tables | assist_table, profile),
                # cbf's margin counts one control period at the command, as the sweep does.
                cbf=CbfParams.from_mapping(
                    filter_tables | {"period_s": 1.0 / rate_hz} | cbf_table, profile
                ),
            )

        rate_hz = args.rate_hz if args.rate_hz is not None else _number(robot, "rate_hz", 20.0)
        if not 1.0 / MAX_CONTROL_PERIOD_S <= rate_hz <= 1000.0:
            # Slower, the base lags its commands by more than the footprint sweep's margin.
            raise UsageError(
                f"--rate-hz must be within [{1.0 / MAX_CONTROL_PERIOD_S:g}, 1000], got {rate_hz!r}"
            )
        pipeline = pipeline_config(bool(free_setting))
        pipeline_if_free = pipeline_config(True) if free_setting is None else None
        defaults = ControllerConfig(pipeline)
        return ControllerConfig(
            pipeline=pipeline,
            pipeline_if_free=pipeline_if_free,
            max_command_age_s=_number(safety, "max_command_age_s", defaults.max_command_age_s),
            max_command_age_filtered_s=_number(
                safety, "max_command_age_filtered_s", defaults.max_command_age_filtered_s
            ),
            resume_window_s=_number(link, "resume_window_s", defaults.resume_window_s),
            link_aware=(
                _flag(link, "link_aware", defaults.link_aware)
                if getattr(args, "link_aware", None) is None
                else bool(args.link_aware)
            ),
            reaction_time_s=_number(link, "reaction_time_s", defaults.reaction_time_s),
            blind_time_direct_s=_number(link, "blind_time_direct_s", defaults.blind_time_direct_s),
            blind_time_filtered_s=_number(
                link, "blind_time_filtered_s", defaults.blind_time_filtered_s
            ),
            latency_turn_cap=_flag(link, "latency_turn_cap", defaults.latency_turn_cap),
            command_timeout_s=_number(safety, "command_timeout_s", defaults.command_timeout_s),
            scan_timeout_s=_number(safety, "scan_timeout_s", defaults.scan_timeout_s),
            release_timeout_s=_number(safety, "release_timeout_s", defaults.release_timeout_s),
            centre_tolerance=_number(safety, "centre_tolerance", defaults.centre_tolerance),
            require_clock_sync=_flag(safety, "require_clock_sync", False),
            telemetry_scan_decimation=int(
                _number(robot, "telemetry_scan_decimation", defaults.telemetry_scan_decimation)
            ),
            nominal_period_s=1.0 / rate_hz,
            sources=build_sources(args, cfg),
            operator_priorities=operator_priorities(cfg.get("operator")),
        )
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def build_sources(args: argparse.Namespace, cfg: dict[str, Any]) -> MuxConfig | None:
    """DESIGN 14: the ``[[source]]`` and ``[[lock]]`` tables (None without ``[[source]]``),
    checked against the driver: ``ros2`` ones need ``--driver ros2`` and may not listen on the
    topic this robot publishes its commands to (a loop)."""
    mux = mux_config(cfg.get("source"), cfg.get("lock"))
    if mux is None:
        return None
    topics = [(f"source {s.name}", s.topic) for s in mux.sources if s.topic is not None]
    topics += [(f"lock {lk.name}", lk.topic) for lk in mux.locks if lk.topic is not None]
    if topics and args.driver != "ros2":
        what = topics[0][0]
        raise ValueError(f"{what} is fed by the ROS 2 topic {topics[0][1]}: it needs --driver ros2")
    if topics:
        ros = _ros2_settings(args, cfg, need_rclpy=False)

        def resolved(topic: str) -> str:  # as the node in its namespace resolves it
            return topic if topic.startswith("/") else f"{ros.namespace.rstrip('/')}/{topic}"

        for what, topic in topics:
            if resolved(topic) == resolved(ros.cmd_topic):
                raise ValueError(
                    f"{what} listens on {topic}, where this robot publishes its own commands "
                    "(--ros-cmd): a loop; give the navigation stack's output another topic, "
                    "e.g. /cmd_vel_nav"
                )
    return mux


def build_budget_config(args: argparse.Namespace, cfg: dict[str, Any]) -> BudgetConfig:
    """DESIGN 12: ``--telemetry-hz`` / ``robot.telemetry_hz`` and ``--downlink-kbps`` /
    ``robot.downlink_kbps`` (kbit/s or "auto")."""
    try:
        robot = config_mod.section(cfg, "robot", SECTIONS["robot"])
    except config_mod.ConfigError as exc:
        raise UsageError(str(exc)) from None
    defaults = BudgetConfig()
    hz = args.telemetry_hz
    if hz is None:
        hz = _number(robot, "telemetry_hz", defaults.telemetry_hz)
    if not math.isfinite(hz) or not defaults.min_telemetry_hz <= hz <= 1000:
        raise UsageError(
            f"--telemetry-hz must be within [{defaults.min_telemetry_hz:g}, 1000], got {hz:g}"
        )
    raw = args.downlink_kbps if args.downlink_kbps is not None else robot.get("downlink_kbps")
    kbps: float | None = None
    if raw is not None and raw != "auto":
        try:
            kbps = float(raw) if not isinstance(raw, bool) else math.nan
        except (TypeError, ValueError):
            kbps = math.nan
        if not (math.isfinite(kbps) and 1.0 <= kbps <= 1e7):
            raise UsageError(
                f"--downlink-kbps must be auto or a number of kbit/s in [1, 10000000], got {raw!r}"
            )
    return BudgetConfig(downlink_kbps=kbps, telemetry_hz=hz, min_telemetry_hz=min(5.0, hz))


def _ros2_settings(
    args: argparse.Namespace, cfg: dict[str, Any], need_rclpy: bool = True
) -> Ros2Settings:
    """``--driver ros2``: settings from ``[ros2]`` and the flags, checked before anything opens;
    one line naming the extra if rclpy is missing."""
    from egc_robot.ros2_driver import require_rclpy

    flags = {
        "scan": args.ros_scan,
        "odom": args.ros_odom,
        "cmd": args.ros_cmd,
        "cmd_type": args.ros_cmd_type,
        "namespace": args.ros_namespace,
        "laser_pose": args.laser_pose,
        "laser_upside_down": args.laser_upside_down,
    }
    try:
        settings = ros2_settings(
            config_mod.section(cfg, "ros2", SECTIONS["ros2"]),
            flags,
            default_laser_pose=get_profile(args.profile).laser_pose,
        )
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    if need_rclpy:
        require_rclpy()
    return settings


def _open_driver(
    args: argparse.Namespace, cfg: dict[str, Any], session: Any, camera_topic: str | None = None
) -> Driver:
    if args.driver == "ros2":
        from egc_robot.ros2_driver import Ros2Driver

        settings = _ros2_settings(args, cfg)
        mux = build_sources(args, cfg)
        sources = () if mux is None else tuple(s for s in mux.sources if s.kind == "ros2")
        locks = () if mux is None else tuple(lk for lk in mux.locks if lk.topic is not None)
        try:
            footprint = get_profile(args.profile).footprint
            return Ros2Driver(
                settings,
                footprint_half_m=footprint,
                camera_topic=camera_topic,
                sources=sources,
                locks=locks,
            )
        except Exception as exc:  # rclpy's own errors (e.g. ROS_DOMAIN_ID out of range)
            raise UsageError(f"cannot start the ROS 2 node: {exc}") from None
    if args.driver == "zenoh":
        from egc_robot.zenoh_driver import ZenohDriver

        return ZenohDriver(session, args.robot, get_profile(args.profile).footprint)
    from egc_sim.bridge import RealTimeSim, open_simulator, parse_pose
    from egc_sim.grid_world import map_message, world_id

    try:
        sim_cfg = config_mod.section(cfg, "sim", SECTIONS["sim"])
    except config_mod.ConfigError as exc:
        raise UsageError(str(exc)) from None
    beams = sim_cfg.get("beams")
    sim = open_simulator(
        args.map,
        get_profile(args.profile),
        parse_pose(args.start),
        int(_number(sim_cfg, "seed", 0)),
        None if beams is None else int(beams),
    )
    scan_hz = _number(sim_cfg, "scan_hz", 20.0)
    world_map = map_message(sim.world, time.monotonic_ns()).encode()
    return SimDriver(
        RealTimeSim(sim, time.monotonic_ns(), 1.0 / scan_hz),
        serve_static(session, keys.world_map(args.robot), world_map),
        map_id=world_id(sim.world),
    )


def _open_recorder(args: argparse.Namespace) -> Recorder | None:
    if args.record is None:
        return None
    from egc_robot.blackbox import BlackBox

    check_writable(args.record, "--record")
    try:
        recorder: Recorder = BlackBox(
            args.record, args.robot, scan_decimation=args.record_scan_every
        )
    except (OSError, ValueError, RuntimeError) as exc:  # rerun's "Failed to create file"
        raise UsageError(f"cannot record to {args.record}: {exc}") from None
    return recorder


def resume_window_caveat(config: ControllerConfig, lease_ms: int | None) -> str | None:
    """Why ``resume_window_s`` cannot take effect in full, or None when it can.

    A gap longer than ``release_timeout_s``, or than the Zenoh lease (the operator's liveliness
    token goes with it), ends the operator's session, and a new one needs a centred stick
    (DESIGN 8) whatever the resume window says. ``lease_ms`` None: unknown (a config file).
    """
    if not config.link_aware:
        return None
    limits = [("safety.release_timeout_s", config.release_timeout_s)]
    if lease_ms is not None:
        limits.append(("the Zenoh lease (--lease-ms)", lease_ms / 1000.0))
    name, limit_s = min(limits, key=lambda item: item[1])
    if config.resume_window_s <= limit_s:
        return None
    return (
        f"link.resume_window_s {config.resume_window_s:g} s is longer than {name} "
        f"{limit_s:g} s: a link gap longer than {limit_s:g} s ends the operator's session and "
        "needs a centred stick; to resume after longer gaps raise safety.release_timeout_s and "
        "--lease-ms here and the operator's --lease-ms as well"
    )


@functools.cache
def _version() -> str:
    """The installed egc-teleop's version, looked up at the first info query, not at start-up
    (importing importlib.metadata was about a tenth of the robot's import time)."""
    import importlib.metadata

    try:
        return importlib.metadata.version("egc-teleop")
    except importlib.metadata.PackageNotFoundError:
        return "unknown"


def _describer(
    args: argparse.Namespace, controller: RobotController, map_id: str | None = None
) -> Any:
    """What ``egc/<robot>/info`` answers (DESIGN 15): fixed facts, plus the controller's state
    and operator read at the time of the query (two attribute reads: a snapshot may be one
    cycle old, never inconsistent enough to matter for a listing). ``map_id``: the map frame
    the driver's map poses are in, when it gives them (the simulator: its world's id)."""
    profile = get_profile(args.profile)
    footprint = tuple(profile.footprint.outline()[:-1])  # as given (DESIGN 14), open
    camera = str(getattr(args, "camera", None) or "none")

    def describe() -> RobotInfo:
        return RobotInfo(
            robot=args.robot,
            state=controller.state.value,
            driver=args.driver,
            profile=profile.name,
            filter=args.filter,
            camera=camera,
            version=_version(),
            footprint_m=footprint,
            operator=controller.operator,
            map=map_id,
        )

    return describe


def run(args: argparse.Namespace) -> int:
    logging.basicConfig(level=args.log_level, format="robot: %(message)s")
    try:
        keys.validate_id(args.robot)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    if args.record_scan_every < 1:
        raise UsageError("--record-scan-every must be >= 1")
    try:
        cfg = config_mod.load(args.config, args.set, ROBOT_TABLES)
    except config_mod.ConfigError as exc:
        raise UsageError(str(exc)) from None
    controller_config = build_controller_config(args, cfg)
    budget_config = build_budget_config(args, cfg)
    # Bad ROS 2 flags are one line whatever the driver (a typo now, not on the day it runs on
    # --driver ros2); without rclpy only --driver ros2 stops.
    _ros2_settings(args, cfg, need_rclpy=args.driver == "ros2")
    camera = _camera_config(args, cfg)
    if args.driver == "ros2":
        # DESIGN 11: a zero twist in HOLD; a ROS 2 base brakes at its own limits.
        controller_config = dataclasses.replace(controller_config, hold_ramp=False)
    rate_hz = 1.0 / controller_config.nominal_period_s
    lease_ms = args.lease_ms
    if lease_ms is None and args.zenoh_config is None:
        lease_ms = LEASE_MS
    caveat = resume_window_caveat(controller_config, lease_ms)
    if caveat is not None:
        log.warning("%s", caveat)
    if args.summary is not None:
        check_writable(args.summary, "--summary")
    recorder = _open_recorder(args)  # a bad path: one line, before any session or driver opens
    session = open_session(options_from_args(args))
    try:
        driver = _open_driver(args, cfg, session, camera.topic)
        opened = _open_camera(camera, args.robot, session, driver)
    except BaseException:
        # The session's threads would keep the process alive, deaf to SIGTERM: close it.
        session.close()
        if recorder is not None:
            recorder.close()
        raise
    streamer, viewers = (None, None) if opened is None else opened
    stop = stop_on_signals()  # not threading.Event: its set() can deadlock in a handler
    stats = RunStats()
    node = RobotNode(
        session,
        args.robot,
        RobotController(controller_config, time.monotonic_ns()),
        driver,
        rate_hz,
        recorder=recorder,
        stats=stats,
        clock_id=monotonic_clock_id(),
        budget=budget_config
        if streamer is None
        else dataclasses.replace(budget_config, camera=True, camera_max_fps=camera.max_fps),
        camera=streamer,
    )
    map_id = getattr(driver, "map_id", None)
    info = InfoServer(session, args.robot, _describer(args, node.controller, map_id))
    mux = controller_config.sources
    if mux is not None:
        log.info(
            "command sources (DESIGN 14): %s; locks: %s",
            ", ".join(f"{s.name} ({s.kind}, priority {s.priority})" for s in mux.sources),
            ", ".join(f"{lk.name} (priority {lk.priority})" for lk in mux.locks) or "none",
        )
    log.info(
        "robot %r ready: driver %s, profile %s, filter %s, %.6g Hz, telemetry %.6g Hz, "
        "downlink budget %s",
        args.robot,
        args.driver,
        args.profile,
        args.filter,
        rate_hz,
        budget_config.telemetry_hz,
        "auto"
        if budget_config.downlink_kbps is None
        else f"{budget_config.downlink_kbps:g} kbit/s",
    )
    # What exists now (modules, configuration, the session) lives as long as the process: keep
    # it out of the garbage collector's scans, so a collection in a control cycle stays short.
    gc.collect()
    gc.freeze()
    try:
        node.run(stop)
    finally:
        # Each step even if one before it fails: a Zenoh close that times out (a peer or router
        # gone at the same moment: "close operation timed out") ended the process with a
        # traceback and without its summary.
        for what, step in (
            ("stop answering info queries", info.close),
            ("stop the node", node.shutdown),
            ("stop the camera", lambda: _close_camera(streamer, viewers)),
            ("close the driver", driver.close),
            ("close the Zenoh session", session.close),
        ):
            try:
                step()
            except Exception as exc:
                log.error("could not %s: %s", what, exc)
        summary = stats.summary()
        summary["accepted"] = node.controller.counters.accepted
        summary["rejected"] = dict(node.controller.counters.rejected)
        received, missing = node.controller.link_totals
        summary["seq_received"] = received
        summary["seq_missing"] = missing
        if streamer is not None:
            summary["camera"] = streamer.summary()  # DESIGN 12, pinned keys
        log.info("stopped: %s", json.dumps(summary))
        if args.summary:
            try:
                Path(args.summary).write_text(
                    json.dumps(summary, indent=2) + "\n", encoding="utf-8"
                )
            except OSError as exc:  # checked at the start; the disk may have filled since
                log.error("could not write the summary to %s: %s", args.summary, exc)
    return 0
