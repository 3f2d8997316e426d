"""Seeded dense-clutter worlds sized to the robot (issue 28, item 5): every way from start to
goal leads through gaps only 1.2 to 1.5 times the robot's width.

``clutter_world(seed, params)`` is a pure function of the seed and the parameters, like
``random_field.random_world``. ``ClutterParams.for_robot(width_m, reach_m)`` sizes a world for
a robot: the gaps from its width, the room (and the free bands where it turns) from its reach.
The seed picks one of two kinds:

- ``cylinders``: a field of discs in staggered columns across the whole room, wall to wall.
  Within a column every gap (disc to disc, disc to wall) is drawn in
  [``gap_min_ratio``, ``gap_max_ratio``] x the width; between columns a free band wide enough
  for the robot to turn in place (2 x reach + ``turn_margin_m``..), so the way is a weave
  through one gap of every column.
- ``baffles``: walls across the room, each with one opening of 1.2-1.5 x the width, the
  openings alternating between the upper and lower half (a zig-zag); a thick wall makes its
  opening a short corridor of that width.

Every world is *solvable*: a disc of the robot's half width + ``passage_margin_m`` links start
and goal on the grid's distance transform (``field_world.linked``, as for the random worlds), and the
straight start-goal line is blocked for that disc at least once, so a goal-seeking operator
(``operators.GoalOperator``) must be helped through. Start on the left, goal on the right,
both ``margin_m`` from the side walls so the robot can turn where it starts.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from egc_sim.field_world import clearance_m, field_world, linked
from egc_sim.grid_world import World, WorldError
from egc_sim.shapes import Circle, Polygon, Shape, rasterise

KINDS = ("cylinders", "baffles")
_WALL_M = 0.1
_ATTEMPTS = 200
# The Jackal (DESIGN 14's profile): 0.430 m wide, 0.333 m of reach.
_JACKAL_WIDTH_M = 0.43
_JACKAL_REACH_M = 0.3335


@dataclass(frozen=True, slots=True)
class ClutterParams:
    """The robot's size, the gap ratios and the room (metres).

    ``robot_width_m`` sets the gaps (``gap_*_ratio`` x it); ``robot_reach_m`` the free bands
    between columns/walls (2 x reach + ``turn_margin_m`` .. + ``band_extra_m``) and the start
    and goal margins. ``resolution_m`` is fine enough (1/17 of the Jackal's width) that a gap
    keeps its drawn width on the grid within a cell."""

    robot_width_m: float = _JACKAL_WIDTH_M
    robot_reach_m: float = _JACKAL_REACH_M
    gap_min_ratio: float = 1.2
    gap_max_ratio: float = 1.5
    width_m: float = 8.0
    height_m: float = 4.0
    resolution_m: float = 0.025
    radius_min_m: float = 0.1
    radius_max_m: float = 0.3
    turn_margin_m: float = 0.15
    band_extra_m: float = 0.35
    wall_min_m: float = 0.1
    wall_max_m: float = 0.8
    margin_m: float = 0.7
    passage_margin_m: float = 0.02
    goal_tolerance_m: float = 0.3

    @property
    def gap_min_m(self) -> float:
        return self.gap_min_ratio * self.robot_width_m

    @property
    def gap_max_m(self) -> float:
        return self.gap_max_ratio * self.robot_width_m

    @property
    def passage_m(self) -> float:
        """Radius of the disc that must link start and goal: half the width + a little."""
        return 0.5 * self.robot_width_m + self.passage_margin_m

    @staticmethod
    def for_robot(width_m: float, reach_m: float) -> ClutterParams:
        """Worlds for a robot ``width_m`` wide whose footprint reaches ``reach_m`` from its
        centre. The Jackal gets the defaults; every room length scales with the reach (never
        below the Jackal's), the gaps follow the width, disc sizes both."""
        if not (math.isfinite(width_m) and math.isfinite(reach_m)) or width_m <= 0.0:
            raise WorldError(f"clutter world needs a positive robot width, got {width_m!r}")
        if reach_m < 0.5 * width_m:
            raise WorldError(f"robot reach {reach_m} m is less than half its width {width_m} m")
        d = ClutterParams()
        scale = max(1.0, reach_m / d.robot_reach_m)
        return ClutterParams(
            robot_width_m=width_m,
            robot_reach_m=reach_m,
            width_m=d.width_m * scale,
            height_m=d.height_m * scale,
            radius_min_m=d.radius_min_m * scale,
            radius_max_m=d.radius_max_m * scale,
            margin_m=max(d.margin_m, reach_m + _WALL_M + 0.15),
            goal_tolerance_m=d.goal_tolerance_m,
        )


def _box(x0: float, y0: float, x1: float, y1: float) -> Polygon:
    return Polygon(((x0, y0), (x1, y0), (x1, y1), (x0, y1)))


def _room(p: ClutterParams) -> list[Shape]:
    w, h, t = p.width_m, p.height_m, _WALL_M
    return [_box(0, 0, w, t), _box(0, h - t, w, h), _box(0, 0, t, h), _box(w - t, 0, w, h)]


def _band(rng: np.random.Generator, p: ClutterParams) -> float:
    """Clear width of a free band between two columns or walls: room to turn in place."""
    low = 2.0 * p.robot_reach_m + p.turn_margin_m
    return float(rng.uniform(low, low + p.band_extra_m))


def _column(rng: np.random.Generator, x: float, p: ClutterParams) -> tuple[list[Shape], float]:
    """Discs on the line x = const from wall to wall, every gap in [gap_min_m, gap_max_m];
    returns the discs and the largest radius."""
    lo, hi = _WALL_M, p.height_m - _WALL_M
    mean_gap = 0.5 * (p.gap_min_m + p.gap_max_m)
    mean_d = p.radius_min_m + p.radius_max_m
    n = max(1, round((hi - lo - mean_gap) / (mean_gap + mean_d)))
    for _ in range(_ATTEMPTS):
        gaps = rng.uniform(p.gap_min_m, p.gap_max_m, size=n + 1)
        diameters = rng.uniform(2 * p.radius_min_m, 2 * p.radius_max_m, size=n)
        # The discs take what the gaps leave: scale the drawn diameters to fill the column.
        diameters *= (hi - lo - gaps.sum()) / diameters.sum()
        if diameters.min() >= 2 * p.radius_min_m and diameters.max() <= 2 * p.radius_max_m:
            break
    else:  # pragma: no cover - the counts above make this all but impossible
        raise WorldError("cannot fill a clutter column with the given gaps and radii")
    shapes: list[Shape] = []
    y = lo
    for g, d in zip(gaps[:-1], diameters, strict=True):
        y += g
        shapes.append(Circle((x, y + 0.5 * d), 0.5 * d))
        y += d
    return shapes, 0.5 * float(diameters.max())


def _cylinders(rng: np.random.Generator, p: ClutterParams) -> list[Shape]:
    shapes: list[Shape] = []
    x_end = p.width_m - 2.0 * p.margin_m
    x = 2.0 * p.margin_m + p.radius_max_m
    while x < x_end - p.radius_max_m:
        column, _ = _column(rng, x, p)
        shapes += column
        x += 2 * p.radius_max_m + _band(rng, p)
    return shapes


def _baffles(rng: np.random.Generator, p: ClutterParams) -> list[Shape]:
    shapes: list[Shape] = []
    lo, hi = _WALL_M, p.height_m - _WALL_M
    x = 2.0 * p.margin_m
    upper = bool(rng.random() < 0.5)
    while True:
        thick = float(rng.uniform(p.wall_min_m, p.wall_max_m))
        if x + thick > p.width_m - 2.0 * p.margin_m:
            break
        gap = float(rng.uniform(p.gap_min_m, p.gap_max_m))
        mid = 0.5 * (lo + hi)
        # The opening lies wholly in one half (alternating), at least a gap from the wall.
        y0 = float(rng.uniform(mid, hi - 2 * gap) if upper else rng.uniform(lo + gap, mid - gap))
        shapes += [_box(x, lo, x + thick, y0), _box(x, y0 + gap, x + thick, hi)]
        upper = not upper
        x += thick + _band(rng, p)
    return shapes


def line_blocked(
    clearance_m: np.ndarray,
    radius_m: float,
    start: tuple[float, float],
    goal: tuple[float, float],
    resolution_m: float,
) -> bool:
    """Whether a disc of ``radius_m`` sliding straight from start to goal touches something."""
    n = int(math.dist(start, goal) / (0.5 * resolution_m)) + 2
    t = np.linspace(0.0, 1.0, n)
    xs = start[0] + t * (goal[0] - start[0])
    ys = start[1] + t * (goal[1] - start[1])
    rows, cols = (ys / resolution_m).astype(int), (xs / resolution_m).astype(int)
    return bool((clearance_m[rows, cols] < radius_m).any())


def clutter_world(seed: int, params: ClutterParams | None = None) -> World:
    """A solvable dense-clutter world for ``seed`` (module docstring); WorldError if none."""
    p = params or ClutterParams()
    if not p.gap_min_ratio <= p.gap_max_ratio or p.gap_min_m < 2 * p.passage_m:
        raise WorldError(
            f"clutter gaps {p.gap_min_ratio}-{p.gap_max_ratio} x the width leave no passage"
        )
    if p.width_m < 4 * p.margin_m + 1.0 or p.height_m < 2 * p.margin_m:
        raise WorldError("clutter world too small for its start/goal margins")
    rng = np.random.default_rng(seed)
    kind = KINDS[int(rng.integers(len(KINDS)))]
    res = p.resolution_m
    rows, cols = round(p.height_m / res), round(p.width_m / res)
    for _ in range(_ATTEMPTS):
        start = (p.margin_m, float(rng.uniform(p.margin_m, p.height_m - p.margin_m)))
        goal = (
            p.width_m - p.margin_m,
            float(rng.uniform(p.margin_m, p.height_m - p.margin_m)),
        )
        inner = _cylinders(rng, p) if kind == "cylinders" else _baffles(rng, p)
        occupancy = rasterise([*_room(p), *inner], rows, cols, res, (0.0, 0.0))
        clearance = clearance_m(occupancy, res)
        if linked(clearance, p.passage_m, start, goal, res) and line_blocked(
            clearance, p.passage_m, start, goal, res
        ):
            return field_world(f"clutter:{seed}", occupancy, res, start, goal, p.goal_tolerance_m)
    raise WorldError(f"no solvable clutter world found for seed {seed} in {_ATTEMPTS} attempts")
