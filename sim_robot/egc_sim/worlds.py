"""Load a world from a file or a built-in name (``load_world``), the one entry point.

``spec`` may be:

- a ROS map_server ``.yaml`` with a PGM or PNG image (``map_server``);
- a geometric ``.toml`` world of segments, circles and polygons (``shapes``);
- a ``.npy`` occupancy grid, 0.05 m cells, origin (0, 0) (``npy_grid``);
- a built-in name: ``hallway`` (after the paper's Fig. 9, ``worlds/hallway.toml``), the MRPB
  maps shipped in ``worlds/`` (e.g. ``office02``), and ``random`` / ``random:SEED``
  (``random_field``; plain ``random`` uses the ``seed`` argument; ``reach_m``, the robot's
  footprint reach, sizes the field for a large robot: ``RandomFieldParams.for_reach``).

Every failure raises ``WorldError`` (a ValueError) with one clear line.
"""

from __future__ import annotations

from pathlib import Path

from egc_sim.grid_world import Area, Pose, World, WorldError
from egc_sim.map_server import load_map_yaml
from egc_sim.npy_grid import load_npy_grid
from egc_sim.random_field import RandomFieldParams, random_world
from egc_sim.shapes import load_toml_world

__all__ = ["Area", "Pose", "World", "WorldError", "builtin_names", "load_world"]

WORLDS_DIR = Path(__file__).resolve().parent / "worlds"


def _shipped() -> dict[str, Path]:
    """Worlds shipped with the package: ``worlds/NAME.toml`` and ``worlds/NAME/map.yaml``."""
    found = {p.stem: p for p in WORLDS_DIR.glob("*.toml")}
    found.update({p.parent.name: p for p in WORLDS_DIR.glob("*/map.yaml")})
    return found


def builtin_names() -> list[str]:
    return sorted([*_shipped(), "random"])


def load_world(spec: str, seed: int = 0, reach_m: float | None = None) -> World:
    """A world from a path or a built-in name (module docstring)."""
    text = str(spec).strip()
    if not text:
        raise WorldError("empty world name")
    field = None if reach_m is None else RandomFieldParams.for_reach(reach_m)
    if text == "random":
        return random_world(seed, field)
    if text.startswith("random:"):
        raw = text.partition(":")[2]
        try:
            value = int(raw)
        except ValueError:
            raise WorldError(f"random world seed must be an integer, got {raw!r}") from None
        return random_world(value, field)
    shipped = _shipped()
    if text in shipped:
        return load_world(str(shipped[text]))
    path = Path(text)
    suffix = path.suffix.lower()
    if suffix in (".yaml", ".yml"):
        return load_map_yaml(path)
    if suffix == ".toml":
        return load_toml_world(path)
    if suffix == ".npy":
        return load_npy_grid(path)
    if path.is_dir() and (path / "map.yaml").is_file():
        return load_map_yaml(path / "map.yaml")
    raise WorldError(
        f"unknown world {text!r}: give a map .yaml, a .toml or .npy file, or one of "
        f"{', '.join(builtin_names())}"
    )
