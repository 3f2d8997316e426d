"""An episode written as a ROS 2 log (issue 28): what a robot's recorder would have kept.

``EpisodeBag(path)`` writes, one ``BagStep`` per control cycle, with the simulator's time as
both the log (receive) time and the header stamp:

- ``/scan`` ``sensor_msgs/msg/LaserScan`` (frame ``laser``, at the robot's centre as in the
  simulator): the scan the robot's pipeline used in that cycle, REP 117 (``+inf`` no return);
- ``/odom`` ``nav_msgs/msg/Odometry`` (``odom`` -> ``base_link``): the simulator's odometry pose
  and the base's actual body twist at the start of the cycle;
- ``/cmd_vel`` ``geometry_msgs/msg/Twist``: what the driver asked for (the stick after eq. 4,
  *before* any filter), as a log of a person driving the robot directly records it. Written
  before the scan of the same cycle, so that a replay (``egc-teleop replay``, DESIGN 11) pairs
  each scan with the command it was driven with.

The topics, frames and message types are those of ``egc-teleop sim --ros2`` (DESIGN 11), so the
log reads like one recorded there. ``path`` ending in ``.mcap`` is a single MCAP file (what is
usually shared); anything else becomes a ROS 2 bag directory (``metadata.yaml`` and one MCAP
file), as ``ros2 bag record -s mcap -o PATH`` makes. Both are written with the ``rosbags``
library (no ROS install); an existing ``path`` is never overwritten (``BagError``).

This is an adapter (DESIGN 2: files are IO): the episode loop hands it its per-cycle records
and it only converts and writes.
"""

from __future__ import annotations

import math
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np
from egc_common.scan import Scan

from egc_sim.grid_world import Pose

SCAN_TOPIC = "/scan"
ODOM_TOPIC = "/odom"
CMD_TOPIC = "/cmd_vel"
LASER_SCAN = "sensor_msgs/msg/LaserScan"
ODOMETRY = "nav_msgs/msg/Odometry"
TWIST = "geometry_msgs/msg/Twist"
NS_PER_S = 1_000_000_000


class BagError(ValueError):
    """The log cannot be written where asked; the message says why."""


@dataclass(frozen=True, slots=True)
class BagStep:
    """One control cycle as the log records it; times in ns of the simulated clock."""

    stamp_ns: int
    scan: Scan
    odom_pose: Pose  # x_m, y_m, yaw_rad in the odometry frame
    odom_twist: tuple[float, float]  # v_mps, w_radps of the base, in {R}
    command: tuple[float, float]  # v_mps, w_radps the driver asked for (before any filter)


def check_bag_path(path: str | Path) -> Path:
    """``path`` as a Path if a log can be written there (it does not exist and its folder
    does); else ``BagError`` with one line."""
    p = Path(path)
    if p.exists():
        raise BagError(f"{p} exists already: the log is never written over an existing one")
    if not p.resolve().parent.is_dir():
        raise BagError(f"{p}: its folder does not exist")
    return p


def scan_layout(scan: Scan) -> tuple[float, float]:
    """(angle_min, angle_increment) of ``scan``'s beams; ``BagError`` unless they are evenly
    spaced, as a LaserScan requires."""
    a = np.asarray(scan.angles_rad, dtype=np.float64)
    if a.size == 0:
        return 0.0, 0.0
    if a.size == 1:
        return float(a[0]), 0.0
    step = float(a[1] - a[0])
    if not np.allclose(np.diff(a), step, rtol=0.0, atol=1e-9):
        raise BagError("a LaserScan needs evenly spaced beams; this scan's are not")
    return float(a[0]), step


