"""ROS map_server maps (``map.yaml`` + PGM/PNG image) with map_server's exact semantics.

The YAML keys, as map_server defines them (wiki.ros.org/map_server, ``image_loader.cpp``):

- ``image``: the image file, relative to the YAML file's folder.
- ``resolution``: metres per pixel.
- ``origin``: [x, y, yaw], the world pose of the **lower-left** pixel. Image row 0 is the *top*
  of the map, so rows are flipped to put row 0 at the lowest y (``grid_world``). A non-zero yaw
  is rejected: map_server passes it on but costmaps and planners ignore it, so honouring it here
  would make the simulator disagree with the robot's own stack.
- ``negate``: 0 or 1; ``occupied_thresh``, ``free_thresh``: probabilities in [0, 1].
- ``mode`` (optional): ``trinary`` (default) or ``scale``. ``raw`` maps pixel values straight to
  occupancy numbers without thresholds and is not supported.

Per pixel, with ``c`` the mean of its channels (in trinary mode map_server averages the alpha
channel in too, in scale mode it leaves it out) and ``c' = 255 - c`` when ``negate`` is 1:
``p = (255 - c') / 255``; the cell is **occupied** if ``p > occupied_thresh``, **free** if
``p < free_thresh``, and **unknown** otherwise. (In scale mode map_server gives the in-between
cells a value 1-99; the simulator, which needs a yes/no answer, treats them as unknown.)

A ``tests.txt`` beside the YAML (MRPB's start/goal tests, ``egc_sim.mrpb_tests``) gives the
world its suggested start and goal: those of the first complete test.

PyYAML and Pillow are imported when a map is loaded: a process that loads none (a built-in or
TOML world, a bad argument) does not pay for them at start-up.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from egc_sim.grid_world import BoolGrid, World, WorldError, read_world_text
from egc_sim.mrpb_tests import read_tests_beside

MODES = ("trinary", "scale")
REQUIRED_KEYS = ("image", "resolution", "origin", "negate", "occupied_thresh", "free_thresh")


def classify_pixels(
    pixels: npt.ArrayLike,
    negate: bool,
    occupied_thresh: float,
    free_thresh: float,
    mode: str = "trinary",
) -> tuple[BoolGrid, BoolGrid]:
    """(occupied, unknown) masks of an image, in image row order (row 0 = top).

    ``pixels`` is (rows, cols) for grey images or (rows, cols, channels) with 8-bit channels;
    with 2 or 4 channels the last one is alpha.
    """
    a = np.asarray(pixels, dtype=np.float64)
    if a.ndim == 2:
        color = a
    elif a.ndim == 3 and a.shape[2] in (1, 2, 3, 4):
        has_alpha = a.shape[2] in (2, 4)
        channels = a if (mode == "trinary" or not has_alpha) else a[:, :, :-1]
        color = channels.mean(axis=2)
    else:
        raise WorldError(f"unsupported pixel array shape {a.shape}")
    if negate:
        color = 255.0 - color
    p = (255.0 - color) / 255.0
    occupied = p > occupied_thresh
    free = p < free_thresh
    return occupied, ~(occupied | free)


def read_image(path: Path) -> npt.NDArray[np.uint8]:
    """An 8-bit image as (rows, cols) or (rows, cols, channels); alpha kept as the last channel."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as opened:
            opened.load()
            im: Image.Image = opened
            if im.mode in ("I;16", "I;16B", "I;16L", "I", "F"):
                raise WorldError(f"{path}: {im.mode} images are not supported; use 8-bit PGM/PNG")
            if im.mode == "P":
                im = im.convert("RGBA" if "transparency" in im.info else "RGB")
            elif im.mode not in ("L", "LA", "RGB", "RGBA"):
                im = im.convert("RGB")
            return np.asarray(im, dtype=np.uint8)
    except FileNotFoundError:
        raise WorldError(f"map image not found: {path}") from None
    except (UnidentifiedImageError, OSError) as exc:
        raise WorldError(f"cannot read map image {path}: {exc}") from None


def _number(meta: dict[str, Any], key: str, where: Path) -> float:
    value = meta[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise WorldError(f"{where}: {key} must be a number, got {value!r}")
    return float(value)


def load_map_yaml(path: str | Path) -> World:
    """Load a map_server map; raises WorldError naming the file and the problem."""
    import yaml

    p = Path(path)
    text = read_world_text(p, "map file")
    try:
        meta = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise WorldError(f"{p} is not valid YAML: {exc}") from None
    if not isinstance(meta, dict):
        raise WorldError(f"{p}: expected a YAML mapping with keys {', '.join(REQUIRED_KEYS)}")
    missing = [k for k in REQUIRED_KEYS if k not in meta]
    if missing:
        raise WorldError(f"{p}: missing key(s) {', '.join(missing)}")

    resolution = _number(meta, "resolution", p)
    if resolution <= 0:
        raise WorldError(f"{p}: resolution must be positive, got {resolution}")
    origin = meta["origin"]
    if not (
        isinstance(origin, list)
        and len(origin) == 3
        and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in origin)
        and all(math.isfinite(v) for v in origin)
    ):
        raise WorldError(f"{p}: origin must be [x, y, yaw] numbers, got {origin!r}")
    if origin[2] != 0:
        raise WorldError(f"{p}: origin yaw {origin[2]} is not supported (only 0)")
    occupied_thresh = _number(meta, "occupied_thresh", p)
    free_thresh = _number(meta, "free_thresh", p)
    if not 0.0 <= free_thresh <= occupied_thresh <= 1.0:
        raise WorldError(f"{p}: need 0 <= free_thresh <= occupied_thresh <= 1")
    negate = meta["negate"]
    if negate not in (0, 1) or isinstance(negate, float):
        raise WorldError(f"{p}: negate must be 0 or 1, got {negate!r}")
    mode = meta.get("mode", "trinary")
    if mode not in MODES:
        raise WorldError(f"{p}: mode {mode!r} is not supported (supported: {', '.join(MODES)})")
    image_name = meta["image"]
    if not isinstance(image_name, str) or not image_name:
        raise WorldError(f"{p}: image must be a file name")

    pixels = read_image(p.parent / image_name)
    occupied, unknown = classify_pixels(pixels, bool(negate), occupied_thresh, free_thresh, mode)
    # MRPB ships its start/goal tests beside the map: the first one is the map's suggestion.
    first = next(iter(read_tests_beside(p)), None)
    return World(
        name=p.parent.name if p.stem == "map" else p.stem,
        occupancy=occupied[::-1] | unknown[::-1],
        unknown=unknown[::-1],
        resolution_m=resolution,
        origin_x_m=float(origin[0]),
        origin_y_m=float(origin[1]),
        start_pose=None if first is None else first.start_pose,
        goal=None if first is None else first.goal_xy_m,
    )
