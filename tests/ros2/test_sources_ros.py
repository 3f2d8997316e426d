"""Command sources and locks on a ROS 2 robot (DESIGN 14, issue 29; docs/ros2-sources.md): the
robot process between a navigation stack's ``/cmd_vel_nav`` and the base's ``/cmd_vel``, a
joystick operator over Zenoh on top, a ``std_msgs/Bool`` lock on ``/pause``.

Real processes and a real ROS 2 graph: the test's FakeBase (lidar, odometry, ``/cmd_vel``) and
``NavAndLock`` nodes (rclpy, their own contexts), the robot (``--driver ros2``), an operator
process with a recorded joystick; the test's Zenoh Observer reads the robot's telemetry and
state. The robot's switching is timed on its own stamps (state messages, ``source_age_ms``);
what the base received, on the base's arrival times (the same CLOCK_MONOTONIC)."""

from __future__ import annotations

import signal
import threading
import time
from pathlib import Path

import pytest

pytest.importorskip("rclpy", reason="ROS 2's rclpy is not installed (pip install -e '.[ros2]')")
pytest.importorskip("std_msgs.msg", reason="std_msgs is not installed (ros-jazzy-std-msgs)")

import rclpy
from egc_common.executor_thread import ExecutorThread
from egc_common.transport import free_tcp_port, loopback_endpoint
from geometry_msgs.msg import Twist
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from std_msgs.msg import Bool

from tests.integration.harness import (
    BUSY_MACHINE_SCAN_TIMEOUT,
    ROBOT,
    Observer,
    Processes,
    joystick_file,
    operator_args,
)
from tests.ros2.fake_base import STOP_PATIENCE_S, FakeBase
from tests.ros2.test_robot_ros import wait_log

pytestmark = [pytest.mark.integration, pytest.mark.timeout(180)]
MS = 1_000_000

RECIPE = """
[[source]]
name = "nav"
kind = "ros2"
topic = "/cmd_vel_nav"
priority = 10
timeout_s = 0.5

[[source]]
name = "joystick"
kind = "operator"
priority = 100
timeout_s = 0.5

[[lock]]
name = "pause"
kind = "ros2"
topic = "/pause"
priority = 200
timeout_s = 1.0
"""
V_NAV = 0.12  # m/s, /cmd_vel_nav
STICK = 0.3  # the operator's stick: 0.3 x 0.14 m/s = 0.042 m/s


