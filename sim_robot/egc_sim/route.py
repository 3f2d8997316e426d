"""The ``route`` operator model (DESIGN 10): knows the building, not what is in it.

A person with the floor plan: before driving, a route is planned on the map given to the
operator (``plan_route``); then the stick follows it, pure-pursuit style, from the pose the
operator view shows (the newest arrived telemetry, after a reaction time, as for ``sighted``).
The scan is not looked at: obstacles that are not on the map are met, not avoided (in shared
mode the robot's filter avoids them).

Planning: the map's blocked cells are inflated by the robot's half-width plus ``margin_m`` (the
robot's centre may not enter them); Dijkstra over the free cells, 8-connected, each step costing
its length times ``1 + wall_weight * max(0, 1 - clearance / wall_m)`` so that the route keeps
to the middle of corridors and doorways rather than grazing their walls. A start or goal inside
the inflated obstacles is moved to the nearest free cell. No route: ``RouteError``.

In shared mode the robot's filter may refuse the planned line where it passes obstacles closer
than the filter's guide circle; the route operator, who does not look at the scan, keeps
asking, and the run can stall there. That is a finding of the experiments, not a bug of the
model: a blind operator and a cautious filter dead-lock.

``building_map`` gives "the building without its furniture": blocked blobs smaller than
``max_extent_m`` in both directions (bins, boxes, the random worlds' obstacles) are removed,
walls stay; ``route:map=building`` plans on that.

Following: the route's point nearest to the seen pose (searched forward from the last one, so
the progress never goes back), then the point ``lookahead_m`` further along the route; the
heading error to it gives y_o = clamp(gain * error / pi), x_o = max(cos(error), 0).
"""

from __future__ import annotations

import hashlib
import itertools
import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import numpy.typing as npt
from egc_common.joystick import clamp_unit
from egc_common.kinematics import wrap_angle

from egc_sim.grid_world import BoolGrid, Pose, World
from egc_sim.observation import FloatArray, Observation, ViewBuffer
from egc_sim.operators import Stick, check_mode

_NEIGHBOURS = ((0, 1), (1, 0), (1, 1), (1, -1))  # the other four by symmetry


class RouteError(ValueError):
    """No route from start to goal on the operator's map."""


@dataclass(frozen=True, slots=True)
class RouteParams:
    """Planning and following (module docstring); lengths in m, times in s."""

    reaction_s: float = 0.25
    margin_m: float = 0.05
    wall_m: float = 1.0
    wall_weight: float = 4.0
    lookahead_m: float = 0.8
    gain: float = 2.0

    def __post_init__(self) -> None:
        for name in ("reaction_s", "margin_m", "wall_weight"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"route operator: {name} must be >= 0, got {value}")
        for name in ("wall_m", "lookahead_m", "gain"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"route operator: {name} must be > 0, got {value}")


def building_map(occupancy: BoolGrid, resolution_m: float, max_extent_m: float = 1.5) -> BoolGrid:
    """``occupancy`` without blocked blobs smaller than ``max_extent_m`` both ways (furniture)."""
    from scipy import ndimage

    occ = np.asarray(occupancy, dtype=bool)
    labels, _ = ndimage.label(occ, structure=np.ones((3, 3), dtype=bool))
    out = occ.copy()
    limit = max_extent_m / resolution_m
    for index, box in enumerate(ndimage.find_objects(labels), start=1):
        if box is None:
            continue
        rows = box[0].stop - box[0].start
        cols = box[1].stop - box[1].start
        touches_edge = (
            box[0].start == 0
            or box[1].start == 0
            or box[0].stop == occ.shape[0]
            or box[1].stop == occ.shape[1]
        )
        if rows < limit and cols < limit and not touches_edge:
            out[box][labels[box] == index] = False
    return out


def _grid_key(occupancy: BoolGrid) -> str:
    occ = np.ascontiguousarray(occupancy, dtype=bool)
    return hashlib.sha256(np.packbits(occ).tobytes() + str(occ.shape).encode()).hexdigest()


_GRIDS: dict[str, BoolGrid] = {}


def plan_route(
    occupancy: BoolGrid,
    resolution_m: float,
    origin: tuple[float, float],
    start: tuple[float, float],
    goal: tuple[float, float],
    clearance_m: float,
    wall_m: float = 1.0,
    wall_weight: float = 4.0,
) -> FloatArray:
    """The route (M, 2) in world metres from ``start`` to ``goal`` (module docstring).

    Row 0 of ``occupancy`` is the bottom row (``grid_world``). Results are cached per map.
    """
    occ = np.ascontiguousarray(occupancy, dtype=bool)
    key = _grid_key(occ)
    _GRIDS[key] = occ
    if len(_GRIDS) > 8:
        del _GRIDS[next(iter(_GRIDS))]
    cells = _plan_cells(
        key,
        float(resolution_m),
        (float(origin[0]), float(origin[1])),
        (float(start[0]), float(start[1])),
        (float(goal[0]), float(goal[1])),
        float(clearance_m),
        float(wall_m),
        float(wall_weight),
    )
    route: FloatArray = np.empty((len(cells), 2), dtype=np.float64)
    route[:, 0] = origin[0] + (cells[:, 1] + 0.5) * resolution_m
    route[:, 1] = origin[1] + (cells[:, 0] + 0.5) * resolution_m
    route[0] = start
    route[-1] = goal
    return route


