"""The ROS 2 driver: the robot process as the ROS 2 node ``egc_teleop`` (DESIGN 11, issue 14).

Behind the Driver seam (``egc_robot.drivers``), like the Zenoh driver: the robot's loop polls it
once per control cycle and sends it one command per cycle. The operator link stays Zenoh.
Besides the fixed-rate cycles and those on each accepted command, the robot runs a cycle on
each accepted scan (``set_scan_listener``), so a scan acts on ``/cmd_vel`` within one pipeline
run rather than at the next deadline (up to 50 ms later at 20 Hz; bench/bench_ros2.py).

- ``sensor_msgs/LaserScan`` on ``--ros-scan`` (default ``/scan``) and ``nav_msgs/Odometry`` on
  ``--ros-odom`` (``/odom``), sensor-data QoS (best effort, keep last 5; it also receives reliable
  publishers). Scans become Scans in {R} by ``egc_robot.ros2_core.scan_from_laser`` (REP 117, the
  laser pose, upside-down mounting), in the executor's thread, so the command path finds them
  ready. What arrives is stamped with its *arrival* time on the robot's monotonic clock: the
  watchdog judges freshness by that, never by the sensor's header stamp.
- ``geometry_msgs/Twist`` (or ``TwistStamped``, frame ``base_link``, stamped now) on
  ``--ros-cmd`` (``/cmd_vel``), reliable, keep last 10, every control cycle; in HOLD and ESTOP the
  controller's zero (or decelerating) command goes out like any other. ``close()`` publishes one
  last zero twist and waits (at most 3.5 s) for the subscribers to acknowledge it before the node
  goes.
- The rclpy executor spins in its own thread (``egc_common.executor_thread``). ``poll`` and
  ``send`` never wait on it: ``poll`` swaps two references under a lock the callbacks hold for
  no longer; ``send`` publishes. ``close`` destroys the node only once that thread is out.
- Nothing received can raise out of a callback: malformed scans and odometry are counted by
  reason and logged (rate-limited).

- Command sources and locks (DESIGN 14, ``_Ros2Inputs``): a ``ros2`` source's Twist or
  TwistStamped topic (e.g. ``/cmd_vel_nav``; sensor-data QoS, which also receives reliable
  publishers) and a lock's ``std_msgs/Bool`` topic (reliable, keep last 10: a best-effort lock
  publisher does not match, so that lock stays silent, which locks). Each message goes to the
  listeners the robot sets (``set_input_listeners``) with its arrival time, in the executor's
  thread; malformed ones are counted and logged like scans.

``ROS_DOMAIN_ID``, ``RMW_IMPLEMENTATION`` and ``ROS_AUTOMATIC_DISCOVERY_RANGE`` are read by ROS 2
itself, as ROS users expect. This module and ``egc_sim.ros2_base`` are the only ones importing
rclpy (tests/test_layout.py); without it, ``require_rclpy`` raises a UsageError naming the extra.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from collections.abc import Callable
from typing import Any

import numpy as np
import numpy.typing as npt
from egc_common.errors import UsageError
from egc_common.executor_thread import ExecutorThread
from egc_common.footprint import Footprint
from egc_common.messages import BaseCommand, Odometry
from egc_common.scan import Scan

from egc_robot.drivers import SensorUpdate
from egc_robot.ros2_core import (
    Rejected,
    Ros2Settings,
    cmd_topic_warning,
    command_is_finite,
    odometry_from_ros,
    scan_from_laser,
    unseen_directions,
)
from egc_robot.ros2_image import rgb_from_compressed, rgb_from_image
from egc_robot.source_mux import LockSpec, SourceSpec

log = logging.getLogger("egc.robot.ros2")

NODE_NAME = "egc_teleop"
MISSING_RCLPY = (
    "--driver ros2 needs ROS 2's rclpy: pip install -e '.[ros2]' (the ros2 extra), or create the "
    "venv with --system-site-packages from a shell with a sourced ROS 2"
)
# Fast DDS acknowledges a reliable sample on its heartbeat schedule, not when it arrives (that
# takes milliseconds): 0.98 s in 11 of 14 trials here, 2.96 s in 2, over 1 s in 2 of 6 with a
# 1 s wait, which then warned of a zero twist the base had long received. Shutdown waits for the
# acknowledgement at most this long.
_ACK_TIMEOUT_S = 3.5
# Discovery takes a moment: "nobody subscribes to /cmd_vel" is said only after this long.
_DISCOVERY_GRACE_NS = 3_000_000_000
# Header stamps within this of our ROS clock at arrival mean the sensor's clock agrees with ours.
_CLOCKS_AGREE_NS = 1_000_000_000
# The executor's thread leaves within one wait (0.1 s) plus the callback in progress (a robot
# cycle, milliseconds); past this, something is stuck in a callback and the node stays.
_STOP_PATIENCE_S = 10.0


def require_rclpy() -> None:
    """Raise UsageError (one line naming the extra) unless rclpy and the messages import."""
    try:
        import geometry_msgs.msg  # noqa: F401
        import nav_msgs.msg  # noqa: F401
        import rclpy  # noqa: F401
        import sensor_msgs.msg  # noqa: F401
    except ImportError as exc:
        raise UsageError(f"{MISSING_RCLPY} ({exc})") from None


class Ros2Driver:
    """The Driver of ``egc-teleop robot --driver ros2`` (see the module docstring)."""

    def __init__(
        self,
        settings: Ros2Settings,
        node_name: str = NODE_NAME,
        footprint_half_m: Footprint | tuple[float, float] | None = None,
        camera_topic: str | None = None,
        sources: tuple[SourceSpec, ...] = (),
        locks: tuple[LockSpec, ...] = (),
    ) -> None:
        """``footprint_half_m``: the profile's footprint (or a centred rectangle's half sizes),
        for ``-inf`` readings; ``camera_topic``: an image topic for ``--camera ros2:TOPIC``
        (``newest_image``); ``sources`` and ``locks``: the ``ros2`` ones of DESIGN 14
        (``set_input_listeners``)."""
        self._footprint_half_m = footprint_half_m
        self._coverage_logged = False
        require_rclpy()
        import rclpy
        from geometry_msgs.msg import Twist, TwistStamped
        from nav_msgs.msg import Odometry as OdometryMsg
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
        from rclpy.signals import SignalHandlerOptions
        from sensor_msgs.msg import LaserScan

        self.settings = settings
        self._lock = threading.Lock()
        self._scan: Scan | None = None
        self._scan_rx_ns = 0
        self._odometry: Odometry | None = None
        self.rejected: Counter[str] = Counter()
        self.scans_received = 0
        self._header_age_ns: int | None = None
        self._send_lock = threading.Lock()
        self._closed = False
        self._stamped = settings.cmd_type == "twist-stamped"
        self._twist_type: Any = TwistStamped if self._stamped else Twist
        self._scan_listener: Callable[[], None] | None = None
        self._cmd_warning: str | None = None
        self._started_ns = time.monotonic_ns()
        self._camera: _Ros2Camera | None = None
        self._inputs: _Ros2Inputs | None = None

        # Our own context: rclpy installs no signal handlers (the robot process owns SIGINT and
        # SIGTERM, to send the last zero twist) and nothing global is touched.
        self._context = Context()
        rclpy.init(context=self._context, signal_handler_options=SignalHandlerOptions.NO)
        try:
            self._node = rclpy.create_node(
                node_name, namespace=settings.namespace or None, context=self._context
            )
            node = self._node
            self._publisher = node.create_publisher(
                self._twist_type,
                settings.cmd_topic,
                QoSProfile(  # type: ignore[no-untyped-call]
                    depth=10,
                    history=HistoryPolicy.KEEP_LAST,
                    reliability=ReliabilityPolicy.RELIABLE,
                ),
            )
            node.create_subscription(
                LaserScan, settings.scan_topic, self._on_scan, qos_profile_sensor_data
            )
            node.create_subscription(
                OdometryMsg, settings.odom_topic, self._on_odometry, qos_profile_sensor_data
            )
            if camera_topic is not None:
                self._camera = _Ros2Camera(node, camera_topic)
            if sources or locks:
                self._inputs = _Ros2Inputs(node, sources, locks)
            self._cmd_topic = node.resolve_topic_name(settings.cmd_topic)
            node.create_timer(1.0, self._check_cmd_subscribers)
            self._executor = SingleThreadedExecutor(context=self._context)
            self._executor.add_node(node)
        except Exception:
            self._context.try_shutdown()
            raise
        self._spinner = ExecutorThread(self._executor, self._on_executor_error)
        self._spinner.start()
        log.info(
            "ROS 2 node %s: scans %s, odometry %s, commands %s (%s); laser at %s",
            node.get_fully_qualified_name(),
            node.resolve_topic_name(settings.scan_topic),
            node.resolve_topic_name(settings.odom_topic),
            node.resolve_topic_name(settings.cmd_topic),
            settings.cmd_type,
            settings.laser,
        )

    # -- the executor's thread --------------------------------------------------------------------

    def _on_executor_error(self, exc: Exception) -> None:
        log.error("ROS 2 executor stopped: %s", exc)

    def _on_scan(self, msg: Any) -> None:
        rx_ns = time.monotonic_ns()
        try:
            result = scan_from_laser(
                msg.ranges,
                msg.angle_min,
                msg.angle_increment,
                msg.range_min,
                msg.range_max,
                self.settings.laser,
                stamp_ns=rx_ns,
                footprint_half_m=self._footprint_half_m,
            )
            if isinstance(result, Rejected):
                self._count(result, "scan")
                return
            result.obstacles()  # prepared here, off the command path
            if not self._coverage_logged:
                self._coverage_logged = True
                blind = unseen_directions(result)
                if blind:
                    log.warning(
                        "the laser does not look %s: in shared mode the robot will not drive "
                        "straight into what it does not see (README: mount it to cover the "
                        "directions you drive in)",
                        " or ".join(blind),
                    )
            age_ns = self._node.get_clock().now().nanoseconds - (
                msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            )
        except Exception as exc:  # never out of a callback
            self._count(Rejected("malformed", repr(exc)), "scan")
            return
        with self._lock:
            self._scan, self._scan_rx_ns = result, rx_ns
            self.scans_received += 1
            self._header_age_ns = age_ns if abs(age_ns) <= _CLOCKS_AGREE_NS else None
            listener = self._scan_listener
        if listener is not None:
            try:
                listener()
            except Exception as exc:  # never out of a callback
                log.error("scan listener failed: %s", exc)

    def _check_cmd_subscribers(self) -> None:
        """Say (once per change) when no subscriber of ``/cmd_vel`` takes our message type."""
        try:
            infos = self._node.get_subscriptions_info_by_topic(self._cmd_topic)
            warning = cmd_topic_warning(
                self._cmd_topic, self.settings.cmd_type, [i.topic_type for i in infos]
            )
        except Exception as exc:  # never out of a callback
            log.debug("could not list the subscribers of %s: %s", self._cmd_topic, exc)
            return
        young = time.monotonic_ns() - self._started_ns < _DISCOVERY_GRACE_NS
        if warning == self._cmd_warning or (young and not infos):
            return
        if warning is not None:
            log.warning("%s", warning)
        elif self._cmd_warning is not None:
            log.info("%s now has a subscriber of our message type", self._cmd_topic)
        self._cmd_warning = warning

    def _on_odometry(self, msg: Any) -> None:
        rx_ns = time.monotonic_ns()
        try:
            pose, twist = msg.pose.pose, msg.twist.twist
            q = pose.orientation
            result = odometry_from_ros(
                pose.position.x,
                pose.position.y,
                (q.x, q.y, q.z, q.w),
                twist.linear.x,
                twist.angular.z,
                rx_ns,
            )
        except Exception as exc:
            result = Rejected("malformed_odometry", repr(exc))
        if isinstance(result, Rejected):
            self._count(result, "odometry")
            return
        with self._lock:
            self._odometry = result

    def _count(self, rejection: Rejected, what: str) -> None:
        with self._lock:
            self.rejected[rejection.reason] += 1
            n = self.rejected[rejection.reason]
        if n == 1 or n % 100 == 0:
            log.warning(
                "dropped %s (%s, %d so far): %s", what, rejection.reason, n, rejection.detail
            )

    # -- the Driver seam (the robot's loop) -------------------------------------------------------

    def set_scan_listener(self, listener: Callable[[], None] | None) -> None:
        """Call ``listener`` (in the executor's thread) after each accepted scan, so that the
        robot runs a cycle on it at once instead of at its next deadline (up to one period)."""
        with self._lock:
            self._scan_listener = listener

    def set_input_listeners(
        self,
        on_velocity: Callable[[str, float, float, int], None],
        on_lock: Callable[[str, bool, int], None],
    ) -> None:
        """DESIGN 14: ``on_velocity(source, v_mps, w_radps, rx_ns)`` for each ``ros2`` source's
        message and ``on_lock(lock, value, rx_ns)`` for each lock's, in the executor's thread."""
        if self._inputs is not None:
            self._inputs.set_listeners(on_velocity, on_lock)

    @property
    def header_age_ms(self) -> float | None:
        """Age of the newest scan from its header stamp at arrival, when the clocks agree."""
        with self._lock:
            age = self._header_age_ns
        return None if age is None else age / 1e6

    def newest_image(self) -> tuple[npt.NDArray[np.uint8], int] | None:
        """``--camera ros2:TOPIC``: the newest image as RGB and its arrival time (the robot's
        monotonic clock), or None (no camera topic, nothing yet, or it did not convert)."""
        return None if self._camera is None else self._camera.newest()

    def poll(self, now_ns: int) -> SensorUpdate:
        with self._lock:
            scan, rx_ns, odometry = self._scan, self._scan_rx_ns, self._odometry
            self._scan, self._odometry = None, None
        return SensorUpdate(scan=scan, scan_rx_ns=rx_ns, odometry=odometry)

    def send(self, command: BaseCommand) -> None:
        v, w = command.linear_mps, command.angular_radps
        if not command_is_finite(v, w):
            v, w = 0.0, 0.0
        with self._send_lock:
            if not self._closed:
                self._publish(v, w)

    def _publish(self, linear_mps: float, angular_radps: float) -> None:
        msg = self._twist_type()
        twist = msg.twist if self._stamped else msg
        twist.linear.x = float(linear_mps)
        twist.angular.z = float(angular_radps)
        if self._stamped:
            msg.header.frame_id = "base_link"
            msg.header.stamp = self._node.get_clock().now().to_msg()
        self._publisher.publish(msg)

    def close(self) -> None:
        """One last zero twist, acknowledged by the subscribers if they do so within 3.5 s (a
        base that keeps its last command must not drive on), then the node goes, once the
        executor's thread is out."""
        from rclpy.duration import Duration

        with self._send_lock:
            if self._closed:
                return
            try:
                self._publish(0.0, 0.0)
                acked = self._publisher.wait_for_all_acked(Duration(seconds=_ACK_TIMEOUT_S))
                if not acked and self._publisher.get_subscription_count():
                    log.warning(
                        "the last zero twist was not acknowledged within %.1f s", _ACK_TIMEOUT_S
                    )
            except Exception as exc:
                log.error("could not send the last zero twist: %s", exc)
            self._closed = True
        with self._lock:
            rejected = dict(self.rejected)
            scans = self.scans_received
            age = self._header_age_ns
        log.info(
            "ROS 2 driver closed: %d scans, dropped %s, header age of the last scan %s",
            scans,
            rejected or "none",
            "unknown (the sensor's clock is not ours)" if age is None else f"{age / 1e6:.1f} ms",
        )
        # The executor's thread must be out before the node goes: destroying a node under a
        # running wait crashed the process (issue 31). Still inside: leave it all to the exit.
        if not self._spinner.stop(_STOP_PATIENCE_S):
            log.error(
                "the ROS 2 executor thread did not stop within %.0f s (a callback that does not "
                "return); the node is left to the process's exit",
                _STOP_PATIENCE_S,
            )
            return
        try:
            self._executor.shutdown()
            self._node.destroy_node()  # type: ignore[no-untyped-call]
        finally:
            self._context.try_shutdown()


_IMAGE_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")


class _Ros2Camera:
    """``--camera ros2:TOPIC`` (DESIGN 12): the topic's type (``sensor_msgs/Image`` or
    ``CompressedImage``) is taken from the ROS graph, looked up every 0.5 s until a publisher
    appears, then subscribed with sensor-data QoS. The executor's thread only keeps the newest
    message; it is converted (``egc_robot.ros2_image``) when the camera's thread asks for it,
    so a large image never holds back a scan. Bad images are counted by reason and logged."""

    def __init__(self, node: Any, topic: str) -> None:
        from rclpy.qos import qos_profile_sensor_data
        from sensor_msgs.msg import CompressedImage, Image

        self._node = node
        self._topic = node.resolve_topic_name(topic)
        self._qos = qos_profile_sensor_data
        self._classes = {_IMAGE_TYPES[0]: Image, _IMAGE_TYPES[1]: CompressedImage}
        self._lock = threading.Lock()
        self._latest: tuple[Any, int] | None = None
        self._converted: tuple[Any, tuple[npt.NDArray[np.uint8], int] | None] | None = None
        self._subscription: Any = None
        self._wrong_type_said = False
        self.received = 0
        self.rejected: Counter[str] = Counter()
        self._timer = node.create_timer(0.5, self._discover)
        self._discover()

    def _discover(self) -> None:
        try:
            if self._subscription is not None:
                return
            for name, types in self._node.get_topic_names_and_types():
                if name != self._topic:
                    continue
                found = [t for t in types if t in self._classes]
                if found:
                    cls = self._classes[found[0]]
                    self._subscription = self._node.create_subscription(
                        cls, self._topic, self._on_image, self._qos
                    )
                    self._timer.cancel()
                    log.info("camera: %s (%s)", self._topic, found[0])
                elif not self._wrong_type_said:
                    self._wrong_type_said = True
                    log.warning(
                        "camera topic %s is %s, not sensor_msgs/Image or CompressedImage",
                        self._topic,
                        ", ".join(types),
                    )
        except Exception as exc:  # never out of a callback
            log.debug("camera topic lookup failed: %s", exc)

    def _on_image(self, msg: Any) -> None:
        rx_ns = time.monotonic_ns()
        with self._lock:
            self._latest = (msg, rx_ns)
            self.received += 1

    def newest(self) -> tuple[npt.NDArray[np.uint8], int] | None:
        with self._lock:
            latest = self._latest
        if latest is None:
            return None
        if self._converted is not None and self._converted[0] is latest:
            return self._converted[1]
        msg, rx_ns = latest
        if hasattr(msg, "format"):  # CompressedImage
            result = rgb_from_compressed(str(msg.format), msg.data)
        else:
            result = rgb_from_image(
                str(msg.encoding), msg.width, msg.height, msg.step, msg.is_bigendian, msg.data
            )
        out = None
        if isinstance(result, Rejected):
            self.rejected[result.reason] += 1
            n = self.rejected[result.reason]
            if n == 1 or n % 100 == 0:
                log.warning(
                    "dropped camera image (%s, %d so far): %s", result.reason, n, result.detail
                )
        else:
            out = (result, rx_ns)
        self._converted = (latest, out)
        return out


class _Ros2Inputs:
    """The ``ros2`` command sources and ROS 2 locks of DESIGN 14 (see the module docstring).

    Only what arrived, and when (the robot's monotonic clock), goes to the listeners: whether it
    is valid and what it means is the controller's judgement. A source's message carries the
    forward speed (``linear.x``) and the turn rate (``angular.z``) of a differential drive; the
    other components are not ours to follow and are said once in the log when not zero."""

    def __init__(
        self, node: Any, sources: tuple[SourceSpec, ...], locks: tuple[LockSpec, ...]
    ) -> None:
        from geometry_msgs.msg import Twist, TwistStamped
        from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data

        self._lock = threading.Lock()
        self._on_velocity: Callable[[str, float, float, int], None] | None = None
        self._on_lock: Callable[[str, bool, int], None] | None = None
        self.rejected: Counter[str] = Counter()
        self._said_holonomic: set[str] = set()
        for source in sources:
            stamped = source.cmd_type == "twist-stamped"
            node.create_subscription(
                TwistStamped if stamped else Twist,
                source.topic,
                lambda msg, n=source.name, st=stamped: self._on_twist(n, st, msg),
                qos_profile_sensor_data,
            )
        if locks:
            try:
                from std_msgs.msg import Bool
            except ImportError as exc:
                raise UsageError(
                    f"ROS 2 locks need std_msgs (pip install ros-jazzy-std-msgs): {exc}"
                ) from None
            reliable = QoSProfile(  # type: ignore[no-untyped-call]
                depth=10, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE
            )
            for lock in locks:
                node.create_subscription(
                    Bool, lock.topic, lambda msg, n=lock.name: self._on_bool(n, msg), reliable
                )
        log.info(
            "ROS 2 command sources %s, locks %s",
            ", ".join(f"{s.name} {node.resolve_topic_name(s.topic)}" for s in sources) or "none",
            ", ".join(f"{lk.name} {node.resolve_topic_name(lk.topic)}" for lk in locks) or "none",
        )

    def set_listeners(
        self,
        on_velocity: Callable[[str, float, float, int], None],
        on_lock: Callable[[str, bool, int], None],
    ) -> None:
        with self._lock:
            self._on_velocity, self._on_lock = on_velocity, on_lock

    def _on_twist(self, name: str, stamped: bool, msg: Any) -> None:
        rx_ns = time.monotonic_ns()
        try:
            twist = msg.twist if stamped else msg
            v, w = float(twist.linear.x), float(twist.angular.z)
            other = (twist.linear.y, twist.linear.z, twist.angular.x, twist.angular.y)
            if any(c != 0.0 for c in other) and name not in self._said_holonomic:
                self._said_holonomic.add(name)
                log.warning(
                    "source %s sends velocity components a differential drive does not take "
                    "(linear y/z, angular x/y): only linear.x and angular.z are followed",
                    name,
                )
        except Exception as exc:  # never out of a callback
            self._count(name, repr(exc))
            return
        with self._lock:
            listener = self._on_velocity
        if listener is not None:
            try:
                listener(name, v, w, rx_ns)
            except Exception as exc:
                log.error("source listener failed: %s", exc)

    def _on_bool(self, name: str, msg: Any) -> None:
        rx_ns = time.monotonic_ns()
        try:
            value = msg.data
            if not isinstance(value, bool):
                raise TypeError(f"data is {type(value).__name__}")
        except Exception as exc:
            self._count(name, repr(exc))
            return
        with self._lock:
            listener = self._on_lock
        if listener is not None:
            try:
                listener(name, value, rx_ns)
            except Exception as exc:
                log.error("lock listener failed: %s", exc)

    def _count(self, name: str, detail: str) -> None:
        with self._lock:
            self.rejected[name] += 1
            n = self.rejected[name]
        if n == 1 or n % 100 == 0:
            log.warning("dropped a message of %s (%d so far): %s", name, n, detail)
