"""The fake base's ROS 2 node, in a process of its own: ``python -m tests.ros2.fake_base_process``.

Run by ``FakeBase`` (``fake_base.py``, whose docstring says what the base does). It is a process
of its own, as a real base and lidar are, for two reasons the CI runs gave:

- Its scans came from a thread of the pytest worker. With two suites on two cores that worker
  paused for 100-180 ms between scans now and then (CI run 92).
- Its rclpy node was destroyed in the pytest worker: ``destroy_node()`` segfaulted once inside
  ``rcl_node_fini`` (Fast DDS deleting the participant), with both of its threads provably out
  (CI run 74), and took the worker and the run with it. Here the threads are stopped and joined,
  then the process ends with ``os._exit``: no node is destroyed, the kernel frees it all.

Argument: one JSON object (``cmd_type``, ``wall_x_m``, ``laser_yaw_rad``, ``upside_down``,
``range_min_m``). Lines it prints, one per event:

- ``ready`` once its node and publishers exist, just before its threads start;
- ``cmd RX_NS LINEAR ANGULAR FRAME`` for every ``/cmd_vel`` (FRAME ``-`` for a plain Twist);
- ``tick X_M SCANS SUBSCRIBERS`` every period: its pose, scans published, ``/scan``'s subscribers;
- ``gap MS`` for every gap between two of its scans longer than two periods;
- ``error TEXT`` for an exception in its executor; ``closed ok`` or ``closed stuck`` at the end.

Lines it reads: ``scans on``, ``scans off``, ``ranges JSON_LIST`` (``Infinity``, ``-Infinity`` and
``NaN`` as JSON writes them), ``ranges null``, ``close`` (or its stdin closing).
"""

from __future__ import annotations

import json
import math
import os
import sys
import threading
import time
from typing import Any

import numpy as np
import rclpy
from egc_common.executor_thread import ExecutorThread
from geometry_msgs.msg import Twist, TwistStamped
from nav_msgs.msg import Odometry
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import LaserScan

BEAMS = 360
RANGE_MAX_M = 8.0
PERIOD_S = 0.05  # scans and odometry at 20 Hz
# Both threads leave within a wait or a loop period; this long means one is stuck.
STOP_PATIENCE_S = 30.0


def wall_ranges(
    x_m: float, wall_x_m: float | None, laser_yaw_rad: float, upside_down: bool, range_min_m: float
) -> np.ndarray:
    """The laser's ranges at ``x_m`` of a wall across the x axis at ``wall_x_m`` (none: all
    ``+inf``); beams nearer than ``range_min_m`` read ``-inf`` (REP 117)."""
    angles = -math.pi + 2 * math.pi / BEAMS * np.arange(BEAMS)
    # Physical direction in the base frame of each reported beam (the laser at the centre).
    sign = -1.0 if upside_down else 1.0
    robot_angles = laser_yaw_rad + sign * angles
    out = np.full(BEAMS, np.inf)
    if wall_x_m is not None:
        c = np.cos(robot_angles)
        with np.errstate(divide="ignore"):
            d = np.where(c > 1e-6, (wall_x_m - x_m) / c, np.inf)
        d = np.where(d < range_min_m, -np.inf, d)
        out = np.where(d <= RANGE_MAX_M, d, np.inf)
    return out


