"""``egc-teleop sim``: the simulated robot as its own process, a remote driver over Zenoh.

It plays the part a real robot bridge plays (DESIGN 1, 7): it subscribes to
``egc/<robot>/base/cmd``, steps the simulator in real time, and publishes ``egc/<robot>/scan``
(at ``--scan-hz``) and ``egc/<robot>/base/odom`` (every physics step). Like a real base's
firmware it has its own watchdog: no valid base command for ``--base-timeout-s`` and it stops.
The robot process drives it with ``egc-teleop robot --driver zenoh``.

``RealTimeSim`` (the simulator stepped against a monotonic clock) and ``open_simulator`` are
also used by the robot's in-process ``--driver sim``, so both drivers simulate the same way.
"""

from __future__ import annotations

import argparse
import logging
import math
import threading
import time
from typing import Any

from egc_common import keys
from egc_common.cli_args import PROFILE_HELP, plain_float
from egc_common.errors import UsageError
from egc_common.messages import (
    Odometry,
    Rejection,
    ScanMessage,
    decode_base_command,
)
from egc_common.profiles import RobotProfile, get_profile
from egc_common.scan import Scan
from egc_common.stop_flag import stop_on_signals
from egc_common.transport import (
    DEFAULT_ENDPOINT,
    add_zenoh_arguments,
    data_publisher,
    open_session,
    options_from_args,
    payload_bytes,
    serve_static,
)

from egc_sim.grid_world import map_message
from egc_sim.lidar import LidarConfig
from egc_sim.ros2_base import add_ros2_arguments
from egc_sim.simulator import Simulator
from egc_sim.worlds import load_world

log = logging.getLogger("egc.sim")

DEFAULT_WORLD = "hallway"
NS_PER_S = 1_000_000_000


def parse_pose(text: str | None) -> tuple[float, float, float] | None:
    """``X,Y,YAW`` (metres, metres, radians) or None."""
    if text is None:
        return None
    parts = text.split(",")
    try:
        x, y, yaw = (plain_float(p) for p in parts)
    except ValueError:
        raise UsageError(f"--start must be X,Y,YAW in metres and radians, got {text!r}") from None
    if not all(math.isfinite(v) for v in (x, y, yaw)):
        raise UsageError("--start values must be finite")
    return x, y, yaw


def open_simulator(
    world_spec: str,
    profile: RobotProfile,
    start: tuple[float, float, float] | None,
    seed: int,
    beams: int | None = None,
) -> Simulator:
    """Load a world (path or built-in name) and place the robot (a clear UsageError if not)."""
    try:
        world = load_world(
            world_spec, seed=seed, reach_m=profile.footprint.reach_m, footprint=profile.footprint
        )
    except (OSError, ValueError) as exc:
        raise UsageError(f"cannot load world {world_spec!r}: {exc}") from None
    kwargs: dict[str, Any] = {"seed": seed}
    if start is not None:
        kwargs["start_pose"] = start
    try:
        if beams is not None:
            kwargs["lidar"] = LidarConfig(beams=beams)
        return Simulator(world, profile, **kwargs)
    except ValueError as exc:
        raise UsageError(f"cannot start the simulator: {exc}") from None


class RealTimeSim:
    """The simulator stepped against a monotonic clock: physics in steps of at most
    ``max_step_s`` with the latest velocity command, a scan every ``scan_period_s``."""

    def __init__(
        self, sim: Simulator, start_ns: int, scan_period_s: float, max_step_s: float = 0.01
    ) -> None:
        self.sim = sim
        self._t_ns = start_ns
        self._scan_period_ns = int(scan_period_s * NS_PER_S)
        self._next_scan_ns = start_ns
        self._max_step_s = max_step_s
        self._cmd = (0.0, 0.0)

    def set_command(self, linear_mps: float, angular_radps: float) -> None:
        self._cmd = (linear_mps, angular_radps)

    def advance(self, now_ns: int) -> None:
        remaining = (now_ns - self._t_ns) / NS_PER_S
        while remaining > 1e-9:
            dt = min(remaining, self._max_step_s)
            self.sim.step(self._cmd[0], self._cmd[1], dt)
            remaining -= dt
        self._t_ns = max(self._t_ns, now_ns)

    def scan_if_due(self, now_ns: int) -> Scan | None:
        if now_ns < self._next_scan_ns:
            return None
        self._next_scan_ns = max(self._next_scan_ns + self._scan_period_ns, now_ns)
        return self.sim.scan(now_ns)

    def odometry(self, now_ns: int) -> Odometry:
        """What a real base reports: wheel odometry (the simulator's, noisy if configured)."""
        x, y, theta = self.sim.odometry
        v, w = self.sim.twist
        mx, my, mth = self.sim.pose
        return Odometry(
            stamp_ns=now_ns,
            x_m=float(x),
            y_m=float(y),
            theta_rad=float(theta),
            linear_mps=float(v),
            angular_radps=float(w),
            collided=bool(self.sim.collided),
            # The simulator knows where it is: its true pose stands in for a localiser's map pose.
            map_pose=(float(mx), float(my), float(mth)),
        )


