"""The robot's rectangular footprint against the blocked cells: exact clearance and contact.

The clearance of the footprint rectangle R (the profile's length x width, centred on the robot,
long side along x of {R}) to the union U of blocked cell squares is the distance between two
sets of convex polygons. For disjoint convex polygons the distance is reached between a vertex
of one and the other polygon, so

    clearance = min( min over corners v of blocked cells: dist(v, R),
                     min over the 4 corners c of R:       dist(c, U) )

which is exact. Where R overlaps a cell the first term is negative (minus the depth of the
deepest cell corner inside R) or the second is 0, so ``clearance <= 0`` is contact. This needs
no edge-crossing test because a cell is smaller than the footprint: a cell can only overlap R
with one of its corners inside R or one of R's corners inside it (``FootprintChecker`` checks
that the footprint is wider than a cell's diagonal).

A Euclidean distance transform of the grid bounds the distance from the robot's centre to the
nearest blocked cell, so only the cells that can be nearest are examined (none at all in open
space). Clearances beyond ``clearance_cap_m`` are reported as the cap.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from egc_common.kinematics import signed_distance_to_rectangle
from scipy import ndimage

from egc_sim.grid_world import World

FloatArray = npt.NDArray[np.float64]


class FootprintChecker:
    """Clearance of a ``length_m`` x ``width_m`` rectangle at any pose in a world."""

    def __init__(
        self, world: World, length_m: float, width_m: float, clearance_cap_m: float = 1.0
    ) -> None:
        res = world.resolution_m
        if not (length_m > 0 and width_m > 0):
            raise ValueError("footprint length and width must be positive")
        if min(length_m, width_m) <= res * math.sqrt(2.0):
            raise ValueError(
                f"footprint {length_m} x {width_m} m must be wider than a cell's diagonal "
                f"({res * math.sqrt(2.0):.3f} m) for exact contact tests"
            )
        if not clearance_cap_m > 0:
            raise ValueError("clearance cap must be positive")
        self.world = world
        self.half_length_m = 0.5 * length_m
        self.half_width_m = 0.5 * width_m
        self.half_diagonal_m = math.hypot(self.half_length_m, self.half_width_m)
        self.clearance_cap_m = clearance_cap_m
        # Pad with blocked cells (outside the grid blocks) wide enough for any window.
        self._pad = math.ceil((clearance_cap_m + self.half_diagonal_m) / res) + 2
        blocked = np.pad(world.occupancy, self._pad, constant_values=True)
        self._blocked = blocked
        # Distance between cell centres and the nearest blocked cell centre (m).
        self._edt = ndimage.distance_transform_edt(~blocked) * res
        # Grid vertices that are a corner of at least one blocked cell: (rows + 1, cols + 1).
        corner = np.zeros((blocked.shape[0] + 1, blocked.shape[1] + 1), dtype=bool)
        corner[:-1, :-1] |= blocked
        corner[1:, :-1] |= blocked
        corner[:-1, 1:] |= blocked
        corner[1:, 1:] |= blocked
        self._corner = corner

    def clearance(self, x_m: float, y_m: float, yaw_rad: float, below: float = math.inf) -> float:
        """Signed clearance (m) of the footprint at the pose; <= 0 is contact, capped above.

        Exact whenever it is below ``below``; otherwise some value above ``below`` (only the
        cells that could be nearer than ``below`` are examined): a caller tracking a running
        minimum, or testing for contact, needs no more.
        """
        w = self.world
        res = w.resolution_m
        fr = (y_m - w.origin_y_m) / res + self._pad
        fc = (x_m - w.origin_x_m) / res + self._pad
        row, col = math.floor(fr), math.floor(fc)
        n_rows, n_cols = self._blocked.shape
        if not (0 <= row < n_rows and 0 <= col < n_cols):
            return -self.half_diagonal_m  # far outside the map: deep in unknown space
        # The centre is within res/sqrt(2) of its cell centre and a blocked square within
        # res/sqrt(2) of its own centre, so the distance d from the centre to U satisfies
        # edt - res sqrt(2) <= d <= edt + res / sqrt(2), and clearance >= d - half_diagonal.
        edt = float(self._edt[row, col])
        lower = edt - res * math.sqrt(2.0) - self.half_diagonal_m
        if lower >= self.clearance_cap_m:
            return self.clearance_cap_m
        if lower > below:
            return lower
        # Only squares within D of the rectangle can matter: d(rect, U) <= edt + res / sqrt(2),
        # clearances beyond the cap are not reported and beyond ``below`` are not needed. Such a
        # square has its centre within D + half_diagonal + res / sqrt(2) of the robot's centre.
        reach = min(edt + res / math.sqrt(2.0), self.clearance_cap_m, below) + self.half_diagonal_m
        k = math.ceil(reach / res + 0.5 * math.sqrt(2.0)) + 1
        r0, r1 = max(row - k, 0), min(row + k + 1, n_rows)
        c0, c1 = max(col - k, 0), min(col + k + 1, n_cols)
        cells_r, cells_c = np.nonzero(self._blocked[r0:r1, c0:c1])
        if cells_r.size == 0:
            return self.clearance_cap_m
        ox = w.origin_x_m - self._pad * res
        oy = w.origin_y_m - self._pad * res
        cos_t, sin_t = math.cos(yaw_rad), math.sin(yaw_rad)
        hl, hw = self.half_length_m, self.half_width_m

        # Corners of blocked cells against the rectangle (in the robot frame).
        vr, vc = np.nonzero(self._corner[r0 : r1 + 1, c0 : c1 + 1])
        px = ox + (vc + c0) * res - x_m
        py = oy + (vr + r0) * res - y_m
        local_x, local_y = cos_t * px + sin_t * py, -sin_t * px + cos_t * py
        best = float(signed_distance_to_rectangle(local_x, local_y, hl, hw).min())

        # The rectangle's corners against the blocked squares (world frame).
        sx = ox + (cells_c + c0 + 0.5) * res
        sy = oy + (cells_r + r0 + 0.5) * res
        half = 0.5 * res
        for u, v in ((hl, hw), (hl, -hw), (-hl, hw), (-hl, -hw)):
            cx = x_m + cos_t * u - sin_t * v
            cy = y_m + sin_t * u + cos_t * v
            gx = np.maximum(np.abs(sx - cx) - half, 0.0)
            gy = np.maximum(np.abs(sy - cy) - half, 0.0)
            best = min(best, float(np.sqrt((gx * gx + gy * gy).min())))
        return min(best, self.clearance_cap_m)