class BaseNode:
    def __init__(self, settings: dict[str, Any]) -> None:
        self.settings = settings
        self.ranges_override: np.ndarray | None = None
        self.scans_on = threading.Event()
        self.scans_on.set()
        self.x_m = 0.0
        self.scans_published = 0
        self._out_lock = threading.Lock()
        self._v = (0.0, 0.0)
        self._stamped = settings["cmd_type"] == "twist-stamped"
        self._context = Context()
        rclpy.init(context=self._context, signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node("fake_base", context=self._context)
        reliable = QoSProfile(
            depth=10, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE
        )
        self._scan_pub = self.node.create_publisher(LaserScan, "/scan", qos_profile_sensor_data)
        self._odom_pub = self.node.create_publisher(Odometry, "/odom", reliable)
        self.node.create_subscription(
            TwistStamped if self._stamped else Twist, "/cmd_vel", self._on_cmd, reliable
        )
        self._executor = SingleThreadedExecutor(context=self._context)
        self._executor.add_node(self.node)
        self._spinner = ExecutorThread(
            self._executor, lambda e: self.say(f"error {e!r}"), name="fake-base-ros2"
        )
        self._stop = threading.Event()
        self._loop_thread = threading.Thread(target=self._loop, name="fake-base-loop", daemon=True)

    def start(self) -> None:
        self._spinner.start()
        self._loop_thread.start()

    def say(self, line: str) -> None:
        with self._out_lock:
            sys.stdout.write(line + "\n")
            sys.stdout.flush()

    def _on_cmd(self, msg: Any) -> None:
        now = time.monotonic_ns()
        twist = msg.twist if self._stamped else msg
        frame = msg.header.frame_id if self._stamped else "-"
        self._v = (twist.linear.x, twist.angular.z)
        self.say(f"cmd {now} {twist.linear.x!r} {twist.angular.z!r} {frame or '-'}")

    def _ranges(self) -> np.ndarray:
        if self.ranges_override is not None:
            return self.ranges_override
        s = self.settings
        return wall_ranges(
            self.x_m, s["wall_x_m"], s["laser_yaw_rad"], s["upside_down"], s["range_min_m"]
        )

    def _loop(self) -> None:
        last = time.monotonic()
        last_scan = None
        while not self._stop.wait(PERIOD_S):
            now = time.monotonic()
            v, _ = self._v
            self.x_m += v * (now - last)
            last = now
            stamp = self.node.get_clock().now().to_msg()
            if self.scans_on.is_set():
                scan = LaserScan()
                scan.header.stamp = stamp
                scan.header.frame_id = "laser"
                scan.angle_min = -math.pi
                scan.angle_increment = 2 * math.pi / BEAMS
                scan.angle_max = math.pi - 2 * math.pi / BEAMS
                scan.range_min = self.settings["range_min_m"]
                scan.range_max = RANGE_MAX_M
                scan.ranges = self._ranges().astype(np.float32)
                self._scan_pub.publish(scan)
                self.scans_published += 1
                if last_scan is not None and now - last_scan > 2 * PERIOD_S:
                    self.say(f"gap {(now - last_scan) * 1e3:.0f}")
                last_scan = now
            else:
                last_scan = None
            odom = Odometry()
            odom.header.stamp = stamp
            odom.header.frame_id = "odom"
            odom.child_frame_id = "base_link"
            odom.pose.pose.position.x = self.x_m
            odom.pose.pose.orientation.w = 1.0
            odom.twist.twist.linear.x = v
            self._odom_pub.publish(odom)
            subscribers = self._scan_pub.get_subscription_count()
            self.say(f"tick {self.x_m!r} {self.scans_published} {subscribers}")

    def stop(self) -> bool:
        """Both threads out (True), or one still inside after ``STOP_PATIENCE_S``."""
        self._stop.set()
        self._loop_thread.join(STOP_PATIENCE_S)
        spinner_out = self._spinner.stop(STOP_PATIENCE_S)
        return spinner_out and not self._loop_thread.is_alive()


def main(argv: list[str]) -> None:
    base = BaseNode(json.loads(argv[0]))
    base.say("ready")  # first: its threads print too (CI run 97 read a "tick" first)
    base.start()
    for line in sys.stdin:
        words = line.strip().split(maxsplit=1)
        if words == ["scans", "on"]:
            base.scans_on.set()
        elif words == ["scans", "off"]:
            base.scans_on.clear()
        elif words[:1] == ["ranges"] and len(words) == 2:
            value = json.loads(words[1])
            base.ranges_override = None if value is None else np.asarray(value, np.float64)
        elif words == ["close"]:
            break
    base.say(f"closed {'ok' if base.stop() else 'stuck'}")
    os._exit(0)  # no destroy_node(): see the module's docstring


if __name__ == "__main__":
    main(sys.argv[1:])
