"""A local planner on the current scan: where ``assist`` steers when a via point is set (issue 28).

``plan_target(obstacles, goal_xy_m, settings, previous)`` is a pure function of one scan
(points in {R}), the via point in {R} and last cycle's path moved into this cycle's {R}
(``moved_path``, by the velocity last sent). It answers with a ``LocalPlan``: the point in {R}
the assistant's rules steer to this cycle (instead of the via point itself), the path it lies
on, the clearance that sets the speed, and the gap being crossed. The plan is made again
every cycle on the scan it was given; the last path only makes its own cells cheaper.

Steps (DESIGN 6, ``assist``; the paper has no planner, see the deviation in ``assist``):

1. **Local grid.** A square of ``2 window_m`` around the robot, cells ``cell_m`` wide, the
   robot on the centre cell. A cell's *clearance* is its centre's distance to the nearest scan
   point, capped at ``clearance_pref_m``: a distance transform of the points on the grid, made
   exact (a k-d tree) within a cell of ``clearance_min_m``, where it decides what is
   traversable (a gap 1.2 x the robot's width leaves 4 cm either side, less than the raster's
   error). Cells nearer the sensor than the return in their direction are *seen* free; the
   rest are *unknown* and cost ``unknown_cost`` times as much (optimistic: behind an obstacle
   is not known to be blocked).
2. **Traversable**: clearance >= ``clearance_min_m`` (half the footprint's width + 1 cm): the
   robot's centre can be there with its sides clear. Each cell costs
   w = 1 + ``clearance_weight`` (pref - c) / (pref - min) for c < pref, 1 above, so paths keep
   to the middle of bands and gaps (cost ~ 1 / clearance); cells of the last path
   ``keep_cost`` times that.
3. **Shortest path** (Dijkstra, ``scipy.sparse.csgraph``) over the 8-connected cells from the
   robot's: a step costs its length x the cost of the cell it enters. The end is the via
   point's cell when it is reachable; for a via point outside the window, the cell of the
   window's rim with the least path cost + straight distance to the via point; for one inside
   but out of reach, the cell with the least path cost + ``heuristic_weight`` x that distance.
4. **Gaps along their axis.** A *narrow* stretch of the path (clearance below ``narrow_m``:
   no room to turn the footprint in place) within ``horizon_m`` ahead may be a gap. At its
   narrowest cell, the closest pair of scan points one either side of the path (p_L, p_R) is
   its throat when the path crosses the segment between them and the pair lies across the
   path (not a wall beside it): the gap's middle M = (p_L + p_R) / 2, its axis n
   perpendicular to p_L - p_R, along the path. Off the axis and not yet at the gap's mouth,
   the robot first goes to the *entry point* E = M - s n, s the nearest distance in
   [``approach_min_m``, ``approach_max_m``] with the most room to turn there, when the way
   to E is clear (else along the path); at E, on the axis (within ``entry_tolerance_m``,
   facing along it; twice that once threading) or at the mouth, it steers at the axis point
   ``axis_lookahead_m`` ahead of its own projection on the axis (pure pursuit of the axis
   line), so it enters straight and centred. Without a gap ahead the target is the path
   point ``lookahead_m`` along it.

scipy's ndimage, sparse and spatial are imported when the first plan is made: a robot that
never plans does not carry their ~20 MB (issue 31's soak).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
from egc_common.scan import ObstaclePoints

if TYPE_CHECKING:
    from scipy.sparse import csr_matrix

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

_SQRT2 = math.sqrt(2.0)
# A throat's two points lie across the path: |cos| of their angle to it at most this.
_ACROSS = 0.6
# On a gap's axis and heading along it within this (rad): threaded without the entry point.
_LINED_UP_RAD = math.radians(15.0)


@dataclass(frozen=True, slots=True)
class PlanSettings:
    """The planner's settings (metres, 1). ``AssistParams.plan_settings`` builds them."""

    cell_m: float
    window_m: float
    clearance_min_m: float
    clearance_pref_m: float
    clearance_weight: float
    unknown_cost: float
    heuristic_weight: float
    narrow_m: float
    horizon_m: float
    lookahead_m: float
    axis_lookahead_m: float
    approach_min_m: float
    approach_max_m: float
    entry_tolerance_m: float
    keep_cost: float = 0.7


