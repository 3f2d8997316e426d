"""Load a world from a file or a built-in name (``load_world``), the one entry point.

``spec`` may be:

- a ROS map_server ``.yaml`` with a PGM or PNG image (``map_server``);
- a geometric ``.toml`` world of segments, circles and polygons (``shapes``);
- a ``.npy`` occupancy grid, 0.05 m cells, origin (0, 0) (``npy_grid``);
- a built-in name: ``hallway`` (after the paper's Fig. 9, ``worlds/hallway.toml``), the MRPB
  maps shipped in ``worlds/`` (e.g. ``office02``), and ``random`` / ``random:SEED``
  (``random_field``; plain ``random`` uses the ``seed`` argument; ``reach_m``, the robot's
  footprint reach, sizes the field for a large robot: ``RandomFieldParams.for_reach``), and
  ``clutter`` / ``clutter:SEED`` (``clutter_field``: dense clutter whose gaps are 1.2-1.5 x
  the robot's width; ``footprint`` sizes it, ``ClutterParams.for_robot``; without one, a
  disc of ``reach_m`` stands in for the robot, and without either the Jackal).

Every failure raises ``WorldError`` (a ValueError) with one clear line.
"""

from __future__ import annotations

from pathlib import Path

from egc_common.footprint import Footprint

from egc_sim.clutter_field import ClutterParams, clutter_world
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
    return sorted([*_shipped(), "clutter", "random"])


def _clutter_params(reach_m: float | None, footprint: Footprint | None) -> ClutterParams | None:
    if footprint is not None:
        return ClutterParams.for_robot(footprint.width_m, footprint.reach_m)
    if reach_m is not None:
        return ClutterParams.for_robot(2.0 * reach_m, reach_m)
    return None


def _seed(text: str, kind: str) -> int:
    raw = text.partition(":")[2]
    try:
        return int(raw)
    except ValueError:
        raise WorldError(f"{kind} world seed must be an integer, got {raw!r}") from None


def load_world(
    spec: str,
    seed: int = 0,
    reach_m: float | None = None,
    footprint: Footprint | None = None,
) -> World:
    """A world from a path or a built-in name (module docstring). ``reach_m`` sizes the random
    worlds, ``footprint`` (else ``reach_m``) the clutter worlds; other worlds ignore both."""
    text = str(spec).strip()
    if not text:
        raise WorldError("empty world name")
    if text in ("random", "clutter") or text.startswith(("random:", "clutter:")):
        kind = text.partition(":")[0]
        value = _seed(text, kind) if ":" in text else seed
        if kind == "random":
            field = None if reach_m is None else RandomFieldParams.for_reach(reach_m)
            return random_world(value, field)
        return clutter_world(value, _clutter_params(reach_m, footprint))
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