class EpisodeBag:
    """Writes ``BagStep``s to a ROS 2 log at ``path`` (module docstring); a context manager."""

    def __init__(self, path: str | Path) -> None:
        from rosbags.rosbag2 import StoragePlugin, Writer
        from rosbags.typesys import Stores, get_typestore

        self.path = check_bag_path(path)
        self._single_file = self.path.suffix.lower() == ".mcap"
        self._work: Path | None = None
        if self._single_file:  # rosbags writes a bag directory; its one MCAP file is kept
            self._work = Path(tempfile.mkdtemp(prefix=".bag-", dir=self.path.resolve().parent))
            bag_dir = self._work / self.path.stem
        else:
            bag_dir = self.path
        self._ts = get_typestore(Stores.ROS2_JAZZY)
        self._types: Any = self._ts.types
        self._writer = Writer(bag_dir, version=9, storage_plugin=StoragePlugin.MCAP)
        self._bag_dir = bag_dir
        self._writer.open()
        self._scan = self._writer.add_connection(SCAN_TOPIC, LASER_SCAN, typestore=self._ts)
        self._odom = self._writer.add_connection(ODOM_TOPIC, ODOMETRY, typestore=self._ts)
        self._cmd = self._writer.add_connection(CMD_TOPIC, TWIST, typestore=self._ts)
        self.steps = 0
        self._closed = False

    def __enter__(self) -> EpisodeBag:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def _header(self, stamp_ns: int, frame: str) -> Any:
        t = self._types
        stamp = t["builtin_interfaces/msg/Time"](stamp_ns // NS_PER_S, stamp_ns % NS_PER_S)
        return t["std_msgs/msg/Header"](stamp, frame)

    def _twist(self, v_mps: float, w_radps: float) -> Any:
        t = self._types
        vector = t["geometry_msgs/msg/Vector3"]
        return t["geometry_msgs/msg/Twist"](vector(v_mps, 0.0, 0.0), vector(0.0, 0.0, w_radps))

    def write(self, step: BagStep) -> None:
        """Append one cycle: its command, odometry and scan, all at ``step.stamp_ns``."""
        if self._closed:
            raise BagError(f"{self.path}: the log is closed")
        t, ts, ns = self._types, self._ts, int(step.stamp_ns)
        if ns < 0:
            raise BagError(f"a log time is never negative, got {ns} ns")
        cmd = self._twist(*step.command)
        self._writer.write(self._cmd, ns, ts.serialize_cdr(cmd, TWIST))

        x, y, yaw = step.odom_pose
        pose = t["geometry_msgs/msg/Pose"](
            t["geometry_msgs/msg/Point"](x, y, 0.0),
            t["geometry_msgs/msg/Quaternion"](0.0, 0.0, math.sin(0.5 * yaw), math.cos(0.5 * yaw)),
        )
        covariance = np.zeros(36, dtype=np.float64)
        odom = t[ODOMETRY](
            self._header(ns, "odom"),
            "base_link",
            t["geometry_msgs/msg/PoseWithCovariance"](pose, covariance),
            t["geometry_msgs/msg/TwistWithCovariance"](self._twist(*step.odom_twist), covariance),
        )
        self._writer.write(self._odom, ns, ts.serialize_cdr(odom, ODOMETRY))

        scan = step.scan
        angle_min, increment = scan_layout(scan)
        n = int(np.size(scan.ranges_m))
        msg = t[LASER_SCAN](
            self._header(ns, "laser"),
            angle_min,
            angle_min + increment * max(n - 1, 0),
            increment,
            0.0,
            0.0,
            float(scan.range_min_m),
            float(scan.range_max_m),
            np.asarray(scan.ranges_m, dtype=np.float32),
            np.zeros(0, dtype=np.float32),
        )
        self._writer.write(self._scan, ns, ts.serialize_cdr(msg, LASER_SCAN))
        self.steps += 1

    def close(self) -> None:
        """Finish the log (idempotent); a single-file log is moved into place here."""
        if self._closed:
            return
        self._closed = True
        try:
            self._writer.close()
            if self._single_file:
                produced = self._bag_dir / f"{self._bag_dir.name}.mcap"
                produced.replace(self.path)
        finally:
            if self._work is not None:
                shutil.rmtree(self._work, ignore_errors=True)