@dataclass(frozen=True, slots=True)
class LocalPlan:
    """One cycle's plan, all in {R}.

    ``target_xy_m``: where the rules steer; ``path_xy_m``: the planned cells' centres, from the
    robot; ``clearance_ahead_m``: the smallest clearance on the path within ``lookahead_m``;
    ``phase``: "path" (no gap ahead), "approach" (to a gap's entry point) or "thread" (along a
    gap's axis); ``gap``: (M, n) of that gap, else None."""

    target_xy_m: tuple[float, float]
    path_xy_m: FloatArray
    clearance_ahead_m: float
    phase: str
    gap: tuple[tuple[float, float], tuple[float, float]] | None = None


@lru_cache(maxsize=8)
def _layout(cell_m: float, window_m: float, bins: int) -> _Layout:
    half = round(window_m / cell_m)
    axis = (np.arange(2 * half + 1) - half) * cell_m
    xx, yy = np.meshgrid(axis, axis)  # [row = y, col = x]
    angle = np.arctan2(yy, xx)
    sector = np.minimum(((angle + math.pi) / (2.0 * math.pi) * bins).astype(np.int64), bins - 1)
    rim = np.zeros(xx.shape, dtype=bool)
    rim[[0, -1], :] = True
    rim[:, [0, -1]] = True
    n = 2 * half + 1
    own = np.arange(n * n).reshape(n, n)
    neighbours = np.empty((n * n, len(_NEIGHBOURS)), dtype=np.int32)
    for k, (dr, dc) in enumerate(_NEIGHBOURS):
        r, c = np.arange(n)[:, None] + dr, np.arange(n)[None, :] + dc
        ok = (r >= 0) & (r < n) & (c >= 0) & (c < n)
        neighbours[:, k] = np.where(
            ok, np.clip(r, 0, n - 1) * n + np.clip(c, 0, n - 1), own
        ).ravel()
    indptr = np.arange(0, len(_NEIGHBOURS) * n * n + 1, len(_NEIGHBOURS), dtype=np.int32)
    return _Layout(half, xx, yy, np.hypot(xx, yy), sector, rim, neighbours, indptr)


@dataclass(frozen=True, slots=True, eq=False)
class _Layout:
    """The grid's geometry for one (cell, window): built once, shared by every cycle."""

    half: int
    xx: FloatArray
    yy: FloatArray
    radius: FloatArray
    sector: IntArray
    rim: npt.NDArray[np.bool_]  # the window's outermost ring of cells
    # The 8-neighbour graph's fixed shape: every cell's neighbours (itself past the border)
    # and the CSR row pointers (8 entries a row).
    neighbours: npt.NDArray[np.int32]
    indptr: npt.NDArray[np.int32]


_BINS = 720  # angular sectors of the "seen" test (a quarter of a degree wider than 1 deg beams)
_NEIGHBOURS = ((-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1))
_LENGTHS = np.array([_SQRT2 if dr and dc else 1.0 for dr, dc in _NEIGHBOURS])


def seen_cells(x: FloatArray, y: FloatArray, layout: _Layout) -> npt.NDArray[np.bool_]:
    """Cells nearer the sensor than the return in their direction (the beam crossed them), as a
    mask indexed [row = y, col = x]; directions without a return are unknown."""
    reach = np.zeros(_BINS)
    if len(x):
        sector = np.minimum(
            ((np.arctan2(y, x) + math.pi) / (2.0 * math.pi) * _BINS).astype(np.int64), _BINS - 1
        )
        np.maximum.at(reach, sector, np.hypot(x, y))
        # A beam lights its neighbour sectors too (beams may be coarser than the sectors).
        reach = np.maximum(reach, np.maximum(np.roll(reach, 1), np.roll(reach, -1)))
    return layout.radius < reach[layout.sector]