def nearest_free(free: BoolGrid, cell: tuple[int, int]) -> tuple[int, int]:
    rows, cols = free.shape
    r, c = cell
    if 0 <= r < rows and 0 <= c < cols and free[r, c]:
        return r, c
    rr, cc = np.nonzero(free)
    if len(rr) == 0:
        raise RouteError("the map has no room for the robot anywhere")
    i = int(np.argmin((rr - r) ** 2 + (cc - c) ** 2))
    return int(rr[i]), int(cc[i])


@lru_cache(maxsize=32)
def _plan_cells(
    key: str,
    res: float,
    origin: tuple[float, float],
    start: tuple[float, float],
    goal: tuple[float, float],
    clearance_m: float,
    wall_m: float,
    wall_weight: float,
) -> npt.NDArray[np.int64]:
    from scipy import ndimage

    occ = _GRIDS[key]
    # Distance (m) from each cell centre to the nearest blocked cell; outside the grid blocks.
    padded = np.pad(~occ, 1, constant_values=False)
    distance = ndimage.distance_transform_edt(padded)[1:-1, 1:-1] * res
    free = distance > clearance_m

    def cell_of(p: tuple[float, float]) -> tuple[int, int]:
        return math.floor((p[1] - origin[1]) / res), math.floor((p[0] - origin[0]) / res)

    s_cell = nearest_free(free, cell_of(start))
    g_cell = nearest_free(free, cell_of(goal))
    penalty = 1.0 + wall_weight * np.clip(1.0 - distance / wall_m, 0.0, None)
    cells = grid_path(free, penalty, s_cell, g_cell)
    if cells is None:
        raise RouteError(
            f"no route from ({start[0]:.2f}, {start[1]:.2f}) to ({goal[0]:.2f}, {goal[1]:.2f}) "
            f"for a robot of half-width {clearance_m:.2f} m on this map"
        )
    return cells


