"""A ROS 2 robot in the test process: a fake base and lidar for ``egc-teleop robot --driver ros2``.

``FakeBase`` is a real rclpy node (its own context, its own executor thread) that

- integrates the velocity it receives on ``/cmd_vel`` (Twist or TwistStamped) into a pose,
- publishes ``sensor_msgs/LaserScan`` at 20 Hz (sensor-data QoS) of a world made of one wall
  across the x axis at ``wall_x_m`` (or no wall: all ``+inf``), seen by a laser with a given
  pose in the base frame, optionally mounted upside down, or any ``ranges_override``,
- publishes ``nav_msgs/Odometry``,
- records every ``/cmd_vel`` with its arrival time (``time.monotonic_ns()``, comparable with
  the processes' clocks on Linux),
- records the gaps between its own scans longer than two periods (``scan_gaps_ms``), so that a
  robot that held for "sensor stale" says whether its lidar (this test process) went quiet.

Its scans come from a thread of the pytest worker, so it keeps that worker's collections short
as the observer does (``keep_collections_short``).

Every test picks its own ``ROS_DOMAIN_ID`` and keeps discovery on this machine
(``domain_for_test``), so tests and parallel runs cannot hear each other.
"""

from __future__ import annotations

import itertools
import math
import os
import threading
import time
from dataclasses import dataclass
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

from tests.integration.harness import keep_collections_short

_COUNTER = itertools.count()
BEAMS = 360
RANGE_MIN_M = 0.1
RANGE_MAX_M = 8.0
PERIOD_S = 0.05  # scans and odometry at 20 Hz
# Both threads leave within a wait or a loop period; this long means one is stuck.
STOP_PATIENCE_S = 30.0


