"""``egc-teleop sim --ros2``: our simulator as a ROS 2 robot (DESIGN 11, issue 14).

Any of our worlds behaves like a TurtleBot, Jackal or Pioneer with ROS 2 drivers:

- publishes ``sensor_msgs/LaserScan`` on ``--ros-scan`` (default ``/scan``; frame ``laser`` at the
  base's centre, ``+inf`` where a beam has no return within range_max, REP 117) at ``--scan-hz``,
  with sensor-data QoS as lidar drivers do;
- publishes ``nav_msgs/Odometry`` on ``--ros-odom`` (``/odom``; ``odom`` -> ``base_link``, the
  twist in ``base_link``) every physics step, reliable;
- takes ``geometry_msgs/Twist`` (or ``TwistStamped`` with ``--ros-cmd-type twist-stamped``) on
  ``--ros-cmd`` (``/cmd_vel``), and stops the base when that topic has been silent for
  ``--base-timeout-s`` (0.5 s), as real bases do. A non-finite twist is taken as zero.

``ROS_DOMAIN_ID`` and ``RMW_IMPLEMENTATION`` are read by ROS 2 itself. With
``egc-teleop robot --driver ros2`` and ``egc-teleop operator`` this runs the whole product with a
real ROS 2 graph in the loop (``egc-teleop demo --ros2``). This module and
``egc_robot.ros2_driver`` are the only ones importing rclpy, and only when used.
"""

from __future__ import annotations

import argparse
import logging
import math
import threading
import time
from typing import Any

from egc_common.errors import UsageError
from egc_common.executor_thread import ExecutorThread
from egc_common.ros2_topics import (
    DEFAULT_CMD_TOPIC,
    DEFAULT_ODOM_TOPIC,
    DEFAULT_SCAN_TOPIC,
    default_topic,
)
from egc_common.scan import Scan
from egc_common.stop_flag import stop_on_signals

from egc_sim.simulator import Simulator

log = logging.getLogger("egc.sim.ros2")

NS_PER_S = 1_000_000_000
# The executor's thread leaves within one wait (0.1 s) plus the callback in progress; past this,
# a callback is stuck and the node is left to the process's exit (never destroyed under it).
_STOP_PATIENCE_S = 10.0
NODE_NAME = "egc_sim"
CMD_TYPES = ("twist", "twist-stamped")
MISSING_RCLPY = (
    "--ros2 needs ROS 2's rclpy: pip install -e '.[ros2]' (the ros2 extra), or create the venv "
    "with --system-site-packages from a shell with a sourced ROS 2"
)


def add_ros2_arguments(parser: argparse.ArgumentParser) -> None:
    """``--ros2`` and the topic flags of ``egc-teleop sim`` (the names of ``robot --driver ros2``)."""
    group = parser.add_argument_group("ROS 2 (--ros2: a ROS 2 robot instead of Zenoh keys)")
    group.add_argument(
        "--ros2",
        action="store_true",
        help="be a ROS 2 robot: LaserScan and Odometry out, Twist in (no Zenoh)",
    )
    in_ns = ", or relative to --ros-namespace"
    group.add_argument("--ros-scan", metavar="TOPIC", help=f"(default: /scan{in_ns})")
    group.add_argument("--ros-odom", metavar="TOPIC", help=f"(default: /odom{in_ns})")
    group.add_argument("--ros-cmd", metavar="TOPIC", help=f"(default: /cmd_vel{in_ns})")
    group.add_argument(
        "--ros-cmd-type", choices=CMD_TYPES, default="twist", help="(default: twist)"
    )
    group.add_argument("--ros-namespace", default="", metavar="NS", help="(default: none)")


def require_rclpy() -> None:
    """Raise UsageError (one line naming the extra) unless rclpy and the messages import."""
    try:
        import geometry_msgs.msg  # noqa: F401
        import nav_msgs.msg  # noqa: F401
        import rclpy  # noqa: F401
        import sensor_msgs.msg  # noqa: F401
    except ImportError as exc:
        raise UsageError(f"{MISSING_RCLPY} ({exc})") from None


def command_in_effect(
    last: tuple[float, float], rx_ns: int, now_ns: int, timeout_ns: int
) -> tuple[float, float]:
    """The velocity the base drives with: the last command unless it is older than the timeout
    (or was never received, ``rx_ns`` 0), then zero."""
    if rx_ns == 0 or now_ns - rx_ns > timeout_ns:
        return 0.0, 0.0
    return last


