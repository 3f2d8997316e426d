"""The robot's footprint against the blocked cells: exact clearance and contact (DESIGN 14).

The footprint F is the profile's shape as given: a simple polygon in {R} (a rectangle, a
pentagon, an L) or a disc. Blocked cells are squares; U is their union.

Polygon. For disjoint polygons the distance is reached between a vertex of one and an edge of
the other (the distance between two segments is reached at an endpoint of one of them), so

    clearance = min( min over corners v of blocked cells: signed_distance(v, F),
                     min over the vertices c of F:        dist(c, U) )

is exact when F and U do not overlap. They overlap when a cell corner lies inside F (the first
term is negative: minus the depth of the deepest corner), a vertex of F inside a cell (the second
is 0), or, with neither, when an edge of F crosses a cell (a thin part of F across a square): an
explicit segment-square test (``segments_cross_boxes``) reports that as 0. So ``clearance <= 0``
is contact, for every simple polygon and every cell size.

Disc of radius r about the origin: clearance = dist(centre, U) - r, exact (negative inside).

A Euclidean distance transform of the grid bounds the distance from the robot's centre to the
nearest blocked cell, so only the cells that can be nearest are examined (none at all in open
space). Clearances beyond ``clearance_cap_m`` are reported as the cap.

scipy (the transform) is imported when the first checker is built, not with this module: it is
a third of the start-up of a process that imports the simulator and then stops at a bad argument.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from egc_common.footprint import Footprint, contains, segments_cross_boxes, signed_distance

from egc_sim.grid_world import World

FloatArray = npt.NDArray[np.float64]


class FootprintChecker:
    """Clearance of a ``footprint`` (polygon or disc, {R}) at any pose in a world."""

    def __init__(self, world: World, footprint: Footprint, clearance_cap_m: float = 1.0) -> None:
        res = world.resolution_m
        if not isinstance(footprint, Footprint):
            raise TypeError("footprint must be an egc_common.footprint.Footprint")
        if not clearance_cap_m > 0:
            raise ValueError("clearance cap must be positive")
        self.world = world
        self.footprint = footprint
        # The radius of the circle that holds the footprint at any yaw (its reach from {R}).
        self.half_diagonal_m = footprint.reach_m
        self._vertices = footprint.vertices
        self._holds_centre = bool(contains(footprint, 0.0, 0.0))
        self.clearance_cap_m = clearance_cap_m
        # Pad with blocked cells (outside the grid blocks) wide enough for any window.
        self._pad = math.ceil((clearance_cap_m + self.half_diagonal_m) / res) + 2
        blocked = np.pad(world.occupancy, self._pad, constant_values=True)
        self._blocked = blocked
        # Distance between cell centres and the nearest blocked cell centre (m).
        from scipy import ndimage

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
        # Only squares within D of the footprint can matter: d(F, U) <= edt + res / sqrt(2)
        # (when F holds the centre), clearances beyond the cap are not reported and beyond
        # ``below`` are not needed. Such a square has its centre within
        # D + half_diagonal + res / sqrt(2) of the robot's centre.
        near = edt + res / math.sqrt(2.0) if self._holds_centre else math.inf
        reach = min(near, self.clearance_cap_m, below) + self.half_diagonal_m
        k = math.ceil(reach / res + 0.5 * math.sqrt(2.0)) + 1
        r0, r1 = max(row - k, 0), min(row + k + 1, n_rows)
        c0, c1 = max(col - k, 0), min(col + k + 1, n_cols)
        cells_r, cells_c = np.nonzero(self._blocked[r0:r1, c0:c1])
        if cells_r.size == 0:
            return self.clearance_cap_m
        ox = w.origin_x_m - self._pad * res
        oy = w.origin_y_m - self._pad * res
        sx = ox + (cells_c + c0 + 0.5) * res
        sy = oy + (cells_r + r0 + 0.5) * res
        half = 0.5 * res
        fp = self.footprint
        if fp.is_disc:  # distance from the centre to the nearest square, minus the radius
            gx = np.maximum(np.abs(sx - x_m) - half, 0.0)
            gy = np.maximum(np.abs(sy - y_m) - half, 0.0)
            return min(
                float(np.sqrt((gx * gx + gy * gy).min())) - fp.radius_m, self.clearance_cap_m
            )
        cos_t, sin_t = math.cos(yaw_rad), math.sin(yaw_rad)

        # Corners of blocked cells against the footprint (in the robot frame).
        vr, vc = np.nonzero(self._corner[r0 : r1 + 1, c0 : c1 + 1])
        px = ox + (vc + c0) * res - x_m
        py = oy + (vr + r0) * res - y_m
        local_x, local_y = cos_t * px + sin_t * py, -sin_t * px + cos_t * py
        best = float(signed_distance(fp, local_x, local_y).min())

        # The footprint's vertices against the blocked squares (world frame), all at once.
        u, v = self._vertices[:, 0], self._vertices[:, 1]
        cx = x_m + cos_t * u - sin_t * v
        cy = y_m + sin_t * u + cos_t * v
        gx = np.maximum(np.abs(sx[None, :] - cx[:, None]) - half, 0.0)
        gy = np.maximum(np.abs(sy[None, :] - cy[:, None]) - half, 0.0)
        best = min(best, float(np.sqrt((gx * gx + gy * gy).min())))
        if best > 0.0:
            # Neither holds a vertex of the other; an edge across a square is still contact.
            a = np.stack([cx, cy], axis=1)
            centres = np.stack([sx, sy], axis=1)
            if bool(segments_cross_boxes(a, np.roll(a, -1, axis=0), centres, half).any()):
                return 0.0
        return min(best, self.clearance_cap_m)