def domain_for_test() -> int:
    """A ROS_DOMAIN_ID in [1, 101] of its own: pytest-xdist workers take disjoint residues, and
    the process id spreads separate runs on one machine."""
    worker = os.environ.get("PYTEST_XDIST_WORKER", "gw0")
    index = int(worker[2:]) if worker[2:].isdigit() else 0
    workers = max(1, int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")))
    slots = 101 // workers
    k = (os.getpid() * 7 + next(_COUNTER)) % slots
    return 1 + index + workers * k


@dataclass
class CmdSample:
    rx_ns: int
    linear_mps: float
    angular_radps: float
    frame_id: str | None


class FakeBase:
    def __init__(
        self,
        cmd_type: str = "twist",
        wall_x_m: float | None = None,
        laser_yaw_rad: float = 0.0,
        upside_down: bool = False,
        range_min_m: float = RANGE_MIN_M,
    ) -> None:
        keep_collections_short()
        self.wall_x_m = wall_x_m
        self.range_min_m = range_min_m
        self.laser_yaw_rad = laser_yaw_rad
        self.upside_down = upside_down
        self.ranges_override: np.ndarray | None = None
        self.scans_on = threading.Event()
        self.scans_on.set()
        self.x_m = 0.0
        self.max_x_m = 0.0
        self.cmds: list[CmdSample] = []
        self.scans_published = 0
        self.scan_gaps_ms: list[float] = []
        self._lock = threading.Lock()
        self._v = (0.0, 0.0)
        self._stamped = cmd_type == "twist-stamped"
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
        self._errors: list[Exception] = []
        self._spinner = ExecutorThread(self._executor, self._errors.append, name="fake-base-ros2")
        self._stop = threading.Event()
        self._loop_thread = threading.Thread(target=self._loop, name="fake-base-loop", daemon=True)
        self._spinner.start()
        self._loop_thread.start()

    # -- /cmd_vel -------------------------------------------------------------------------------

    def _on_cmd(self, msg: Any) -> None:
        now = time.monotonic_ns()
        twist = msg.twist if self._stamped else msg
        frame = msg.header.frame_id if self._stamped else None
        sample = CmdSample(now, twist.linear.x, twist.angular.z, frame)
        with self._lock:
            self.cmds.append(sample)
            self._v = (twist.linear.x, twist.angular.z)

    def commands(self, since_ns: int = 0) -> list[CmdSample]:
        with self._lock:
            return [c for c in self.cmds if c.rx_ns >= since_ns]

    def wait_for(self, what: str, predicate: Any, timeout_s: float = 20.0) -> Any:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            value = predicate()
            if value:
                return value
            time.sleep(0.01)
        last = self.commands()[-3:]
        raise AssertionError(
            f"timed out after {timeout_s} s waiting for {what}; last: {last}; {self.health()}"
        )

    def health(self) -> str:
        """What the base itself did: how far it went, its scans and their gaps."""
        return (
            f"the fake base drove to x {self.max_x_m:.3f} m at most and published "
            f"{self.scans_published} scans; gaps between them over {2 * PERIOD_S * 1e3:.0f} ms: "
            f"{[round(g) for g in self.scan_gaps_ms]}"
        )

    def wait_connected(self, timeout_s: float = 30.0) -> None:
        """Until the robot's node hears our scans and we hear its /cmd_vel (ROS 2 discovery)."""
        self.wait_for(
            "the robot's node to match our topics",
            lambda: self._scan_pub.get_subscription_count() > 0 and self.commands(),
            timeout_s,
        )
        time.sleep(0.2)  # a few scans on their way

    def wait_driving(self, timeout_s: float = 30.0) -> int:
        """Arrival time of the first command moving forward."""
        sample = self.wait_for(
            "a forward /cmd_vel",
            lambda: next((c for c in self.commands() if c.linear_mps > 0.0), None),
            timeout_s,
        )
        return int(sample.rx_ns)

    # -- the world, the lidar and the odometry --------------------------------------------------

    def ranges(self) -> np.ndarray:
        if self.ranges_override is not None:
            return self.ranges_override
        angles = -math.pi + 2 * math.pi / BEAMS * np.arange(BEAMS)
        # Physical direction in the base frame of each reported beam (the laser at the centre).
        sign = -1.0 if self.upside_down else 1.0
        robot_angles = self.laser_yaw_rad + sign * angles
        out = np.full(BEAMS, np.inf)
        if self.wall_x_m is not None:
            c = np.cos(robot_angles)
            with np.errstate(divide="ignore"):
                d = np.where(c > 1e-6, (self.wall_x_m - self.x_m) / c, np.inf)
            d = np.where(d < self.range_min_m, -np.inf, d)  # closer than range_min (REP 117)
            out = np.where(d <= RANGE_MAX_M, d, np.inf)
        return out

    def _loop(self) -> None:
        last = time.monotonic()
        last_scan = None
        while not self._stop.wait(PERIOD_S):
            now = time.monotonic()
            with self._lock:
                v, _ = self._v
            self.x_m += v * (now - last)
            self.max_x_m = max(self.max_x_m, self.x_m)
            last = now
            stamp = self.node.get_clock().now().to_msg()
            if self.scans_on.is_set():
                scan = LaserScan()
                scan.header.stamp = stamp
                scan.header.frame_id = "laser"
                scan.angle_min = -math.pi
                scan.angle_increment = 2 * math.pi / BEAMS
                scan.angle_max = math.pi - 2 * math.pi / BEAMS
                scan.range_min = self.range_min_m
                scan.range_max = RANGE_MAX_M
                scan.ranges = self.ranges().astype(np.float32)
                self._scan_pub.publish(scan)
                self.scans_published += 1
                if last_scan is not None and now - last_scan > 2 * PERIOD_S:
                    self.scan_gaps_ms.append((now - last_scan) * 1e3)
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

    def close(self) -> None:
        """Both threads out, then the node goes: destroying it under a thread still using it
        segfaulted a CI run (issue 31). A thread still inside fails the test and the node is
        left to the process's exit."""
        self._stop.set()
        self._loop_thread.join(STOP_PATIENCE_S)
        spinner_out = self._spinner.stop(STOP_PATIENCE_S)
        if self._loop_thread.is_alive() or not spinner_out:
            raise AssertionError(f"the fake base's threads did not stop in {STOP_PATIENCE_S} s")
        self._executor.shutdown()
        self.node.destroy_node()
        self._context.try_shutdown()
        assert not self._errors, f"the fake base's executor failed: {self._errors}"
