"""``egc-teleop sim --ros2`` as the ROS 2 robot under ``egc-teleop robot --driver ros2`` and a
real operator: the whole product with a real ROS 2 graph in the loop (DESIGN 11)."""

from __future__ import annotations

import math
import signal
import time

import pytest

pytest.importorskip("rclpy", reason="ROS 2's rclpy is not installed (pip install -e '.[ros2]')")

from egc_common.transport import free_tcp_port, loopback_endpoint

from tests.integration.harness import (
    BUSY_MACHINE_SCAN_TIMEOUT,
    ROBOT,
    Processes,
    joystick_file,
    operator_args,
)
from tests.ros2.test_robot_ros import STOP_TIMEOUT_S, wait_log

pytestmark = [pytest.mark.integration, pytest.mark.timeout(120)]


@pytest.fixture
def procs(tmp_path):
    group = Processes(tmp_path)
    try:
        yield group
    finally:
        group.cleanup()
        for name in group.children:
            print(f"---- {name} ----\n{group.log(name)[-3000:]}")


@pytest.mark.parametrize(
    ("cmd_type", "topics", "scan_topic"),
    [
        ("twist", ["--ros-scan", "front/scan"], "/front/scan"),
        # A namespace alone moves the default topics into it (relative, as ROS 2 users expect).
        ("twist-stamped", ["--ros-namespace", "robot1"], "/robot1/scan"),
    ],
)
def test_sim_ros2_drives_under_the_robot_and_stops_on_silence(
    ros_domain, procs, tmp_path, cmd_type, topics, scan_topic
):
    port = free_tcp_port()
    summary = tmp_path / "summary.json"
    ros_flags = ["--ros-cmd-type", cmd_type, *topics]
    procs.start("sim", "sim", "--ros2", "--map", "hallway", *ros_flags)
    procs.start(
        "robot",
        *["robot", "--robot", ROBOT, "--driver", "ros2", "--listen", loopback_endpoint(port)],
        *["--summary", str(summary), *ros_flags, *BUSY_MACHINE_SCAN_TIMEOUT],
    )
    wait_log(procs, "robot", r"ready: driver ros2")
    wait_log(procs, "sim", r"as a ROS 2 robot")
    assert f"scans {scan_topic}," in procs.log("robot")
    # The robot hears the simulator's scans (no 'sensor stale' once the operator comes).
    time.sleep(2.0)
    stick = joystick_file(tmp_path / "stick.csv", [(0, 0, 0, 1), (1.5, 1, 0, 1), (60, 1, 0, 1)])
    procs.start("operator", *operator_args(port, "op", stick))
    wait_log(procs, "robot", r"state DRIVING", 30.0)
    time.sleep(3.0)
    # The base stops by itself when /cmd_vel goes silent: SIGKILL leaves no last zero twist.
    procs.children["robot"].send_signal(signal.SIGKILL)
    procs.children["robot"].wait(5)
    time.sleep(1.0)
    assert procs.stop("sim", timeout_s=STOP_TIMEOUT_S) == 0
    sim_log = procs.log("sim")
    assert "collided: False" in sim_log
    commands = int(sim_log.rsplit("stopped after ", 1)[1].split()[0])
    assert commands > 50, sim_log  # about 20 per second of the robot's life


def test_sim_ros2_base_stops_half_a_second_after_cmd_vel_goes_silent(ros_domain, procs):
    """The simulator's base starts braking 0.5 s after the last /cmd_vel (no robot process at
    all), and is stopped after its own deceleration."""
    import rclpy
    from geometry_msgs.msg import Twist
    from nav_msgs.msg import Odometry
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    procs.start("sim", "sim", "--ros2", "--map", "hallway")
    wait_log(procs, "sim", r"as a ROS 2 robot")
    context = Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("probe", context=context)
    # (the simulator's stamp, v): its ROS clock is the system clock, time.time_ns() here; the
    # stamp says when it braked, without the message's trip to this process (issue 32)
    odom: list[tuple[int, float]] = []

    def on_odom(m: Odometry) -> None:
        stamp = m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec
        odom.append((stamp, m.twist.twist.linear.x))

    node.create_subscription(Odometry, "/odom", on_odom, 10)
    pub = node.create_publisher(Twist, "/cmd_vel", 10)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline and not (odom and odom[-1][1] > 0.0999):
            msg = Twist()
            msg.linear.x = 0.1
            pub.publish(msg)
            executor.spin_once(timeout_sec=0.05)
        assert odom and odom[-1][1] > 0.0999, "the simulator never reached 0.1 m/s"
        last_cmd_ns = time.time_ns()
        end = time.monotonic() + 1.5
        while time.monotonic() < end:
            executor.spin_once(timeout_sec=0.05)
        # It keeps the last command for 0.5 s, then brakes at the profile's deceleration
        # (Pioneer 3-DX: 0.5 m/s^2, so 0.2 s from 0.1 m/s), as a real base does. On the
        # simulator's stamps: 0.506-0.515 s and 0.704-0.712 s at load average 6.6.
        braking = next(t for t, v in odom if t > last_cmd_ns and v < 0.099)
        stopped = next(t for t, v in odom if t > last_cmd_ns and v == 0.0)
        assert 0.45 < (braking - last_cmd_ns) / 1e9 < 0.5 + 0.15, (braking - last_cmd_ns) / 1e9
        assert (stopped - last_cmd_ns) / 1e9 < 0.5 + 0.2 + 0.15, (stopped - last_cmd_ns) / 1e9
        assert all(v == 0.0 for t, v in odom if t > stopped)
        assert math.isfinite(odom[-1][1])
    finally:
        # Spun in this thread only (spin_once above), so nothing is inside it now (issue 31).
        executor.shutdown()
        node.destroy_node()
        context.try_shutdown()