def clearances(obstacles: ObstaclePoints, layout: _Layout, s: PlanSettings) -> FloatArray:
    """Each cell's distance to the nearest scan point, capped at ``clearance_pref_m``: a
    distance transform of the points on the grid, made exact (k-d tree) where it decides
    traversability (within a cell of ``clearance_min_m``)."""
    from scipy.ndimage import distance_transform_edt
    from scipy.spatial import cKDTree

    n = 2 * layout.half + 1
    if len(obstacles) == 0:
        return np.full((n, n), s.clearance_pref_m)
    ci = np.rint(obstacles.x / s.cell_m).astype(np.int64) + layout.half
    ri = np.rint(obstacles.y / s.cell_m).astype(np.int64) + layout.half
    ok = (ci >= 0) & (ci < n) & (ri >= 0) & (ri < n)
    free = np.ones((n, n), dtype=bool)
    free[ri[ok], ci[ok]] = False
    raster: FloatArray = np.asarray(distance_transform_edt(free), dtype=np.float64)
    clearance = np.minimum(raster * s.cell_m, s.clearance_pref_m)
    edge = np.abs(clearance - s.clearance_min_m) <= s.cell_m
    if edge.any():
        d, _ = cKDTree(obstacles.xy).query(
            np.column_stack((layout.xx[edge], layout.yy[edge])),
            distance_upper_bound=s.clearance_pref_m,
        )
        clearance[edge] = np.minimum(d, s.clearance_pref_m)
    return clearance


def _graph(
    trav: npt.NDArray[np.bool_], cost: FloatArray, cell_m: float, layout: _Layout
) -> csr_matrix:
    """The 8-connected graph of the cells (node = row-major cell index): a step costs its
    length x the cost of the cell it enters, inf into a cell that is not traversable (never
    taken); past the window's border a cell's neighbour is itself (a loop, never taken).
    Every row has its 8 entries, so the CSR is built without a sort."""
    from scipy.sparse import csr_matrix

    entered = np.where(trav, cost, np.inf).ravel()
    weights = entered[layout.neighbours] * (_LENGTHS * cell_m)
    size = len(entered)
    return csr_matrix(
        (weights.ravel(), layout.neighbours.ravel(), layout.indptr), shape=(size, size)
    )


def moved_path(
    path_xy_m: tuple[tuple[float, float], ...], v_mps: float, w_radps: float, dt_s: float
) -> tuple[tuple[float, float], ...]:
    """Last cycle's path in this cycle's {R}: the robot drove (v, w) for dt since (an arc)."""
    if not path_xy_m or dt_s <= 0.0:
        return path_xy_m
    dth = w_radps * dt_s
    if abs(dth) < 1e-9:
        dx, dy = v_mps * dt_s, 0.0
    else:
        radius = v_mps / w_radps
        dx, dy = radius * math.sin(dth), radius * (1.0 - math.cos(dth))
    c, sn = math.cos(dth), math.sin(dth)
    pts = np.asarray(path_xy_m) - (dx, dy)
    out = np.column_stack((c * pts[:, 0] + sn * pts[:, 1], -sn * pts[:, 0] + c * pts[:, 1]))
    return tuple((float(a), float(b)) for a, b in out)


