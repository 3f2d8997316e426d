"""Occupancy grids stored as numpy ``.npy`` files.

Layout as ``nav_msgs/OccupancyGrid``: row 0 is the bottom row (lowest y), the origin is the world
position of the lower-left corner. Values:

- ``bool``: True = occupied, False = free;
- numbers: OccupancyGrid values, -1 (any negative) = unknown, 0..100 = occupancy probability in
  percent, classified with map_server's default thresholds: occupied above 65, free below 19.6,
  unknown in between (and unknown blocks, see ``grid_world``).

Resolution and origin are not stored in a ``.npy`` file: a bare ``.npy`` world uses 0.05 m cells
with the origin at (0, 0); a TOML world can place a grid with ``grid``, ``resolution_m`` and
``origin_m`` and draw shapes over it (``shapes``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from egc_sim.grid_world import World, WorldError

DEFAULT_RESOLUTION_M = 0.05
OCCUPIED_THRESH = 65.0
FREE_THRESH = 19.6


def load_npy_grid(
    path: str | Path,
    resolution_m: float = DEFAULT_RESOLUTION_M,
    origin: tuple[float, float] = (0.0, 0.0),
) -> World:
    p = Path(path)
    try:
        a = np.load(p, allow_pickle=False)
    except FileNotFoundError:
        raise WorldError(f"grid file not found: {p}") from None
    except (OSError, ValueError) as exc:
        raise WorldError(f"cannot read grid file {p}: {exc}") from None
    if a.ndim != 2 or a.size == 0:
        raise WorldError(f"{p}: expected a non-empty 2-D array, got shape {a.shape}")
    if a.dtype == np.bool_:
        occupied = a
        unknown = np.zeros(a.shape, dtype=bool)
    elif np.issubdtype(a.dtype, np.integer) or np.issubdtype(a.dtype, np.floating):
        v = a.astype(np.float64)
        if not np.all(np.isfinite(v)):
            raise WorldError(f"{p}: grid values must be finite")
        occupied = v > OCCUPIED_THRESH
        unknown = (v < 0) | ((v >= FREE_THRESH) & ~occupied)
    else:
        raise WorldError(f"{p}: grid dtype {a.dtype} is neither bool nor numeric")
    return World(
        name=p.stem,
        occupancy=occupied | unknown,
        unknown=unknown,
        resolution_m=resolution_m,
        origin_x_m=origin[0],
        origin_y_m=origin[1],
    )
