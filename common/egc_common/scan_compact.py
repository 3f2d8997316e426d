"""The telemetry's compact scan (DESIGN 12): beams in order, ranges in whole millimetres.

A scan of 360 beams as float32 (x, y) points took 8 bytes a point (2,880 bytes, most of a
2 kB telemetry message at decimation 2); as uint16 millimetres in beam order with the first
angle, the increment and the sensor's origin given once it takes 2 bytes a beam. Fewer beams
when the downlink budget is small (``egc_common.view_budget``): each shown beam is the *nearest*
valid reading of the group of neighbouring beams it stands for, at the group's middle angle, so
that a thin obstacle seen by one beam of the group is never thinned out of the view.

Pure: numpy arrays and frozen dataclasses, no IO.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from egc_common.scan import Scan

MAX_RANGE_MM = 65_535  # uint16; a reading further than 65.535 m is not shown
# Beam angles within this of a uniform spacing count as uniform (float64 angles built from
# angle_min + i * increment are within 1e-12 of it; a float32 source within ~1e-6).
_UNIFORM_TOL_RAD = 1e-5


@dataclass(frozen=True, slots=True, eq=False)
class PolarScan:
    """Beams in order from ``origin_xy_m`` in {R}: beam i points at ``angle_min_rad + i *
    angle_increment_rad`` and reads ``ranges_mm[i]`` millimetres; 0 means no reading shown
    (invalid, no return, or beyond ``MAX_RANGE_MM``)."""

    ranges_mm: npt.NDArray[np.uint16]
    angle_min_rad: float
    angle_increment_rad: float
    origin_xy_m: tuple[float, float] = (0.0, 0.0)

    @property
    def beams(self) -> int:
        return int(self.ranges_mm.size)

    @property
    def shown(self) -> int:
        """How many beams hold a reading (the number of points)."""
        return int(np.count_nonzero(self.ranges_mm))

    def points(self) -> npt.NDArray[np.float32]:
        """The readings as (N, 2) float32 points in {R}, in beam order."""
        mm = self.ranges_mm
        keep = np.flatnonzero(mm)
        r = mm[keep].astype(np.float64) / 1000.0
        a = self.angle_min_rad + self.angle_increment_rad * keep.astype(np.float64)
        out = np.empty((keep.size, 2), dtype=np.float32)
        out[:, 0] = r * np.cos(a) + self.origin_xy_m[0]
        out[:, 1] = r * np.sin(a) + self.origin_xy_m[1]
        return out


def uniform_spacing(angles_rad: npt.NDArray[np.float64]) -> float | None:
    """The increment of evenly spaced beam angles, or None when they are not evenly spaced."""
    n = angles_rad.size
    if n == 0:
        return None
    if n == 1:
        return 0.0
    step = (float(angles_rad[-1]) - float(angles_rad[0])) / (n - 1)
    expected = float(angles_rad[0]) + step * np.arange(n, dtype=np.float64)
    if not np.all(np.abs(angles_rad - expected) <= _UNIFORM_TOL_RAD):
        return None
    return step


def compact(scan: Scan, max_beams: int) -> PolarScan | None:
    """``scan`` as at most ``max_beams`` beams (see the module docstring); None when its beams
    are not evenly spaced (the caller sends points instead). Readings outside [range_min,
    range_max], NaN and +-inf are not shown (the points of ``Scan.obstacles`` are the same
    readings; its ``extra_xy_m`` are not beams and are not here)."""
    if max_beams < 1:
        raise ValueError("max_beams must be >= 1")
    increment = uniform_spacing(scan.angles_rad)
    if increment is None:
        return None
    r = scan.ranges_m
    n = r.size
    valid = scan.valid_mask
    mm = np.zeros(n, dtype=np.float64)
    mm[valid] = np.rint(r[valid] * 1000.0)
    mm[mm > MAX_RANGE_MM] = 0.0
    mm[valid & (mm < 1.0)] = 1.0  # a valid reading closer than 0.5 mm is still a reading
    group = max(1, math.ceil(n / max_beams))
    if group > 1:
        pad = (-n) % group
        grouped = np.concatenate((mm, np.zeros(pad))).reshape(-1, group)
        nearest = np.where(grouped > 0, grouped, np.inf).min(axis=1)
        mm = np.where(np.isfinite(nearest), nearest, 0.0)
    first = float(scan.angles_rad[0]) if n else 0.0
    return PolarScan(
        ranges_mm=mm.astype(np.uint16),
        angle_min_rad=first + increment * (group - 1) / 2.0,
        angle_increment_rad=increment * group,
        origin_xy_m=(float(scan.mount_x_m), float(scan.mount_y_m)),
    )
