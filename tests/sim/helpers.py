"""Shared helpers of the simulator tests: tiny map files, worlds and the MRPB folder."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from egc_sim.grid_world import World

MRPB = Path(__file__).resolve().parents[2] / ".." / "shared" / "worlds" / "mrpb"


def write_pgm(path: Path, pixels: np.ndarray) -> None:
    """A binary (P5) 8-bit PGM, row 0 at the top as in any image file."""
    rows, cols = pixels.shape
    path.write_bytes(b"P5\n%d %d\n255\n" % (cols, rows) + pixels.astype(np.uint8).tobytes())


def write_map_yaml(
    folder: Path,
    pixels: np.ndarray,
    negate: int = 0,
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0),
    resolution: float = 0.05,
    occupied_thresh: float = 0.65,
    free_thresh: float = 0.196,
    extra: str = "",
) -> Path:
    write_pgm(folder / "map.pgm", pixels)
    yaml_path = folder / "map.yaml"
    yaml_path.write_text(
        f"image: map.pgm\nresolution: {resolution}\n"
        f"origin: [{origin[0]}, {origin[1]}, {origin[2]}]\n"
        f"negate: {negate}\noccupied_thresh: {occupied_thresh}\nfree_thresh: {free_thresh}\n{extra}"
    )
    return yaml_path


def grid_world(occupied: np.ndarray, resolution_m: float = 0.05, origin=(0.0, 0.0)) -> World:
    """A world from a boolean grid given with row 0 at the bottom."""
    occ = np.asarray(occupied, dtype=bool)
    return World("test", occ, np.zeros_like(occ), resolution_m, origin[0], origin[1])


def boxed_room(width_m: float, height_m: float, resolution_m: float = 0.05) -> np.ndarray:
    """A free room with a one-cell wall on its border."""
    rows, cols = round(height_m / resolution_m), round(width_m / resolution_m)
    occ = np.zeros((rows, cols), dtype=bool)
    occ[0, :] = occ[-1, :] = True
    occ[:, 0] = occ[:, -1] = True
    return occ