def plan_target(
    obstacles: ObstaclePoints,
    goal_xy_m: tuple[float, float],
    s: PlanSettings,
    previous: tuple[tuple[float, float], ...] = (),
    threading: bool = False,
) -> LocalPlan | None:
    """The cycle's plan (module docstring); None when the robot's own cell is not traversable
    (then the rules decide alone). ``previous``: last cycle's path in this {R}
    (``moved_path``); cells along it cost ``keep_cost`` times as much, so two ways of about
    the same cost do not take turns as the robot moves (it rocked between two gaps).
    ``threading``: last cycle's phase was "thread"."""
    layout = _layout(s.cell_m, s.window_m, _BINS)
    half = layout.half
    n = 2 * half + 1
    gx, gy = goal_xy_m
    clearance = clearances(obstacles, layout, s)
    trav = clearance >= s.clearance_min_m
    if not trav[half, half]:
        return None
    span = max(s.clearance_pref_m - s.clearance_min_m, 1e-9)
    cost = 1.0 + s.clearance_weight * (s.clearance_pref_m - clearance) / span
    cost = np.where(seen_cells(obstacles.x, obstacles.y, layout), cost, s.unknown_cost * cost)
    if previous:
        kept = np.asarray(previous)
        kc = np.rint(kept[:, 0] / s.cell_m).astype(np.int64) + half
        kr = np.rint(kept[:, 1] / s.cell_m).astype(np.int64) + half
        inside = (kc >= 1) & (kc < n - 1) & (kr >= 1) & (kr < n - 1)
        along_kept = np.zeros((n, n), dtype=bool)
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                along_kept[kr[inside] + dr, kc[inside] + dc] = True
        cost = np.where(along_kept, s.keep_cost * cost, cost)
    from scipy.sparse.csgraph import dijkstra

    graph = _graph(trav, cost, s.cell_m, layout)
    start = half * n + half
    dist, pred = dijkstra(graph, directed=True, indices=start, return_predecessors=True)
    gc, gr = round(float(gx) / s.cell_m) + half, round(float(gy) / s.cell_m) + half
    goal_id = gr * n + gc if 0 <= gc < n and 0 <= gr < n else -1
    if goal_id >= 0 and math.isfinite(dist[goal_id]):
        end = goal_id
    else:
        to_goal = np.hypot(layout.xx.ravel() - gx, layout.yy.ravel() - gy)
        rim = layout.rim.ravel() & np.isfinite(dist)
        if goal_id < 0 and rim.any():  # the way on leaves the window: through its rim
            end = int(np.argmin(np.where(rim, dist + to_goal, np.inf)))
        else:  # the via point is in the window but out of reach: get as near it as possible
            end = int(np.argmin(dist + s.heuristic_weight * to_goal))
    nodes = [end]
    while nodes[-1] != start:
        nodes.append(int(pred[nodes[-1]]))
    order = np.asarray(nodes[::-1], dtype=np.int64)
    path = np.column_stack((layout.xx.ravel()[order], layout.yy.ravel()[order]))
    path_clear = clearance.ravel()[order]
    steps = np.hypot(*np.diff(path, axis=0).T) if len(path) > 1 else np.zeros(0)
    along = np.concatenate(([0.0], np.cumsum(steps)))
    within = along <= s.horizon_m
    ahead = float(path_clear[along <= s.lookahead_m].min())

    narrow = np.flatnonzero(within & (path_clear < s.narrow_m))
    gap = None
    if len(narrow):
        first = last = int(narrow[0])
        while last + 1 < len(path) and path_clear[last + 1] < s.narrow_m and within[last + 1]:
            last += 1
        throat = first + int(np.argmin(path_clear[first : last + 1]))
        gap = _gap_at(obstacles, path, throat, s)
    if gap is None:
        k = min(int(np.searchsorted(along, s.lookahead_m)), len(path) - 1)
        target = (gx, gy) if k == 0 else (float(path[k, 0]), float(path[k, 1]))
        return LocalPlan(target, path, ahead, "path")
    (mx, my), (nx, ny) = gap
    a = -(mx * nx + my * ny)  # the robot's coordinate along the axis (0 at the middle)
    off = abs(mx * ny - my * nx)  # and its distance from the axis
    entry_s = _entry_distance(obstacles, (mx, my), (nx, ny), s)
    ex, ey = mx - entry_s * nx, my - entry_s * ny
    # To the entry point first, unless already there, on the axis facing along it, or at the
    # gap's mouth (where there is no room to turn any more).
    at_entry = math.hypot(ex, ey) <= s.entry_tolerance_m
    lined_up = off <= s.entry_tolerance_m and abs(math.atan2(ny, nx)) <= _LINED_UP_RAD
    # Threading last cycle and still near the axis: go on (turning on the spot at the entry
    # point swings the robot's heading, and with it the tests above, back and forth).
    lined_up = lined_up or (threading and off <= 2.0 * s.entry_tolerance_m)
    if not (at_entry or lined_up or a >= -s.approach_min_m):
        if _segment_clear(obstacles, (ex, ey), s.clearance_min_m):
            return LocalPlan((ex, ey), path, ahead, "approach", gap)
        k = min(int(np.searchsorted(along, s.lookahead_m)), len(path) - 1)
        return LocalPlan((float(path[k, 0]), float(path[k, 1])), path, ahead, "path", gap)
    t = max(a, -entry_s) + s.axis_lookahead_m
    return LocalPlan((mx + t * nx, my + t * ny), path, ahead, "thread", gap)


