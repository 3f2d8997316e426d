"""The pure half of the ROS 2 driver (DESIGN 11): settings, REP 117 scans, odometry, no rclpy.

``egc_robot.ros2_driver`` is the thin rclpy adapter; everything it decides lives here, so it is
unit-tested without ROS 2 installed.

Scans (``scan_from_laser``) follow REP 117:

- ``+inf``: no object within ``range_max`` on that beam. Free (REP 117 defines it so); dropped
  from the points, but it is information: a scan of nothing but ``+inf`` says "all free".
- ``NaN``: no information on that beam (unknown); dropped.
- ``-inf``: an object closer than ``range_min``: an obstacle *at* ``range_min``, kept; and, as
  the reading stays ``-inf`` however close the object comes, one more just outside the
  footprint on that beam, where it may be nearest (the robot may back away, not drive on).
- finite readings outside ``[range_min, range_max]`` (an older driver's "no return" code, 0.0,
  ``range_max + 1``): dropped, and not information.

A scan that carries no information at all (no valid reading, no ``-inf``, no ``+inf``: all NaN,
all out of range, or no beams) is rejected: the driver does not deliver it, so the robot's
sensor goes stale and it holds (``scan_timeout``). That is what lets the driver declare
``no_return_is_free`` for the scans it does deliver without ever taking "nothing seen" for
"free".

Any beam count, angular range and sweep direction (``angle_increment`` may be negative). The
laser's pose in the base frame {R} (``LaserPose``) is applied before filtering: beam angle
``a`` becomes ``yaw + a`` (``yaw - a`` when mounted upside down, which mirrors the laser's y
axis), and the point is offset by the mount position.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
from egc_common.cli_args import plain_float
from egc_common.footprint import Footprint
from egc_common.messages import Odometry
from egc_common.ros2_topics import (
    DEFAULT_CMD_TOPIC,
    DEFAULT_ODOM_TOPIC,
    DEFAULT_SCAN_TOPIC,
    default_topic,
)
from egc_common.scan import Scan, carries_information, too_close_readings

# Bounds on what a scan from the network may be; beyond them it is rejected, not processed.
MAX_BEAMS = 100_000
MAX_RANGE_M = 1e5
CMD_TYPES = ("twist", "twist-stamped")
ROS_TYPE_OF_CMD = {
    "twist": "geometry_msgs/msg/Twist",
    "twist-stamped": "geometry_msgs/msg/TwistStamped",
}
# The [ros2] keys of the robot TOML; flags of the same name (scan -> --ros-scan) override them.
ROS2_KEYS = ("scan", "odom", "cmd", "cmd_type", "namespace", "laser_pose", "laser_upside_down")

# ROS 2 topic and namespace names (design article "Topic and Service name mapping"): tokens of
# alphanumerics and underscores, not starting with a digit, separated by '/'; '~' and
# substitutions are not accepted here.
_TOKEN = r"[A-Za-z_][A-Za-z0-9_]*"
_TOPIC = re.compile(rf"^/?{_TOKEN}(/{_TOKEN})*$")
_NAMESPACE = re.compile(rf"^(/|/{_TOKEN}(/{_TOKEN})*)$")


@dataclass(frozen=True, slots=True)
class LaserPose:
    """Where the laser sits in the base frame {R}: position (m), yaw (rad), and whether it is
    mounted upside down (its y axis, and so its sweep, mirrored)."""

    x_m: float = 0.0
    y_m: float = 0.0
    yaw_rad: float = 0.0
    upside_down: bool = False

    def __post_init__(self) -> None:
        if not all(math.isfinite(v) for v in (self.x_m, self.y_m, self.yaw_rad)):
            raise ValueError("the laser pose must be finite")
        if max(abs(self.x_m), abs(self.y_m)) > 100.0:
            raise ValueError("the laser must be within 100 m of the base")


@dataclass(frozen=True, slots=True)
class Ros2Settings:
    """Topics, command type, namespace and laser mounting of ``--driver ros2`` (DESIGN 11)."""

    scan_topic: str = DEFAULT_SCAN_TOPIC
    odom_topic: str = DEFAULT_ODOM_TOPIC
    cmd_topic: str = DEFAULT_CMD_TOPIC
    cmd_type: str = "twist"
    namespace: str = ""
    laser: LaserPose = field(default_factory=LaserPose)

    def __post_init__(self) -> None:
        for what, topic in (
            ("scan", self.scan_topic),
            ("odom", self.odom_topic),
            ("cmd", self.cmd_topic),
        ):
            if not _TOPIC.match(topic):
                raise ValueError(f"ros2 {what} topic {topic!r} is not a valid ROS 2 topic name")
        if self.cmd_type not in CMD_TYPES:
            raise ValueError(f"ros2 cmd_type must be one of {', '.join(CMD_TYPES)}")
        namespace = normalise_namespace(self.namespace)
        object.__setattr__(self, "namespace", namespace)


def is_topic_name(name: str) -> bool:
    """A valid ROS 2 topic name (absolute or relative; no ``~`` or substitutions)."""
    return bool(_TOPIC.match(name))


def normalise_namespace(namespace: str) -> str:
    """A ROS 2 namespace as rclpy takes it (``robot1`` is ``/robot1``); ValueError if invalid."""
    if not namespace:
        return ""
    absolute = namespace if namespace.startswith("/") else "/" + namespace
    if not _NAMESPACE.match(absolute):
        raise ValueError(f"ros2 namespace {namespace!r} is not a valid ROS 2 namespace")
    return absolute


def parse_laser_pose(text: str) -> tuple[float, float, float]:
    """``X,Y,YAW`` (metres, metres, radians), e.g. ``-0.1,0,3.14159``; ValueError if not."""
    parts = text.split(",")
    try:
        values = tuple(plain_float(p) for p in parts)
    except ValueError:
        values = ()
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise ValueError(f"laser pose must be X,Y,YAW in metres and radians, got {text!r}")
    return values[0], values[1], values[2]


def ros2_settings(
    table: Mapping[str, Any],
    flags: Mapping[str, Any],
    default_laser_pose: tuple[float, float, float] | None = None,
) -> Ros2Settings:
    """Settings from the robot TOML's ``[ros2]`` table, overridden by flags that are not None.

    Both use the keys of ``ROS2_KEYS``; ``laser_pose`` is ``"X,Y,YAW"`` or a list of three
    numbers, and when neither gives one, ``default_laser_pose`` (the profile's ``laser_pose``,
    DESIGN 14), else 0, 0, 0. Raises ValueError with a message naming the key.
    """
    unknown = sorted(set(table) - set(ROS2_KEYS))
    if unknown:
        raise ValueError(
            f"unknown [ros2] key(s) {', '.join(unknown)} (known: {', '.join(ROS2_KEYS)})"
        )
    merged = dict(table)
    merged.update({k: v for k, v in flags.items() if v is not None})
    for key in ("scan", "odom", "cmd", "cmd_type", "namespace"):
        if key in merged and not isinstance(merged[key], str):
            raise ValueError(f"ros2 {key} must be a string, got {merged[key]!r}")
    pose_value = merged.get("laser_pose", default_laser_pose or (0.0, 0.0, 0.0))
    if isinstance(pose_value, str):
        pose = parse_laser_pose(pose_value)
    elif (
        isinstance(pose_value, (list, tuple))
        and len(pose_value) == 3
        and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in pose_value)
    ):
        pose = (float(pose_value[0]), float(pose_value[1]), float(pose_value[2]))
    else:
        raise ValueError(f"ros2 laser_pose must be 'X,Y,YAW' or [x, y, yaw], got {pose_value!r}")
    upside_down = merged.get("laser_upside_down", False)
    if not isinstance(upside_down, bool):
        raise ValueError(f"ros2 laser_upside_down must be true or false, got {upside_down!r}")
    namespace = merged.get("namespace", "")
    return Ros2Settings(
        scan_topic=merged.get("scan", default_topic(DEFAULT_SCAN_TOPIC, namespace)),
        odom_topic=merged.get("odom", default_topic(DEFAULT_ODOM_TOPIC, namespace)),
        cmd_topic=merged.get("cmd", default_topic(DEFAULT_CMD_TOPIC, namespace)),
        cmd_type=merged.get("cmd_type", "twist"),
        namespace=namespace,
        laser=LaserPose(pose[0], pose[1], pose[2], upside_down),
    )


@dataclass(frozen=True, slots=True)
class Rejected:
    """Why a LaserScan was not turned into a Scan (counted and logged by the driver)."""

    reason: str
    detail: str


def scan_from_laser(
    ranges_m: npt.ArrayLike,
    angle_min_rad: float,
    angle_increment_rad: float,
    range_min_m: float,
    range_max_m: float,
    pose: LaserPose,
    stamp_ns: int = 0,
    footprint_half_m: Footprint | tuple[float, float] | None = None,
) -> Scan | Rejected:
    """A ``sensor_msgs/LaserScan``'s fields as a Scan in {R} (REP 117; see the module docstring).

    With the footprint (the profile's shape), each ``-inf`` beam also gets a point just
    outside the footprint (``egc_common.scan.too_close_points``). Never raises on any input: a
    malformed or empty scan is a ``Rejected``.
    """
    try:
        r = np.array(ranges_m, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError) as exc:
        return Rejected("malformed", f"ranges are not numbers: {exc}")
    numbers = (angle_min_rad, angle_increment_rad, range_min_m, range_max_m)
    if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in numbers):
        return Rejected(
            "malformed", "angle_min, angle_increment, range_min, range_max must be finite"
        )
    if not 0.0 <= range_min_m < range_max_m <= MAX_RANGE_M:
        return Rejected(
            "malformed",
            f"needs 0 <= range_min < range_max <= {MAX_RANGE_M:g} m, got "
            f"[{range_min_m:g}, {range_max_m:g}]",
        )
    if r.size > MAX_BEAMS:
        return Rejected("malformed", f"{r.size} beams (at most {MAX_BEAMS})")
    beam_angles = angle_min_rad + angle_increment_rad * np.arange(r.size, dtype=np.float64)
    if r.size and not (np.all(np.isfinite(beam_angles)) and np.abs(beam_angles).max() <= 1e3):
        return Rejected("malformed", "beam angles are not finite")
    sign = -1.0 if pose.upside_down else 1.0
    angles = pose.yaw_rad + sign * beam_angles
    r, extra = too_close_readings(r, angles, range_min_m, pose.x_m, pose.y_m, footprint_half_m)
    if not carries_information(r, range_min_m, range_max_m):
        return Rejected(
            "no_information", f"{r.size} beams, none valid, none +inf (all NaN or out of range)"
        )
    return Scan(
        angles,
        r,
        float(range_min_m),
        float(range_max_m),
        stamp_ns=stamp_ns,
        no_return_is_free=True,  # scans with no information at all were rejected above
        mount_x_m=pose.x_m,
        mount_y_m=pose.y_m,
        extra_xy_m=extra,
    )


_DIRECTIONS = (
    ("ahead", 0.0),
    ("left", 0.5 * math.pi),
    ("behind", math.pi),
    ("right", -0.5 * math.pi),
)


def blind_directions(angles_rad: npt.ArrayLike) -> list[str]:
    """Which of ahead, left, behind and right no beam of a scan looks at (beam angles in {R};
    a direction counts as seen within 1.5 beam gaps of a beam), for the driver's one line
    about it (README, "what the laser does not look at")."""
    a = np.sort(np.mod(np.asarray(angles_rad, dtype=np.float64).reshape(-1), 2.0 * math.pi))
    if a.size < 2:
        return [name for name, _ in _DIRECTIONS]
    gaps = np.diff(np.concatenate((a, [a[0] + 2.0 * math.pi])))
    tolerance = 1.5 * float(np.median(gaps))
    blind = []
    for name, direction in _DIRECTIONS:
        d = np.abs(np.mod(a - direction + math.pi, 2.0 * math.pi) - math.pi)
        if float(d.min()) > tolerance:
            blind.append(name)
    return blind


def unseen_directions(scan: Scan) -> list[str]:
    """``blind_directions``, plus ahead or behind where the robot's own reach along its axis
    (``Scan.obstacles``: seen from where the laser sits) stops short of range_max: a laser
    mounted off the origin can look at a direction from the origin and still not see the axis
    there (a 270-degree laser at (0.2, 0.2), yawed 45 degrees, sees nothing straight behind)."""
    blind = blind_directions(scan.angles_rad)
    points = scan.obstacles()
    for name, seen_m, full_m in (
        ("ahead", points.seen_ahead_m, scan.range_max_m + scan.mount_x_m),
        ("behind", points.seen_behind_m, scan.range_max_m - scan.mount_x_m),
    ):
        if seen_m < full_m and name not in blind:
            blind.append(name)
    return blind


def cmd_topic_warning(topic: str, cmd_type: str, subscriber_types: Sequence[str]) -> str | None:
    """What is wrong with who listens to our command topic, in one line (None: a subscriber
    takes our type). ROS 2 does not connect a publisher and a subscriber of different types, so
    a base that wants TwistStamped never sees our Twist, and no error says so anywhere."""
    ours = ROS_TYPE_OF_CMD[cmd_type]
    if ours in subscriber_types:
        return None
    if not subscriber_types:
        return (
            f"nobody subscribes to {topic}: no base will move (is the base driver running, in "
            "this namespace and ROS_DOMAIN_ID? `ros2 topic info -v` shows who listens)"
        )
    theirs = sorted(set(subscriber_types))
    fix = [name for name, ros in ROS_TYPE_OF_CMD.items() if ros in theirs]
    hint = f": run with --ros-cmd-type {fix[0]} (or cmd_type in [ros2])" if fix else ""
    return (
        f"the base subscribes to {topic} as {' and '.join(theirs)} but this robot publishes "
        f"{ours}, which ROS 2 does not deliver to it{hint}"
    )


def yaw_from_quaternion(x: float, y: float, z: float, w: float) -> float:
    """The yaw (rad, about +z) of a rotation quaternion; NaN if it is not a finite, non-zero one."""
    if not all(math.isfinite(v) for v in (x, y, z, w)) or x * x + y * y + z * z + w * w < 1e-12:
        return math.nan
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def quaternion_from_yaw(yaw_rad: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation by ``yaw_rad`` about +z."""
    return 0.0, 0.0, math.sin(yaw_rad / 2.0), math.cos(yaw_rad / 2.0)


def odometry_from_ros(
    x_m: float,
    y_m: float,
    orientation_xyzw: tuple[float, float, float, float],
    linear_mps: float,
    angular_radps: float,
    rx_ns: int,
) -> Odometry | Rejected:
    """A ``nav_msgs/Odometry``'s pose and (body-frame) twist as our Odometry, stamped with its
    arrival time on the robot's clock; a Rejected("malformed_odometry") if not finite."""
    theta = yaw_from_quaternion(*orientation_xyzw)
    values = (x_m, y_m, theta, linear_mps, angular_radps)
    if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in values):
        return Rejected("malformed_odometry", "odometry pose or twist is not finite")
    return Odometry(
        stamp_ns=rx_ns,
        x_m=float(x_m),
        y_m=float(y_m),
        theta_rad=theta,
        linear_mps=float(linear_mps),
        angular_radps=float(angular_radps),
    )


def command_is_finite(linear_mps: float, angular_radps: float) -> bool:
    """Whether a velocity may go on the wire (a bug upstream must not put NaN on /cmd_vel)."""
    return math.isfinite(linear_mps) and math.isfinite(angular_radps)