class NavAndLock:
    """A navigation stack's ``/cmd_vel_nav`` (Twist, 20 Hz) and a ``/pause`` heartbeat
    (std_msgs/Bool, 10 Hz), each switched on and off by the test."""

    def __init__(self) -> None:
        self.v_mps = V_NAV
        self.nav_on = threading.Event()
        self.lock_on = threading.Event()
        self.lock_value = False
        self.last_nav_ns = 0
        self.last_lock_ns = 0
        self._lock = threading.Lock()
        self._context = Context()
        rclpy.init(context=self._context, signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node("fake_nav", context=self._context)
        reliable = QoSProfile(
            depth=10, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE
        )
        self._nav = self.node.create_publisher(Twist, "/cmd_vel_nav", reliable)
        self._pause = self.node.create_publisher(Bool, "/pause", reliable)
        self._executor = SingleThreadedExecutor(context=self._context)
        self._executor.add_node(self.node)
        self._stop = threading.Event()
        self._errors: list[Exception] = []
        self._spinner = ExecutorThread(self._executor, self._errors.append, name="fake-nav-ros2")
        self._loop_thread = threading.Thread(target=self._loop, daemon=True)
        self._spinner.start()
        self._loop_thread.start()

    def wait_matched(self, timeout_s: float = 30.0) -> None:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if self._nav.get_subscription_count() and self._pause.get_subscription_count():
                return
            time.sleep(0.05)
        raise AssertionError("the robot's node never subscribed to /cmd_vel_nav and /pause")

    def set_lock(self, value: bool) -> int:
        """Publish ``value`` on /pause now (and on, at 10 Hz); returns when it was sent."""
        with self._lock:
            self.lock_value = value
            self.lock_on.set()
            sent_ns = time.monotonic_ns()
            self._pause.publish(Bool(data=value))
            self.last_lock_ns = sent_ns
        return sent_ns

    def _loop(self) -> None:
        tick = 0
        while not self._stop.wait(0.05):
            tick += 1
            if self.nav_on.is_set():
                msg = Twist()
                msg.linear.x = self.v_mps
                self._nav.publish(msg)
                self.last_nav_ns = time.monotonic_ns()
            if tick % 2 == 0:
                with self._lock:
                    if self.lock_on.is_set():
                        self._pause.publish(Bool(data=self.lock_value))
                        self.last_lock_ns = time.monotonic_ns()

    def close(self) -> None:
        """As ``FakeBase.close``: both threads out, then the node goes. This one shut its
        executor down under a thread still spinning it (``executor.spin``, joined with a
        timeout); CI run 39 then segfaulted in the fake base's ``destroy_node`` right after."""
        self._stop.set()
        self._loop_thread.join(STOP_PATIENCE_S)
        spinner_out = self._spinner.stop(STOP_PATIENCE_S)
        if self._loop_thread.is_alive() or not spinner_out:
            raise AssertionError(
                f"the fake navigation's threads did not stop in {STOP_PATIENCE_S} s"
            )
        self._executor.shutdown()
        self.node.destroy_node()
        self._context.try_shutdown()
        assert not self._errors, f"the fake navigation's executor failed: {self._errors}"


@pytest.fixture
def graph(ros_domain):
    base, feeds = FakeBase(), NavAndLock()
    yield base, feeds
    feeds.close()
    base.close()


@pytest.fixture
def procs(tmp_path):
    group = Processes(tmp_path)
    try:
        yield group
    finally:
        group.cleanup()
        for name in group.children:  # shown by pytest when the test fails
            print(f"---- {name} ----\n{group.log(name)[-3000:]}")


def start_robot(procs: Processes, tmp_path: Path, base: FakeBase, feeds: NavAndLock) -> int:
    port = free_tcp_port()
    config = tmp_path / "robot.toml"
    config.write_text(RECIPE)
    procs.start(
        "robot",
        "robot",
        "--robot",
        ROBOT,
        "--driver",
        "ros2",
        "--config",
        str(config),
        "--listen",
        loopback_endpoint(port),
        *BUSY_MACHINE_SCAN_TIMEOUT,
    )
    wait_log(procs, "robot", r"ready: driver ros2")
    base.wait_connected()
    feeds.wait_matched()
    return port


def state_after(observer: Observer, what: str, since_ns: int, predicate, timeout_s: float = 30.0):
    def found():
        with observer._lock:
            return next(
                (s for _, s in observer.rec.state if s.stamp_ns > since_ns and predicate(s)), None
            )

    return observer.wait_for(what, found, timeout_s)


def moving_at(base: FakeBase, v_mps: float, since_ns: int, what: str) -> None:
    base.wait_for(
        what,
        lambda: any(abs(c.linear_mps - v_mps) < 0.005 for c in base.commands(since_ns)),
        30.0,
    )


def test_navigation_drives_the_joystick_takes_over_and_hands_back_and_silence_stops_the_base(
    graph, procs, tmp_path
):
    base, feeds = graph
    feeds.set_lock(False)
    port = start_robot(procs, tmp_path, base, feeds)
    observer = Observer(port)
    try:
        feeds.nav_on.set()
        moving_at(base, V_NAV, 0, "navigation's speed on /cmd_vel")
        t = observer.wait_for(
            "telemetry of navigation driving",
            lambda: next((t for t in observer.telemetry() if t.source == "nav"), None),
        )
        assert (t.state, t.reason, t.lock) == ("DRIVING", "source nav", None)

        # The joystick operator (priority 100): centred for 1 s, then STICK forward.
        stick = joystick_file(
            tmp_path / "stick.csv", [(0, 0, 0, 1), (1.0, STICK, 0, 1), (60, STICK, 0, 1)]
        )
        procs.start("operator", *operator_args(port, "op", stick))
        took = state_after(observer, "the joystick's turn", 0, lambda s: s.source == "joystick")
        assert took.operator == "op"
        moving_at(base, STICK * 0.14, took.stamp_ns, "the joystick's speed on /cmd_vel")

        # The operator falls silent: navigation drives again after the joystick's timeout.
        procs.children["operator"].send_signal(signal.SIGSTOP)
        back = state_after(observer, "navigation again", took.stamp_ns, lambda s: s.source == "nav")
        joystick = [t for t in observer.telemetry() if t.source == "joystick"]
        last_ns = joystick[-1].stamp_ns - round(joystick[-1].source_age_ms * MS)
        assert back.stamp_ns > last_ns + 500 * MS
        assert all(t.stamp_ns <= last_ns + 500 * MS for t in joystick)
        moving_at(base, V_NAV, back.stamp_ns, "navigation's speed again")

        # Navigation falls silent too: the base gets zero, at once, after its timeout.
        feeds.nav_on.clear()
        none = state_after(observer, "no source", back.stamp_ns, lambda s: s.source is None)
        assert none.stamp_ns > feeds.last_nav_ns + 500 * MS
        zero = base.wait_for(
            "a zero twist",
            lambda: next(
                (
                    c
                    for c in base.commands(none.stamp_ns)
                    if (c.linear_mps, c.angular_radps) == (0, 0)
                ),
                None,
            ),
            5.0,
        )
        time.sleep(0.5)
        later = base.commands(zero.rx_ns)
        assert len(later) >= 5 and all(c.linear_mps == 0.0 for c in later)
        assert none.reason == "no source fresh"
    finally:
        observer.close()


def test_a_bool_lock_stops_everything_and_a_silent_lock_stays_locked(graph, procs, tmp_path):
    base, feeds = graph
    feeds.set_lock(False)
    port = start_robot(procs, tmp_path, base, feeds)
    observer = Observer(port)
    try:
        feeds.nav_on.set()
        moving_at(base, V_NAV, 0, "navigation's speed on /cmd_vel")
        sent_ns = feeds.set_lock(True)
        locked = state_after(observer, "the lock", sent_ns, lambda s: s.lock == "pause")
        # On the robot's clock, the lock acted within 150 ms of being published.
        assert locked.stamp_ns - sent_ns < 150 * MS, (locked.stamp_ns - sent_ns) / MS
        assert (locked.state, locked.reason, locked.source) == ("HOLD", "lock pause: true", None)
        first_zero = base.wait_for(
            "a zero twist",
            lambda: next((c for c in base.commands(sent_ns) if c.linear_mps == 0.0), None),
            5.0,
        )
        time.sleep(1.0)
        after = base.commands(first_zero.rx_ns)
        assert len(after) >= 10 and all(c.linear_mps == 0.0 for c in after)

        released_ns = feeds.set_lock(False)
        free = state_after(observer, "released", released_ns, lambda s: s.lock is None)
        moving_at(base, V_NAV, free.stamp_ns, "navigation's speed after the release")

        # The heartbeat stops (a dead lock publisher): locked after its timeout, and it stays.
        feeds.lock_on.clear()
        last_beat_ns = feeds.last_lock_ns
        # After the state that showed the release: a 1 Hz state sent between publishing the
        # release and the robot taking it still says "lock pause: true" (CI run 26, load 5.5).
        silent = state_after(
            observer,
            "the silent lock",
            free.stamp_ns,
            lambda s: s.lock == "pause" and s.reason.startswith("lock pause: silent"),
        )
        assert silent.stamp_ns > last_beat_ns + 1000 * MS
        assert silent.reason.startswith("lock pause: silent for")
        time.sleep(0.3)
        stop_ns = time.monotonic_ns()
        time.sleep(2.0)
        held = base.commands(stop_ns)
        assert len(held) >= 20 and all(c.linear_mps == 0.0 for c in held)
        assert all(t.lock == "pause" for t in observer.telemetry() if t.stamp_ns >= stop_ns)
    finally:
        observer.close()