def _gap_at(
    obstacles: ObstaclePoints, path: FloatArray, k: int, s: PlanSettings
) -> tuple[tuple[float, float], tuple[float, float]] | None:
    """The gap the path crosses at cell ``k``: of the scan points near it, the closest pair
    with one on either side of the path (the throat), its middle and the axis through it
    (perpendicular to the pair, along the path). None when it is not a gap: one side empty,
    the pair as wide as a turn needs, lying along the path rather than across it, or not
    where the path crosses (a wall beside or behind the path)."""
    lo, hi = max(k - 2, 0), min(k + 2, len(path) - 1)
    if hi == lo:
        return None
    dx, dy = path[hi] - path[lo]
    norm = math.hypot(dx, dy)
    dx, dy = dx / norm, dy / norm
    px, py = float(path[k, 0]), float(path[k, 1])
    rx, ry = obstacles.x - px, obstacles.y - py
    d2 = rx * rx + ry * ry
    cross = dx * ry - dy * rx
    reach2 = (s.narrow_m + 2.0 * s.cell_m) ** 2
    left = np.flatnonzero((cross > 0.0) & (d2 <= reach2))
    right = np.flatnonzero((cross < 0.0) & (d2 <= reach2))
    if len(left) == 0 or len(right) == 0:
        return None
    lx = obstacles.x[left][:, None] - obstacles.x[right][None, :]
    ly = obstacles.y[left][:, None] - obstacles.y[right][None, :]
    mx = 0.5 * (obstacles.x[left][:, None] + obstacles.x[right][None, :])
    my = 0.5 * (obstacles.y[left][:, None] + obstacles.y[right][None, :])
    # Ties (the two walls of a corridor): the pair whose middle is nearest the path cell.
    score = np.hypot(lx, ly) + 0.1 * np.hypot(mx - px, my - py)
    i, j = np.unravel_index(int(np.argmin(score)), score.shape)
    gx, gy = float(lx[i, j]), float(ly[i, j])
    width = math.hypot(gx, gy)
    if not 0.0 < width < 2.0 * s.narrow_m or abs(gx * dx + gy * dy) > _ACROSS * width:
        return None
    # The path crosses the throat: its cell lies on the segment between the two points.
    ox = px - float(obstacles.x[right[j]])
    oy = py - float(obstacles.y[right[j]])
    if abs(gx * oy - gy * ox) > 2.0 * s.cell_m * width:
        return None
    if not 0.0 <= gx * ox + gy * oy <= width * width:
        return None
    nx, ny = gy / width, -gx / width
    if nx * dx + ny * dy < 0.0:
        nx, ny = -nx, -ny
    return (float(mx[i, j]), float(my[i, j])), (nx, ny)


def _segment_clear(obstacles: ObstaclePoints, end: tuple[float, float], clearance_m: float) -> bool:
    """No scan point within ``clearance_m`` of the segment from the robot to ``end``."""
    ex, ey = end
    length2 = ex * ex + ey * ey
    if length2 <= 0.0:
        return True
    t = np.clip((obstacles.x * ex + obstacles.y * ey) / length2, 0.0, 1.0)
    d2 = (obstacles.x - t * ex) ** 2 + (obstacles.y - t * ey) ** 2
    return bool(d2.min() >= clearance_m * clearance_m)


def _entry_distance(
    obstacles: ObstaclePoints,
    middle: tuple[float, float],
    axis: tuple[float, float],
    s: PlanSettings,
) -> float:
    """Where on the axis, in [approach_min, approach_max] before the gap's middle, the robot
    turns to face the gap: the roomiest place (clearance capped at clearance_pref_m), the
    nearest of equals."""
    ds = np.arange(s.approach_min_m, s.approach_max_m + 1e-9, 0.5 * s.cell_m)
    px, py = middle[0] - ds * axis[0], middle[1] - ds * axis[1]
    d2 = (obstacles.x[None, :] - px[:, None]) ** 2 + (obstacles.y[None, :] - py[:, None]) ** 2
    room = np.minimum(np.sqrt(d2.min(axis=1)), s.clearance_pref_m)
    return float(ds[np.flatnonzero(room >= room.max() - 1e-9)[0]])
