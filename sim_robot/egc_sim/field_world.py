"""What the seeded worlds share (``random_field``, ``clutter_field``): the solvability check on
the grid's distance transform, and the ``World`` of a walled field with a start on the left
facing the goal on the right. scipy is imported when first used (``egc_sim.collision``)."""

from __future__ import annotations

import math

import numpy as np

from egc_sim.grid_world import World


def clearance_m(occupancy: np.ndarray, resolution_m: float) -> np.ndarray:
    """Each cell's distance to the nearest occupied cell (m)."""
    from scipy import ndimage

    return np.asarray(ndimage.distance_transform_edt(~occupancy)) * resolution_m


def cell(xy: tuple[float, float], resolution_m: float) -> tuple[int, int]:
    """The grid (row, column) of a point (x, y) in metres, origin at (0, 0)."""
    return int(xy[1] / resolution_m), int(xy[0] / resolution_m)


def linked(
    clearance: np.ndarray,
    radius_m: float,
    start: tuple[float, float],
    goal: tuple[float, float],
    resolution_m: float,
) -> bool:
    """Whether a disc of ``radius_m`` can travel from start to goal on the clearance grid."""
    from scipy import ndimage

    labels, _ = ndimage.label(clearance >= radius_m)
    a, b = labels[cell(start, resolution_m)], labels[cell(goal, resolution_m)]
    return bool(a != 0 and a == b)


def field_world(
    name: str,
    occupancy: np.ndarray,
    resolution_m: float,
    start: tuple[float, float],
    goal: tuple[float, float],
    goal_tolerance_m: float,
) -> World:
    """The ``World`` of a field at the origin, fully known, the start facing the goal."""
    yaw = math.atan2(goal[1] - start[1], goal[0] - start[0])
    return World(
        name=name,
        occupancy=occupancy,
        unknown=np.zeros_like(occupancy),
        resolution_m=resolution_m,
        origin_x_m=0.0,
        origin_y_m=0.0,
        start_pose=(start[0], start[1], yaw),
        goal=goal,
        goal_tolerance_m=goal_tolerance_m,
    )
