"""ROS 2 logs the replay tests write themselves with rosbags' writer (MCAP or sqlite3).

``corridor_log`` is a robot driving straight at a wall: 360-beam scans over a full turn, the
wall ahead at ``wall_m[i]`` in scan ``i`` (beams that miss it read ``+inf``, REP 117's "free"),
a few ``NaN`` beams behind, and the commanded velocity either on a Twist (or TwistStamped) topic
or only as odometry poses, whose twist is left in a world frame turned by ``world_yaw_rad`` (as
Stage's ground truth is), so only the poses give the forward speed. ``scan_at`` puts another
scan (``garbled_ranges``: what a damaged storage file deserializes to) in place of scan ``i``,
or leaves it out; ``command_at`` does the same for the command written with scan ``i`` (raw
bytes: a damaged record).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

TS = get_typestore(Stores.ROS2_JAZZY)
T = TS.types
PERIOD_NS = 100_000_000  # 10 Hz
START_NS = 1_700_000_000_000_000_000
BEAMS = 360
STORAGE = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}


def _header(stamp_ns: int, frame: str):
    return T["std_msgs/msg/Header"](
        T["builtin_interfaces/msg/Time"](stamp_ns // 10**9, stamp_ns % 10**9), frame
    )


def _vec(x: float = 0.0, y: float = 0.0, z: float = 0.0):
    return T["geometry_msgs/msg/Vector3"](x, y, z)


def wall_ranges(wall_m: float, beams: int = BEAMS, nan_beams: int = 4) -> np.ndarray:
    """A flat wall across the path at ``wall_m`` ahead (beams within 60 degrees of forward
    hit it), ``+inf`` elsewhere, and ``nan_beams`` NaN beams straight behind."""
    a = -math.pi + 2 * math.pi * np.arange(beams) / beams
    r = np.full(beams, np.inf)
    ahead = np.abs(a) < math.radians(60)
    r[ahead] = wall_m / np.cos(a[ahead])
    r[:nan_beams] = np.nan
    return r.astype(np.float32)


def garbled_ranges(beams: int = BEAMS, seed: int = 7) -> np.ndarray:
    """Random bytes read as float32 ranges, as a log with bytes written over its middle gives:
    huge and tiny values of either sign, NaNs, and a signalling NaN (whose cast to float64 is
    numpy's "invalid value" warning) at beam 0."""
    raw = np.random.default_rng(seed).integers(0, 256, 4 * beams, dtype=np.uint8)
    r = raw.view(np.float32).copy()
    r.view(np.uint32)[0] = 0x7F800001  # signalling NaN
    return r


def scan_msg(
    stamp_ns: int, ranges: np.ndarray, range_max_m: float = 8.0, angle_min_rad: float = -math.pi
):
    n = len(ranges)
    return T["sensor_msgs/msg/LaserScan"](
        _header(stamp_ns, "laser"),
        angle_min_rad,
        angle_min_rad + 2 * math.pi - 2 * math.pi / n,
        2 * math.pi / n,
        0.0,
        0.1,
        0.05,
        range_max_m,
        np.asarray(ranges, dtype=np.float32),
        np.zeros(0, dtype=np.float32),
    )


def corridor_log(
    path: Path,
    storage: str = "mcap",
    wall_m: Sequence[float] = tuple(np.linspace(2.5, 0.3, 30)),
    v_mps: float = 0.12,
    command: str = "twist",  # "twist", "twist-stamped" or "odometry"
    world_yaw_rad: float = 1.0,
    scan_topic: str = "/scan",
    scan_at: Mapping[int, object | None]
    | None = None,  # scan i: this LaserScan (or raw bytes), or none
    command_at: Mapping[int, bytes | None] | None = None,  # command i: these bytes, or none
) -> Path:
    """Write the log; returns ``path`` (a bag directory)."""
    with Writer(path, version=9, storage_plugin=STORAGE[storage]) as w:
        scans = w.add_connection(scan_topic, "sensor_msgs/msg/LaserScan", typestore=TS)
        if command == "twist":
            cmd = w.add_connection("/cmd_vel", "geometry_msgs/msg/Twist", typestore=TS)
        elif command == "twist-stamped":
            cmd = w.add_connection("/cmd_vel", "geometry_msgs/msg/TwistStamped", typestore=TS)
        else:
            cmd = w.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=TS)
        for i, wall in enumerate(wall_m):
            t = START_NS + i * PERIOD_NS
            twist = T["geometry_msgs/msg/Twist"](_vec(v_mps), _vec())
            if command_at is not None and i in command_at:
                raw_cmd = command_at[i]
                if raw_cmd is not None:
                    w.write(cmd, t - 1000, raw_cmd)
            elif command == "twist":
                w.write(cmd, t - 1000, TS.serialize_cdr(twist, "geometry_msgs/msg/Twist"))
            elif command == "twist-stamped":
                msg = T["geometry_msgs/msg/TwistStamped"](_header(t, "base_link"), twist)
                w.write(cmd, t - 1000, TS.serialize_cdr(msg, "geometry_msgs/msg/TwistStamped"))
            else:
                w.write(cmd, t, odometry(t, i * v_mps * PERIOD_NS / 1e9, world_yaw_rad, v_mps))
            msg = scan_msg(t, wall_ranges(wall))
            if scan_at is not None and i in scan_at:
                msg = scan_at[i]
                if msg is None:
                    continue
            raw = (
                msg
                if isinstance(msg, bytes)
                else TS.serialize_cdr(msg, "sensor_msgs/msg/LaserScan")
            )
            w.write(scans, t, raw)  # bytes: a record as damaged as they are
    return path


def odometry(stamp_ns: int, travelled_m: float, yaw_rad: float, v_mps: float) -> bytes:
    """An odometry message at ``travelled_m`` along heading ``yaw_rad``; its twist is the
    world-frame velocity (as Stage's ground truth reports it), not the robot's."""
    pose = T["geometry_msgs/msg/Pose"](
        T["geometry_msgs/msg/Point"](
            travelled_m * math.cos(yaw_rad), travelled_m * math.sin(yaw_rad), 0.0
        ),
        T["geometry_msgs/msg/Quaternion"](0.0, 0.0, math.sin(yaw_rad / 2), math.cos(yaw_rad / 2)),
    )
    cov = np.zeros(36, dtype=np.float64)
    world_twist = T["geometry_msgs/msg/Twist"](
        _vec(v_mps * math.cos(yaw_rad), v_mps * math.sin(yaw_rad)), _vec()
    )
    msg = T["nav_msgs/msg/Odometry"](
        _header(stamp_ns, "odom"),
        "base_link",
        T["geometry_msgs/msg/PoseWithCovariance"](pose, cov),
        T["geometry_msgs/msg/TwistWithCovariance"](world_twist, cov),
    )
    return TS.serialize_cdr(msg, "nav_msgs/msg/Odometry")