class Ros2Base:
    """The simulator's ROS 2 face: a node with its own context and executor thread
    (``egc_common.executor_thread``: ``close`` destroys the node only once it is out)."""

    def __init__(self, sim: Simulator, args: argparse.Namespace) -> None:
        require_rclpy()
        import rclpy
        from geometry_msgs.msg import Twist, TwistStamped
        from nav_msgs.msg import Odometry
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
        from rclpy.signals import SignalHandlerOptions
        from sensor_msgs.msg import LaserScan

        self._sim = sim
        self._lock = threading.Lock()
        self._cmd = (0.0, 0.0)
        self._cmd_rx_ns = 0
        self.commands = 0
        self._laser_scan = LaserScan
        self._odometry_msg = Odometry
        self._stamped = args.ros_cmd_type == "twist-stamped"
        self._context = Context()
        rclpy.init(context=self._context, signal_handler_options=SignalHandlerOptions.NO)
        try:
            self._node = rclpy.create_node(
                NODE_NAME, namespace=args.ros_namespace or None, context=self._context
            )
            reliable = QoSProfile(  # type: ignore[no-untyped-call]
                depth=10, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE
            )
            self._scan_pub = self._node.create_publisher(
                LaserScan, args.ros_scan, qos_profile_sensor_data
            )
            self._odom_pub = self._node.create_publisher(Odometry, args.ros_odom, reliable)
            self._node.create_subscription(
                TwistStamped if self._stamped else Twist, args.ros_cmd, self._on_cmd, reliable
            )
            self._executor = SingleThreadedExecutor(context=self._context)
            self._executor.add_node(self._node)
        except Exception:
            self._context.try_shutdown()
            raise
        self._spinner = ExecutorThread(self._executor, self._on_executor_error)
        self._spinner.start()

    def _on_executor_error(self, exc: Exception) -> None:
        log.error("ROS 2 executor stopped: %s", exc)

    def _on_cmd(self, msg: Any) -> None:
        now = time.monotonic_ns()
        try:
            twist = msg.twist if self._stamped else msg
            v, w = float(twist.linear.x), float(twist.angular.z)
        except Exception:
            return
        if not (math.isfinite(v) and math.isfinite(w)):
            v, w = 0.0, 0.0
        with self._lock:
            self._cmd, self._cmd_rx_ns = (v, w), now
            self.commands += 1

    def command(self, now_ns: int, timeout_ns: int) -> tuple[float, float]:
        with self._lock:
            return command_in_effect(self._cmd, self._cmd_rx_ns, now_ns, timeout_ns)

    def publish_scan(self, scan: Scan, scan_period_s: float) -> None:
        msg = self._laser_scan()
        msg.header.stamp = self._node.get_clock().now().to_msg()
        msg.header.frame_id = "laser"
        angles = scan.angles_rad
        msg.angle_min = float(angles[0])
        msg.angle_increment = float(angles[1] - angles[0]) if angles.size > 1 else 0.0
        msg.angle_max = float(angles[-1])
        msg.time_increment = 0.0
        msg.scan_time = float(scan_period_s)
        msg.range_min = float(scan.range_min_m)
        msg.range_max = float(scan.range_max_m)
        msg.ranges = scan.ranges_m.astype("f4")  # +inf where a beam has no return (REP 117)
        self._scan_pub.publish(msg)

    def publish_odometry(self) -> None:
        x, y, theta = self._sim.odometry
        v, w = self._sim.twist
        msg = self._odometry_msg()
        msg.header.stamp = self._node.get_clock().now().to_msg()
        msg.header.frame_id = "odom"
        msg.child_frame_id = "base_link"
        msg.pose.pose.position.x = float(x)
        msg.pose.pose.position.y = float(y)
        msg.pose.pose.orientation.z = math.sin(float(theta) / 2.0)
        msg.pose.pose.orientation.w = math.cos(float(theta) / 2.0)
        msg.twist.twist.linear.x = float(v)
        msg.twist.twist.angular.z = float(w)
        self._odom_pub.publish(msg)

    def close(self) -> None:
        # The executor's thread must be out before the node goes: destroying a node under a
        # running wait crashed the process (issue 31).
        if not self._spinner.stop(_STOP_PATIENCE_S):
            log.error(
                "the ROS 2 executor thread did not stop within %.0f s; the node is left to the "
                "process's exit",
                _STOP_PATIENCE_S,
            )
            return
        try:
            self._executor.shutdown()
            self._node.destroy_node()  # type: ignore[no-untyped-call]
        finally:
            self._context.try_shutdown()


def resolve_topics(args: argparse.Namespace) -> None:
    """Topics not given: ``/scan``, ``/odom``, ``/cmd_vel``, or in a ``--ros-namespace`` the
    same names relative to it (``/robot1/scan``), as for ``robot --driver ros2``."""
    for attr, default in (
        ("ros_scan", DEFAULT_SCAN_TOPIC),
        ("ros_odom", DEFAULT_ODOM_TOPIC),
        ("ros_cmd", DEFAULT_CMD_TOPIC),
    ):
        if getattr(args, attr, None) is None:
            setattr(args, attr, default_topic(default, args.ros_namespace))


def run_ros2_base(sim: Simulator, args: argparse.Namespace) -> int:
    """Step ``sim`` in real time as a ROS 2 robot until SIGINT/SIGTERM (see the module doc)."""
    from egc_sim.bridge import RealTimeSim  # the same real-time stepping as the Zenoh bridge

    resolve_topics(args)
    stop = stop_on_signals()  # not threading.Event: its set() can deadlock in a handler
    try:
        base = Ros2Base(sim, args)
    except UsageError:
        raise
    except Exception as exc:  # rclpy's own errors (bad topic names, ROS_DOMAIN_ID)
        raise UsageError(f"cannot start the ROS 2 node: {exc}") from None
    now = time.monotonic_ns()
    scan_period_s = 1.0 / args.scan_hz
    rt = RealTimeSim(sim, now, scan_period_s)
    period = int(NS_PER_S / args.physics_hz)
    timeout_ns = int(args.base_timeout_s * NS_PER_S)
    deadline = now + period
    log.info(
        "simulating %s on %s as a ROS 2 robot: %s, %s out, %s (%s) in",
        sim.profile.name,
        args.map,
        args.ros_scan,
        args.ros_odom,
        args.ros_cmd,
        args.ros_cmd_type,
    )
    try:
        while not stop.is_set():
            stop.wait(max(0, deadline - time.monotonic_ns()) / NS_PER_S)
            now = time.monotonic_ns()
            rt.advance(now)
            rt.set_command(*base.command(now, timeout_ns))
            scan = rt.scan_if_due(now)
            if scan is not None:
                base.publish_scan(scan, scan_period_s)
            base.publish_odometry()
            deadline += period
            if deadline <= now:
                deadline = now + period
    finally:
        log.info("stopped after %d commands; collided: %s", base.commands, sim.collided)
        base.close()
    return 0
