"""Geometric worlds: segments, circles and polygons rasterised onto a grid, read from TOML.

Rasterisation rule: a cell is occupied when its **centre** lies inside the shape. Segments are
walls of a given thickness (at least one cell diagonal, so a thin or diagonal wall never has a
gap a ray or the robot could slip through); circles and polygons (even-odd rule) are filled.

A TOML world (all lengths in metres, angles in radians)::

    name = "two boxes"
    resolution_m = 0.05                 # optional, default 0.05
    bounds_m = [0.0, 0.0, 8.0, 4.0]     # x_min, y_min, x_max, y_max: the grid's extent
    # grid = "base.npy"                 # optional occupancy grid underneath (see worlds.py);
    #                                   # then bounds_m is optional and origin_m = [x, y] places it
    start = { x_m = 0.6, y_m = 2.0, yaw_rad = 0.0 }    # optional
    goal = { x_m = 7.4, y_m = 2.0 }                    # optional
    goal_tolerance_m = 0.3                              # optional

    [[segments]]
    from_m = [0.0, 0.0]
    to_m = [8.0, 0.0]
    thickness_m = 0.1                   # optional

    [[circles]]
    center_m = [3.0, 2.2]
    radius_m = 0.3

    [[polygons]]
    points_m = [[5.0, 1.0], [5.6, 1.0], [5.6, 1.8], [5.0, 1.8]]

    [[areas]]                           # optional named boxes, for figures and tests
    name = "A"
    min_m = [2.0, 0.0]
    max_m = [4.0, 4.0]
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from egc_sim.grid_world import Area, BoolGrid, Pose, World, WorldError, read_world_text
from egc_sim.npy_grid import load_npy_grid

DEFAULT_RESOLUTION_M = 0.05
FloatArray = npt.NDArray[np.float64]
Point = tuple[float, float]


@dataclass(frozen=True, slots=True)
class Segment:
    start_m: Point
    end_m: Point
    thickness_m: float = 0.0


@dataclass(frozen=True, slots=True)
class Circle:
    center_m: Point
    radius_m: float


@dataclass(frozen=True, slots=True)
class Polygon:
    points_m: tuple[Point, ...]


Shape = Segment | Circle | Polygon


def cell_centres(
    rows: int, cols: int, resolution_m: float, origin: Point
) -> tuple[FloatArray, FloatArray]:
    """World x and y of every cell centre, each as a (rows, cols) array."""
    xs = origin[0] + (np.arange(cols) + 0.5) * resolution_m
    ys = origin[1] + (np.arange(rows) + 0.5) * resolution_m
    gx, gy = np.meshgrid(xs, ys)
    return gx, gy


def _segment_distance(gx: FloatArray, gy: FloatArray, seg: Segment) -> FloatArray:
    (ax, ay), (bx, by) = seg.start_m, seg.end_m
    dx, dy = bx - ax, by - ay
    length2 = dx * dx + dy * dy
    if length2 == 0.0:
        t = np.zeros_like(gx)
    else:
        t = np.clip(((gx - ax) * dx + (gy - ay) * dy) / length2, 0.0, 1.0)
    result: FloatArray = np.hypot(gx - (ax + t * dx), gy - (ay + t * dy))
    return result


def _inside_polygon(gx: FloatArray, gy: FloatArray, pts: Sequence[Point]) -> BoolGrid:
    """Even-odd rule, vectorised over the points, one loop over the edges."""
    inside = np.zeros(gx.shape, dtype=bool)
    n = len(pts)
    for i in range(n):
        (x0, y0), (x1, y1) = pts[i], pts[(i + 1) % n]
        if y0 == y1:
            continue
        crosses = (gy >= min(y0, y1)) & (gy < max(y0, y1))
        x_at = x0 + (gy - y0) * (x1 - x0) / (y1 - y0)
        inside ^= crosses & (gx < x_at)
    return inside


def rasterise(
    shapes: Sequence[Shape], rows: int, cols: int, resolution_m: float, origin: Point
) -> BoolGrid:
    """Occupancy (True = occupied) of the given shapes on a grid; see the module docstring."""
    gx, gy = cell_centres(rows, cols, resolution_m, origin)
    grid = np.zeros((rows, cols), dtype=bool)
    min_half = 0.5 * math.sqrt(2.0) * resolution_m
    for shape in shapes:
        if isinstance(shape, Segment):
            half = max(0.5 * shape.thickness_m, min_half)
            grid |= _segment_distance(gx, gy, shape) <= half
        elif isinstance(shape, Circle):
            cx, cy = shape.center_m
            grid |= np.hypot(gx - cx, gy - cy) <= shape.radius_m
        else:
            grid |= _inside_polygon(gx, gy, shape.points_m)
    return grid


# ---------------------------------------------------------------------------------------------
# TOML


_TOP_KEYS = {
    "name",
    "description",
    "resolution_m",
    "bounds_m",
    "grid",
    "origin_m",
    "start",
    "goal",
    "goal_tolerance_m",
    "segments",
    "circles",
    "polygons",
    "areas",
}


def _num(value: Any, where: str, positive: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise WorldError(f"{where} must be a number, got {value!r}")
    if positive and value <= 0:
        raise WorldError(f"{where} must be positive, got {value!r}")
    return float(value)


def _pair(value: Any, where: str) -> Point:
    if not isinstance(value, list) or len(value) != 2:
        raise WorldError(f"{where} must be [x, y], got {value!r}")
    return (_num(value[0], where), _num(value[1], where))


def _table(
    value: Any, where: str, required: Sequence[str], optional: Sequence[str] = ()
) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise WorldError(f"{where} must be a table")
    unknown = sorted(set(value) - set(required) - set(optional))
    if unknown:
        raise WorldError(f"{where} has unknown key(s) {', '.join(unknown)}")
    missing = [k for k in required if k not in value]
    if missing:
        raise WorldError(f"{where} lacks key(s) {', '.join(missing)}")
    return value


def _list_of_tables(doc: dict[str, Any], key: str, where: str) -> list[dict[str, Any]]:
    items = doc.get(key, [])
    if not isinstance(items, list):
        raise WorldError(f"{where}: {key} must be an array of tables ([[{key}]])")
    return items


def parse_shapes(doc: dict[str, Any], where: str) -> list[Shape]:
    shapes: list[Shape] = []
    for i, t in enumerate(_list_of_tables(doc, "segments", where)):
        w = f"{where}: segments[{i}]"
        t = _table(t, w, ("from_m", "to_m"), ("thickness_m",))
        thickness = _num(t.get("thickness_m", 0.0), f"{w}.thickness_m")
        shapes.append(
            Segment(_pair(t["from_m"], f"{w}.from_m"), _pair(t["to_m"], f"{w}.to_m"), thickness)
        )
    for i, t in enumerate(_list_of_tables(doc, "circles", where)):
        w = f"{where}: circles[{i}]"
        t = _table(t, w, ("center_m", "radius_m"))
        shapes.append(
            Circle(
                _pair(t["center_m"], f"{w}.center_m"), _num(t["radius_m"], f"{w}.radius_m", True)
            )
        )
    for i, t in enumerate(_list_of_tables(doc, "polygons", where)):
        w = f"{where}: polygons[{i}]"
        t = _table(t, w, ("points_m",))
        pts = t["points_m"]
        if not isinstance(pts, list) or len(pts) < 3:
            raise WorldError(f"{w}.points_m must list at least 3 [x, y] points")
        shapes.append(Polygon(tuple(_pair(p, f"{w}.points_m") for p in pts)))
    return shapes


def parse_scenario(
    doc: dict[str, Any], where: str
) -> tuple[Pose | None, Point | None, float | None, tuple[Area, ...]]:
    """Start pose, goal, goal tolerance and named areas of a TOML world."""
    start: Pose | None = None
    if "start" in doc:
        t = _table(doc["start"], f"{where}: start", ("x_m", "y_m"), ("yaw_rad",))
        start = (
            _num(t["x_m"], f"{where}: start.x_m"),
            _num(t["y_m"], f"{where}: start.y_m"),
            _num(t.get("yaw_rad", 0.0), f"{where}: start.yaw_rad"),
        )
    goal: Point | None = None
    if "goal" in doc:
        t = _table(doc["goal"], f"{where}: goal", ("x_m", "y_m"))
        goal = (_num(t["x_m"], f"{where}: goal.x_m"), _num(t["y_m"], f"{where}: goal.y_m"))
    tolerance = None
    if "goal_tolerance_m" in doc:
        tolerance = _num(doc["goal_tolerance_m"], f"{where}: goal_tolerance_m", True)
    areas = []
    for i, t in enumerate(_list_of_tables(doc, "areas", where)):
        w = f"{where}: areas[{i}]"
        t = _table(t, w, ("name", "min_m", "max_m"))
        (x0, y0), (x1, y1) = _pair(t["min_m"], f"{w}.min_m"), _pair(t["max_m"], f"{w}.max_m")
        areas.append(Area(str(t["name"]), min(x0, x1), min(y0, y1), max(x0, x1), max(y0, y1)))
    return start, goal, tolerance, tuple(areas)


def load_toml_world(path: str | Path) -> World:
    """A geometric world from TOML (module docstring), optionally over a ``.npy`` grid."""
    p = Path(path)
    text = read_world_text(p, "world file")
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise WorldError(f"{p} is not valid TOML: {exc}") from None
    where = str(p)
    unknown = sorted(set(doc) - _TOP_KEYS)
    if unknown:
        raise WorldError(f"{where}: unknown key(s) {', '.join(unknown)}")
    res = _num(doc.get("resolution_m", DEFAULT_RESOLUTION_M), f"{where}: resolution_m", True)

    if "grid" in doc:
        origin = _pair(doc.get("origin_m", [0.0, 0.0]), f"{where}: origin_m")
        base = load_npy_grid(p.parent / str(doc["grid"]), res, origin)
        occupancy, unknown_mask = base.occupancy.copy(), base.unknown
        rows, cols = occupancy.shape
    else:
        if "bounds_m" not in doc:
            raise WorldError(f"{where}: give bounds_m = [x_min, y_min, x_max, y_max] (or a grid)")
        b = doc["bounds_m"]
        if not isinstance(b, list) or len(b) != 4:
            raise WorldError(f"{where}: bounds_m must be [x_min, y_min, x_max, y_max]")
        x0, y0, x1, y1 = (_num(v, f"{where}: bounds_m") for v in b)
        if not (x1 > x0 and y1 > y0):
            raise WorldError(f"{where}: bounds_m must have x_max > x_min and y_max > y_min")
        origin = (x0, y0)
        cols, rows = math.ceil((x1 - x0) / res - 1e-9), math.ceil((y1 - y0) / res - 1e-9)
        if rows * cols > 50_000_000:
            raise WorldError(f"{where}: {rows} x {cols} cells is too large a grid")
        occupancy = np.zeros((rows, cols), dtype=bool)
        unknown_mask = np.zeros((rows, cols), dtype=bool)

    occupancy |= rasterise(parse_shapes(doc, where), rows, cols, res, origin)
    start, goal, tolerance, areas = parse_scenario(doc, where)
    return World(
        name=str(doc.get("name", p.stem)),
        occupancy=occupancy,
        unknown=unknown_mask,
        resolution_m=res,
        origin_x_m=origin[0],
        origin_y_m=origin[1],
        start_pose=start,
        goal=goal,
        goal_tolerance_m=tolerance,
        areas=areas,
    )
