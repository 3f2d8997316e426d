"""The base-and-sensor driver seam of the robot process (DESIGN 1, issue 4).

The robot's loop talks to its base and sensor through one small Protocol, polled once per
control cycle: ``poll(now_ns)`` hands over what arrived since the last poll (the newest scan with
its arrival time, the newest odometry) and ``send`` drives the base. Implementations:

- ``egc_robot.zenoh_driver.ZenohDriver``: the base and sensor are another process speaking the
  pinned ``scan`` / ``base/cmd`` / ``base/odom`` keys (``egc-teleop sim``, or a real robot bridge);
- the in-process simulator wrapper in ``egc_app.robot_cmd`` (egc_robot may not import egc_sim).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
from egc_common.footprint import Footprint
from egc_common.messages import BaseCommand, Odometry, Rejection, RejectReason, ScanMessage
from egc_common.scan import Scan, carries_information, too_close_readings


@dataclass(frozen=True, slots=True)
class SensorUpdate:
    """What a driver received since the previous poll; None where nothing new arrived."""

    scan: Scan | None = None
    scan_rx_ns: int = 0
    odometry: Odometry | None = None


class Driver(Protocol):
    def poll(self, now_ns: int) -> SensorUpdate:
        """The newest scan and odometry since the previous poll."""
        ...

    def send(self, command: BaseCommand) -> None:
        """Drive the base with this velocity until the next command."""
        ...

    def close(self) -> None: ...


def scan_from_message(
    message: ScanMessage, footprint_half_m: Footprint | tuple[float, float] | None = None
) -> Scan | Rejection:
    """A decoded ``egc/<robot>/scan`` message as a Scan in {R}.

    The message has the ROS LaserScan layout, so ``-inf`` means what REP 117 says (an object
    nearer than range_min), as on the ROS 2 driver: an obstacle at range_min and, given the
    footprint, points just outside it (``too_close_points``). It was dropped as "no return",
    so a bridge forwarding LaserScan ranges lost every too-close obstacle.

    A scan that carries no information at all (no beams, or every beam NaN or a finite value
    outside [range_min, range_max]) is a Rejection, as on the ROS 2 driver: delivered, it
    would keep the sensor fresh while saying nothing, and a sender declaring
    ``no_return_is_free`` would have it read as "all free". Rejected, the sensor goes stale
    and the robot holds (``scan_timeout``).
    """
    ranges = message.ranges_m.astype(np.float64)
    if not carries_information(ranges, message.range_min_m, message.range_max_m):
        return Rejection(
            RejectReason.NO_INFORMATION,
            f"{ranges.size} beams, none valid, none +-inf (all NaN or out of range)",
        )
    angles = message.angle_min_rad + message.angle_increment_rad * np.arange(
        ranges.size, dtype=np.float64
    )
    ranges, extra = too_close_readings(
        ranges, angles, message.range_min_m, 0.0, 0.0, footprint_half_m
    )
    return Scan.uniform(
        ranges,
        message.angle_min_rad,
        message.angle_increment_rad,
        message.range_min_m,
        message.range_max_m,
        stamp_ns=message.stamp_ns,
        no_return_is_free=message.no_return_is_free,
        extra_xy_m=extra,
    )