def scan_message(scan: Scan, stamp_ns: int) -> ScanMessage:
    """A uniformly spaced Scan in the wire layout of ``egc/<robot>/scan``."""
    angles = scan.angles_rad
    increment = float(angles[1] - angles[0]) if angles.size > 1 else 0.0
    return ScanMessage(
        stamp_ns=stamp_ns,
        angle_min_rad=float(angles[0]) if angles.size else 0.0,
        angle_increment_rad=increment,
        range_min_m=scan.range_min_m,
        range_max_m=scan.range_max_m,
        ranges_m=scan.ranges_m.astype("<f4"),
        no_return_is_free=scan.no_return_is_free,
    )


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--robot",
        default=keys.DEFAULT_ROBOT_ID,
        metavar="ID",
        help=f"robot id in the Zenoh keys (default: {keys.DEFAULT_ROBOT_ID})",
    )
    parser.add_argument(
        "--map",
        default=DEFAULT_WORLD,
        metavar="SPEC",
        help=f"map.yaml, world .toml, built-in name or random:SEED (default: {DEFAULT_WORLD})",
    )
    parser.add_argument(
        "--profile",
        default="pioneer3dx",
        metavar="NAME|FILE",
        help=f"{PROFILE_HELP} (default: pioneer3dx)",
    )
    parser.add_argument("--start", metavar="X,Y,YAW", help="start pose (default: the world's)")
    parser.add_argument(
        "--seed", type=int, default=0, help="sensor noise and random-world seed (default: 0)"
    )
    parser.add_argument(
        "--beams",
        type=int,
        default=None,
        help=f"lidar beams per scan, 1-100000 (default: {LidarConfig().beams})",
    )
    parser.add_argument("--scan-hz", type=float, default=20.0, help="scan rate (default: 20)")
    parser.add_argument(
        "--physics-hz", type=float, default=100.0, help="physics steps per second (default: 100)"
    )
    parser.add_argument(
        "--base-timeout-s",
        type=float,
        default=0.5,
        help="the base stops after this long without a command (default: 0.5)",
    )
    add_ros2_arguments(parser)
    add_zenoh_arguments(parser, default_connect=(DEFAULT_ENDPOINT,))


def run(args: argparse.Namespace) -> int:
    logging.basicConfig(level=logging.INFO, format="sim: %(message)s")
    try:
        robot_id = keys.validate_id(args.robot)
        profile = get_profile(args.profile)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    for name in ("scan_hz", "physics_hz", "base_timeout_s"):
        if not (math.isfinite(getattr(args, name)) and getattr(args, name) > 0):
            raise UsageError(f"--{name.replace('_', '-')} must be positive")
    if args.ros2:  # a ROS 2 robot instead (egc_sim.ros2_base, DESIGN 11)
        from egc_sim.ros2_base import require_rclpy, run_ros2_base

        require_rclpy()
        sim = open_simulator(args.map, profile, parse_pose(args.start), args.seed, args.beams)
        return run_ros2_base(sim, args)
    sim = open_simulator(args.map, profile, parse_pose(args.start), args.seed, args.beams)
    session: Any = open_session(options_from_args(args))  # zenoh's stubs leave close() untyped
    stop = stop_on_signals()  # not threading.Event: its set() can deadlock in a handler

    lock = threading.Lock()
    last_cmd: list[Any] = [(0.0, 0.0), 0]  # (v, w), arrival time

    def on_base_cmd(sample: Any) -> None:
        now = time.monotonic_ns()
        decoded = decode_base_command(payload_bytes(sample))
        if isinstance(decoded, Rejection):
            log.warning("rejected base command: %s", decoded)
            return
        with lock:
            last_cmd[0], last_cmd[1] = (decoded.linear_mps, decoded.angular_radps), now

    subscriber: Any = session.declare_subscriber(keys.base_cmd(robot_id), on_base_cmd)
    map_server: Any = serve_static(
        session, keys.world_map(robot_id), map_message(sim.world, time.monotonic_ns()).encode()
    )
    scan_pub = data_publisher(session, keys.scan(robot_id))
    odom_pub = data_publisher(session, keys.base_odom(robot_id))
    now = time.monotonic_ns()
    rt = RealTimeSim(sim, now, 1.0 / args.scan_hz)
    period = int(NS_PER_S / args.physics_hz)
    timeout_ns = int(args.base_timeout_s * NS_PER_S)
    deadline = now + period
    log.info("simulating %s on %s for robot %r", profile.name, args.map, robot_id)
    try:
        while not stop.is_set():
            stop.wait(max(0, deadline - time.monotonic_ns()) / NS_PER_S)
            now = time.monotonic_ns()
            with lock:
                (v, w), rx = last_cmd
            rt.advance(now)
            rt.set_command(*((v, w) if now - rx <= timeout_ns else (0.0, 0.0)))
            scan = rt.scan_if_due(now)
            if scan is not None:
                scan_pub.put(scan_message(scan, now).encode())
            odom_pub.put(rt.odometry(now).encode())
            deadline += period
            if deadline <= now:
                deadline = now + period
    finally:
        subscriber.undeclare()
        map_server.undeclare()
        session.close()
    return 0