def grid_path(
    free: BoolGrid,
    penalty: npt.NDArray[np.float64],
    start_cell: tuple[int, int],
    goal_cell: tuple[int, int],
) -> npt.NDArray[np.int64] | None:
    """The cheapest 8-connected path over the ``free`` cells, (K, 2) (row, col) from
    ``start_cell`` to ``goal_cell`` (both free), or None when they are not connected.

    A step costs its length (in cells) times the mean of ``penalty`` at its two ends (Dijkstra).
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import dijkstra

    rows, cols = free.shape
    index = np.full(free.shape, -1, dtype=np.int64)
    fr, fc = np.nonzero(free)
    index[fr, fc] = np.arange(len(fr))
    src: list[npt.NDArray[np.int64]] = []
    dst: list[npt.NDArray[np.int64]] = []
    weight: list[npt.NDArray[np.float64]] = []
    for dr, dc in _NEIGHBOURS:
        a = free[max(0, -dr) : rows - max(0, dr), max(0, -dc) : cols - max(0, dc)]
        b = free[max(0, dr) : rows + min(0, dr) or None, max(0, dc) : cols + min(0, dc) or None]
        both = a & b
        ar, ac = np.nonzero(both)
        ar = ar + max(0, -dr)
        ac = ac + max(0, -dc)
        br, bc = ar + dr, ac + dc
        length = math.hypot(dr, dc)
        w = 0.5 * length * (penalty[ar, ac] + penalty[br, bc])
        ia, ib = index[ar, ac], index[br, bc]
        src += [ia, ib]
        dst += [ib, ia]
        weight += [w, w]
    n = len(fr)
    graph = coo_matrix(
        (np.concatenate(weight), (np.concatenate(src), np.concatenate(dst))), shape=(n, n)
    ).tocsr()
    s_index, g_index = int(index[start_cell]), int(index[goal_cell])
    _, predecessors = dijkstra(graph, directed=True, indices=s_index, return_predecessors=True)
    if s_index != g_index and predecessors[g_index] < 0:
        return None
    chain = [g_index]
    while chain[-1] != s_index:
        chain.append(int(predecessors[chain[-1]]))
    chain.reverse()
    ids = np.asarray(chain, dtype=np.int64)
    return np.stack([fr[ids], fc[ids]], axis=1).astype(np.int64)


class RouteOperator:
    """Follows a route planned on the operator's map (module docstring)."""

    def __init__(
        self,
        route: FloatArray,
        mode: str = "shared",
        params: RouteParams | None = None,
    ) -> None:
        r = np.asarray(route, dtype=np.float64)
        if r.ndim != 2 or r.shape[1] != 2 or len(r) < 1:
            raise ValueError("a route is an (M, 2) array of points")
        self.route = r
        self.mode = check_mode(mode)
        self.params = params or RouteParams()
        self.view = ViewBuffer(self.params.reaction_s)
        steps = np.hypot(*np.diff(r, axis=0).T) if len(r) > 1 else np.zeros(0)
        self._along = np.concatenate([[0.0], np.cumsum(steps)])
        self._progress = 0

    @classmethod
    def on_world(
        cls,
        world: World,
        start: Pose,
        goal: tuple[float, float],
        half_width_m: float,
        mode: str = "shared",
        params: RouteParams | None = None,
        building_only: bool = False,
    ) -> RouteOperator:
        """Plan on ``world``'s map (or its ``building_map``) and follow that route."""
        p = params or RouteParams()
        occ = world.occupancy
        if building_only:
            occ = building_map(occ, world.resolution_m)
        route = plan_route(
            occ,
            world.resolution_m,
            world.origin,
            (start[0], start[1]),
            goal,
            half_width_m + p.margin_m,
            p.wall_m,
            p.wall_weight,
        )
        return cls(route, mode, p)

    @property
    def length_m(self) -> float:
        return float(self._along[-1])

    def observe(self, t_s: float, observation: Observation) -> None:
        self.view.observe(t_s, observation)

    def target(self, x: float, y: float) -> tuple[float, float]:
        """The point ``lookahead_m`` along the route past the point nearest to (x, y)."""
        r, along = self.route, self._along
        # Search forward only, within a window, so that a route passing near itself is safe.
        end = int(np.searchsorted(along, along[self._progress] + 3.0, side="right"))
        window = r[self._progress : max(end, self._progress + 1)]
        d2 = (window[:, 0] - x) ** 2 + (window[:, 1] - y) ** 2
        self._progress += int(np.argmin(d2))
        goal_along = along[self._progress] + self.params.lookahead_m
        i = min(int(np.searchsorted(along, goal_along)), len(r) - 1)
        return float(r[i, 0]), float(r[i, 1])

    def command(self, t_s: float, pose: Pose) -> Stick:
        """The stick at ``t_s``; ``pose`` (the simulator's truth) is not used."""
        obs = self.view.seen(t_s)
        if obs is None or obs.pose is None:
            return Stick(0.0, 0.0, True, self.mode)
        x, y, yaw = obs.pose
        tx, ty = self.target(x, y)
        error = wrap_angle(math.atan2(ty - y, tx - x) - yaw)
        return Stick(
            max(math.cos(error), 0.0),
            clamp_unit(self.params.gain * error / math.pi),
            True,
            self.mode,
        )


def via_points_on_route(
    route: FloatArray, corner_tolerance_m: float = 0.3, max_spacing_m: float = 3.0
) -> list[tuple[float, float]]:
    """Via points an operator would click along ``route``: its corners, at most
    ``max_spacing_m`` apart, ending at the goal (the start itself is left out).

    Corners come from the Ramer-Douglas-Peucker simplification of the polyline: every point of
    the route lies within ``corner_tolerance_m`` of the segments between them.
    """
    r = np.asarray(route, dtype=np.float64)
    if len(r) < 2:
        return [(float(p[0]), float(p[1])) for p in r]
    keep = np.zeros(len(r), dtype=bool)
    keep[0] = keep[-1] = True
    stack = [(0, len(r) - 1)]
    while stack:
        i, j = stack.pop()
        if j <= i + 1:
            continue
        a, b = r[i], r[j]
        ab = b - a
        length = float(np.hypot(*ab))
        seg = r[i + 1 : j] - a
        if length == 0.0:
            dist = np.hypot(seg[:, 0], seg[:, 1])
        else:
            dist = np.abs(ab[0] * seg[:, 1] - ab[1] * seg[:, 0]) / length
        k = int(np.argmax(dist))
        if dist[k] > corner_tolerance_m:
            keep[i + 1 + k] = True
            stack.extend([(i, i + 1 + k), (i + 1 + k, j)])
    corners = r[keep]
    points: list[tuple[float, float]] = []
    for a, b in itertools.pairwise(corners):
        n = max(1, math.ceil(float(np.hypot(*(b - a))) / max_spacing_m))
        for k in range(1, n + 1):
            p = a + (b - a) * (k / n)
            points.append((float(p[0]), float(p[1])))
    return points
