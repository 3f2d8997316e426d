"""The ``careful`` operator model: a driver who keeps a clearance, drives smoothly, cuts no corner.

The driver of the careful drives of DESIGN 13 (issue 28): the footprint never comes within
``clearance_m`` (0.2 m) of anything, at most ``speed_mps`` (0.8 m/s on the Jackal; by default
0.4 of the profile's v_max, which is 0.8 m/s there). It exists so that the project can record
such drives in its own worlds (``egc-teleop episode --operator careful --bag OUT``) and measure
how often a filter changes the commands of someone who needs no help.

It knows the map (as ``route`` does) and reads the operator view (``observation``: the pose,
after a reaction time). Three parts, the first two pure functions of the map:

1. **Plan** (``plan_careful_path``): on the map's cells, the distance from each cell centre to
   the nearest blocked cell's square (``wall_distance_m``); the robot's centre may only use
   cells where that is at least the footprint's half-width + ``clearance_m`` + ``margin_m``
   (half the margin where the full one leaves no way): driving along the path, the robot clears
   everything beside it by ``clearance_m`` with that to spare. The cheapest 8-connected path
   (``route.grid_path``) where a step costs more the less room there is, up to the room to
   turn on the spot plus ``comfort_m``: the path keeps to the middle of gaps and corridors.
   The grid's staircase is resampled every ``STEP_M`` and smoothed (a moving average over
   ``smooth_m``, a point keeping its planned place where the smoothed one would have less room).
   Then the footprint itself, pointing along the path: in a bend of a narrow passage its corners
   swing out although the centre line keeps its distance, so the path is bent away from the
   walls there (``fit_footprint``); where even so it would clear something by less than
   ``clearance_m + check_margin_m`` (a corridor too narrow to turn a corner in), the model
   refuses the drive up front (``RouteError``): a careful driver does not try what cannot be
   done carefully.
2. **Speed along the path** (``speed_profile``): at each point the least of the cruise speed,
   the speed of the curve (lateral acceleration ``lateral_accel_mps2``, turn rate ``turn_radps``),
   and the speed near obstacles (``slow_fraction`` of the cruise speed where the footprint
   clears the nearest obstacle by just ``clearance_m``, full speed ``slow_band_m`` further out);
   then a backward pass so that every slow-down (a curve, a narrow place, the goal at the end)
   is reached braking at ``decel_mps2``, never later.
3. **Driving** (``CarefulOperator.command``): pure pursuit of the path from the pose the view
   shows, brought forward to now with the driver's own commands since (a driver knows what the
   stick has done; over a link they are taken to act when sent, the uplink's delay being
   unknown to the driver, and a filter's changes are seen only when the view shows them); the
   lookahead grows with speed (``lookahead_min_m`` + ``lookahead_s`` times
   the speed), short enough that the arc hugs the smoothed path instead of cutting across its
   bends. Heading error beyond ``turn_in_place_rad``: stop and turn on the spot until it is
   under a third of that. The speed is the profile's at the progress point, slowed with the
   heading error (times its cosine); speed and turn rate then ramp within the comfortable
   accelerations (``accel_mps2``, ``decel_mps2``,
   ``angular_accel_radps2``). Last, a check on the map: driving the command for ``hold_s`` and
   braking to a stop along the same arc must keep the footprint ``clearance_m + check_margin_m``
   from everything (or, where it is already nearer, no nearer than now); if not, the command is
   halved, then quartered, then quartered keeping just ``clearance_m`` (a gap barely wider than
   the margins), then a turn on the spot towards the path; else the driver stops.

Defaults that are ``None`` are scaled from the robot profile (``CarefulParams.resolved``): the
cruise speed 0.4 v_max, the turn rate 0.5 w_max, accelerations half the profile's, lateral
acceleration a quarter of its linear one. The stick is (v / v_max, w / w_max): the robot's eq. 4
(with the default gamma = 1) turns it back into exactly the velocity the driver meant, which is what a log records on
``/cmd_vel``. The model does not read the scan: in the simulator the map is the world, so the
map is everything there is to keep clear of.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, replace

import numpy as np
from egc_common.joystick import clamp_unit
from egc_common.kinematics import integrate_arc, wrap_angle
from egc_common.profiles import RobotProfile

from egc_sim.collision import FootprintChecker
from egc_sim.grid_world import BoolGrid, Pose, World
from egc_sim.observation import FloatArray, Observation, ViewBuffer
from egc_sim.operators import Stick, check_mode
from egc_sim.route import RouteError, grid_path, nearest_free

STEP_M = 0.05  # spacing of the resampled path
_HISTORY_S = 5.0  # own commands kept for bringing a seen pose forward
_SEARCH_M = 2.0  # how far along the path the progress point is searched, forward only
_HAIR_M = 0.005  # the last-resort check's margin over clearance_m
_BEND_M = 0.3  # how much of the path around a tight point bends with it
_BEND_STEP_M = 0.01
_BEND_STEPS = 30
_WALL_WEIGHT = 8.0  # a step where the footprint clears by just clearance_m costs 9 times more


@dataclass(frozen=True, slots=True)
class CarefulParams:
    """Tuning of the careful driver (module docstring); SI units, None: from the profile."""

    speed_mps: float | None = None
    clearance_m: float = 0.2
    margin_m: float = 0.05
    comfort_m: float = 0.4
    smooth_m: float = 0.5
    turn_radps: float | None = None
    accel_mps2: float | None = None
    decel_mps2: float | None = None
    angular_accel_radps2: float | None = None
    lateral_accel_mps2: float | None = None
    slow_fraction: float = 0.4
    slow_band_m: float = 0.4
    lookahead_min_m: float = 0.3
    lookahead_s: float = 0.4
    turn_in_place_rad: float = 1.0
    hold_s: float = 0.2
    check_margin_m: float = 0.01
    reaction_s: float = 0.25

    def __post_init__(self) -> None:
        for name in (
            "clearance_m",
            "margin_m",
            "comfort_m",
            "smooth_m",
            "lookahead_s",
            "reaction_s",
            "hold_s",
            "check_margin_m",
            "slow_band_m",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"careful operator: {name} must be >= 0, got {value}")
        for name in (
            "speed_mps",
            "turn_radps",
            "accel_mps2",
            "decel_mps2",
            "angular_accel_radps2",
            "lateral_accel_mps2",
            "lookahead_min_m",
        ):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value > 0):
                raise ValueError(f"careful operator: {name} must be > 0, got {value}")
        if not 0.0 < self.slow_fraction <= 1.0:
            raise ValueError(
                f"careful operator: slow_fraction must be in (0, 1], got {self.slow_fraction}"
            )
        if not 0.0 < self.turn_in_place_rad < math.pi:
            raise ValueError("careful operator: turn_in_place_rad must be in (0, pi)")

    def resolved(self, profile: RobotProfile) -> CarefulParams:
        """Every None filled in from ``profile``; speeds capped at the profile's limits."""
        p = profile
        speed = 0.4 * p.v_max_mps if self.speed_mps is None else self.speed_mps
        turn = 0.5 * p.w_max_radps if self.turn_radps is None else self.turn_radps
        return replace(
            self,
            speed_mps=min(speed, p.v_max_mps),
            turn_radps=min(turn, p.w_max_radps),
            accel_mps2=min(self.accel_mps2 or 0.5 * p.accel_max_mps2, p.accel_max_mps2),
            decel_mps2=min(self.decel_mps2 or 0.5 * p.decel_max_mps2, p.decel_max_mps2),
            angular_accel_radps2=min(
                self.angular_accel_radps2 or 0.5 * p.angular_accel_max_radps2,
                p.angular_accel_max_radps2,
            ),
            lateral_accel_mps2=self.lateral_accel_mps2 or 0.25 * p.accel_max_mps2,
        )


@dataclass(frozen=True, slots=True, eq=False)
class CarefulPath:
    """A planned path and its speed profile: ``xy`` (M, 2) world metres every ``STEP_M``,
    ``s_m`` (M,) distance along it, ``speed_mps`` (M,) the most the driver goes there."""

    xy: FloatArray
    s_m: FloatArray
    speed_mps: FloatArray

    @property
    def length_m(self) -> float:
        return float(self.s_m[-1])


def wall_distance_m(occupancy: BoolGrid, resolution_m: float) -> FloatArray:
    """Distance (m) from each cell centre to the nearest blocked cell's square (the square of
    the blocked cell whose centre is nearest); everything outside the grid blocks."""
    from scipy import ndimage

    blocked = np.pad(np.asarray(occupancy, dtype=bool), 1, constant_values=True)
    _, (near_r, near_c) = ndimage.distance_transform_edt(~blocked, return_indices=True)
    rows, cols = np.indices(blocked.shape)
    dr = np.maximum(np.abs(rows - near_r) - 0.5, 0.0)
    dc = np.maximum(np.abs(cols - near_c) - 0.5, 0.0)
    out: FloatArray = (np.hypot(dr, dc) * resolution_m)[1:-1, 1:-1]
    return out


def _lookup(
    distance: FloatArray, resolution_m: float, origin: tuple[float, float], xy: FloatArray
) -> FloatArray:
    rows = np.floor((xy[:, 1] - origin[1]) / resolution_m).astype(np.int64)
    cols = np.floor((xy[:, 0] - origin[0]) / resolution_m).astype(np.int64)
    inside = (rows >= 0) & (rows < distance.shape[0]) & (cols >= 0) & (cols < distance.shape[1])
    out = np.zeros(len(xy), dtype=np.float64)
    out[inside] = distance[rows[inside], cols[inside]]
    return out


def resample(polyline: FloatArray, step_m: float = STEP_M) -> FloatArray:
    """Points every ``step_m`` along ``polyline`` (M, 2), first and last kept."""
    p = np.asarray(polyline, dtype=np.float64)
    seg = np.hypot(*np.diff(p, axis=0).T) if len(p) > 1 else np.zeros(0)
    keep = np.concatenate([[True], seg > 1e-12])
    p = p[keep]
    if len(p) < 2:
        out: FloatArray = p.copy()
        return out
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(p, axis=0).T))])
    n = max(2, math.ceil(s[-1] / step_m) + 1)
    t = np.linspace(0.0, s[-1], n)
    return np.stack([np.interp(t, s, p[:, 0]), np.interp(t, s, p[:, 1])], axis=1)


def smooth_path(
    path: FloatArray,
    distance: FloatArray,
    resolution_m: float,
    origin: tuple[float, float],
    required_m: float,
    window_m: float,
) -> FloatArray:
    """``path`` (resampled) smoothed by a moving average over ``window_m``; a point whose
    smoothed place has centre distance below ``required_m`` keeps its planned place. Ends fixed."""
    p = np.asarray(path, dtype=np.float64)
    half = round(0.5 * window_m / STEP_M)
    if half < 1 or len(p) < 3:
        return p.copy()
    out = p.copy()
    for _ in range(2):
        padded = np.concatenate([np.repeat(out[:1], half, 0), out, np.repeat(out[-1:], half, 0)])
        kernel = np.ones(2 * half + 1) / (2 * half + 1)
        smoothed = np.stack(
            [np.convolve(padded[:, k], kernel, mode="valid") for k in range(2)], axis=1
        )
        ok = _lookup(distance, resolution_m, origin, smoothed) >= required_m
        out = np.where(ok[:, None], smoothed, out)
        out[0], out[-1] = p[0], p[-1]
    return resample(out)


def curvature(path: FloatArray, window_m: float = 0.2) -> FloatArray:
    """Unsigned curvature (1/m) at each point of a path sampled every ``STEP_M``: the heading
    change over ``window_m`` divided by it."""
    p = np.asarray(path, dtype=np.float64)
    if len(p) < 3:
        return np.zeros(len(p))
    d = np.diff(p, axis=0)
    heading = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    heading = np.concatenate([heading, heading[-1:]])
    k = max(1, round(0.5 * window_m / STEP_M))
    ahead = np.concatenate([heading[k:], np.repeat(heading[-1:], k)])
    behind = np.concatenate([np.repeat(heading[:1], k), heading[:-k]])
    out: FloatArray = np.abs(ahead - behind) / (2 * k * STEP_M)
    return out


def speed_profile(
    path: FloatArray, clearance_ahead_m: FloatArray, params: CarefulParams
) -> FloatArray:
    """The most the driver goes at each point (module docstring, part 2); 0 at the end.

    ``clearance_ahead_m`` is the footprint's clearance there (driving along the path), ``params``
    resolved.
    """
    assert params.speed_mps is not None and params.turn_radps is not None
    assert params.lateral_accel_mps2 is not None and params.decel_mps2 is not None
    cruise = params.speed_mps
    k = curvature(path)
    with np.errstate(divide="ignore"):
        curve = np.minimum(
            np.sqrt(params.lateral_accel_mps2 / k), params.turn_radps / k
        )  # inf on straights
    near = (clearance_ahead_m - params.clearance_m) / max(params.slow_band_m, 1e-9)
    share = params.slow_fraction + (1.0 - params.slow_fraction) * np.clip(near, 0.0, 1.0)
    v = np.minimum(np.minimum(curve, cruise * share), cruise)
    v[-1] = 0.0
    for i in range(len(v) - 2, -1, -1):  # reach every slow-down braking at decel, not later
        v[i] = min(v[i], math.sqrt(v[i + 1] ** 2 + 2.0 * params.decel_mps2 * STEP_M))
    return v


def headings(path: FloatArray) -> FloatArray:
    """The direction of travel (rad) at each point of a path."""
    p = np.asarray(path, dtype=np.float64)
    if len(p) < 2:
        return np.zeros(len(p))
    d = np.diff(p, axis=0)
    h = np.arctan2(d[:, 1], d[:, 0])
    out: FloatArray = np.concatenate([h, h[-1:]])
    return out


def footprint_clearances(
    path: FloatArray, checker: FootprintChecker, below: float = math.inf
) -> FloatArray:
    """The footprint's clearance at each point of ``path``, pointing along it; exact where it
    is below ``below``, some value above ``below`` elsewhere (``FootprintChecker.clearance``)."""
    return np.array(
        [
            checker.clearance(x, y, h, below=below)
            for (x, y), h in zip(path, headings(path), strict=True)
        ],
        dtype=np.float64,
    )


def fit_footprint(
    path: FloatArray,
    checker: FootprintChecker,
    distance: FloatArray,
    resolution_m: float,
    origin: tuple[float, float],
    target_m: float,
    exempt_m: float,
) -> FloatArray:
    """``path`` bent away from the walls wherever the footprint, pointing along it, clears
    something by less than ``target_m`` (in a bend of a narrow corridor the corners swing out
    although the centre line keeps its distance): such points and their neighbours (a
    triangular window of ``_BEND_M``) move up the gradient of ``distance`` a centimetre at a
    time, for at most ``_BEND_STEPS`` steps. Points within ``exempt_m`` of either end stay.
    """
    xy = np.asarray(path, dtype=np.float64).copy()
    if len(xy) < 3:
        return xy
    grad = np.gradient(distance)
    gy: FloatArray = np.asarray(grad[0], dtype=np.float64)
    gx: FloatArray = np.asarray(grad[1], dtype=np.float64)
    half = max(1, round(_BEND_M / STEP_M))
    window = 1.0 - np.abs(np.arange(-half, half + 1)) / (half + 1)
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    movable = (s > exempt_m) & (s < s[-1] - exempt_m)
    for _ in range(_BEND_STEPS):
        bad = (footprint_clearances(xy, checker, below=target_m) < target_m) & movable
        if not bad.any():
            break
        rows = np.floor((xy[:, 1] - origin[1]) / resolution_m).astype(np.int64)
        cols = np.floor((xy[:, 0] - origin[0]) / resolution_m).astype(np.int64)
        rows = np.clip(rows, 0, distance.shape[0] - 1)
        cols = np.clip(cols, 0, distance.shape[1] - 1)
        g = np.stack([gx[rows, cols], gy[rows, cols]], axis=1)
        norm = np.hypot(g[:, 0], g[:, 1])
        g = np.where(norm[:, None] > 1e-12, g / np.maximum(norm, 1e-12)[:, None], 0.0)
        weight = np.convolve(bad.astype(np.float64), window, mode="same").clip(0.0, 1.0)
        xy += (_BEND_STEP_M * weight * movable)[:, None] * g
    return xy


def plan_careful_path(
    world: World,
    start: tuple[float, float],
    goal: tuple[float, float],
    profile: RobotProfile,
    params: CarefulParams,
    checker: FootprintChecker | None = None,
) -> CarefulPath:
    """The path and its speeds (module docstring, parts 1 and 2); ``params`` resolved.

    Raises ``route.RouteError`` when no path keeps the clearance: none through the grid, or
    one where the footprint, pointing along it, cannot keep ``clearance_m`` (a turn in a
    corridor too narrow for it).
    """
    from scipy import ndimage

    occupancy, resolution_m, origin = world.occupancy, world.resolution_m, world.origin
    if checker is None:
        checker = FootprintChecker(world, profile.footprint)
    half_width = profile.half_size_m[1]  # the footprint's reach sideways
    distance = wall_distance_m(occupancy, resolution_m)
    hard = half_width + params.clearance_m
    comfort = profile.half_diagonal_m + params.clearance_m + params.comfort_m

    def cell_of(p: tuple[float, float]) -> tuple[int, int]:
        return (
            math.floor((p[1] - origin[1]) / resolution_m),
            math.floor((p[0] - origin[0]) / resolution_m),
        )

    def no_path(why: str) -> RouteError:
        return RouteError(
            f"no path from ({start[0]:.2f}, {start[1]:.2f}) to ({goal[0]:.2f}, {goal[1]:.2f}) "
            f"keeps the {profile.name}'s footprint {params.clearance_m:g} m from everything "
            f"on this map{why} (the careful operator)"
        )

    cells = None
    for margin in (params.margin_m, 0.5 * params.margin_m):
        required = hard + margin
        free = distance >= required
        if not free.any():
            continue
        labels, _ = ndimage.label(free, structure=np.ones((3, 3), dtype=bool))
        s_cell, g_cell = nearest_free(free, cell_of(start)), nearest_free(free, cell_of(goal))
        if labels[s_cell] != labels[g_cell]:
            continue
        penalty = 1.0 + _WALL_WEIGHT * np.clip((comfort - distance) / (comfort - hard), 0.0, 1.0)
        cells = grid_path(free, penalty, s_cell, g_cell)
        break
    if cells is None:
        raise no_path("")
    route = np.empty((len(cells) + 2, 2), dtype=np.float64)
    route[1:-1, 0] = origin[0] + (cells[:, 1] + 0.5) * resolution_m
    route[1:-1, 1] = origin[1] + (cells[:, 0] + 0.5) * resolution_m
    route[0], route[-1] = start, goal
    xy = smooth_path(resample(route), distance, resolution_m, origin, required, params.smooth_m)
    exempt = profile.half_diagonal_m + params.clearance_m  # where the robot was put, or stops
    target = params.clearance_m + params.check_margin_m + _HAIR_M
    xy = resample(fit_footprint(xy, checker, distance, resolution_m, origin, target, exempt))
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    fit = footprint_clearances(xy, checker, below=target + params.slow_band_m)
    inner = (s > exempt) & (s < s[-1] - exempt)
    tight = inner & (fit < params.clearance_m + params.check_margin_m)
    if tight.any():
        x, y = xy[int(np.argmax(tight))]
        raise no_path(f": pointing along the path, it has no room to spare at ({x:.2f}, {y:.2f})")
    ahead = np.minimum(_lookup(distance, resolution_m, origin, xy) - half_width, fit)
    return CarefulPath(xy, s, speed_profile(xy, ahead, params))


class CarefulOperator:
    """Drives a ``CarefulPath`` (module docstring, part 3); an observing operator."""

    def __init__(
        self,
        path: CarefulPath,
        checker: FootprintChecker,
        profile: RobotProfile,
        mode: str = "shared",
        params: CarefulParams | None = None,
    ) -> None:
        if len(path.xy) < 1:
            raise ValueError("a careful path needs at least one point")
        self.path = path
        self.checker = checker
        self.profile = profile
        self.mode = check_mode(mode)
        self.params = (params or CarefulParams()).resolved(profile)
        self.view = ViewBuffer(self.params.reaction_s)
        self._progress = 0
        self._commands: deque[tuple[float, float, float]] = deque()  # (t_s, v, w) sent
        self._last_t: float | None = None
        self._turning = False
        self.stops = 0  # commands the map check cut to a stop

    @classmethod
    def on_world(
        cls,
        world: World,
        start: Pose,
        goal: tuple[float, float],
        profile: RobotProfile,
        mode: str = "shared",
        params: CarefulParams | None = None,
    ) -> CarefulOperator:
        """Plan on ``world``'s map from ``start`` to ``goal`` and drive it."""
        p = (params or CarefulParams()).resolved(profile)
        checker = FootprintChecker(world, profile.footprint)
        path = plan_careful_path(world, (start[0], start[1]), goal, profile, p, checker)
        return cls(path, checker, profile, mode, p)

    def observe(self, t_s: float, observation: Observation) -> None:
        self.view.observe(t_s, observation)

    # -- where the robot is now -------------------------------------------------------------

    def predicted_pose(self, t_s: float, seen: Observation) -> Pose:
        """The pose ``seen`` shows, brought forward to ``t_s`` with the commands sent since."""
        assert seen.pose is not None
        pose = seen.pose
        t = seen.stamp_s
        if t_s <= t:
            return pose
        commands = list(self._commands)
        v = w = 0.0
        for t_cmd, v_cmd, w_cmd in commands:  # the command in effect at the stamp
            if t_cmd <= t:
                v, w = v_cmd, w_cmd
        for t_cmd, v_cmd, w_cmd in commands:
            if t_cmd <= t:
                continue
            if t_cmd >= t_s:
                break
            pose = integrate_arc(pose, v, w, t_cmd - t)
            t, v, w = t_cmd, v_cmd, w_cmd
        return integrate_arc(pose, v, w, t_s - t)

    def _advance_progress(self, x: float, y: float) -> int:
        xy, s = self.path.xy, self.path.s_m
        end = int(np.searchsorted(s, s[self._progress] + _SEARCH_M, side="right"))
        window = xy[self._progress : max(end, self._progress + 1)]
        d2 = (window[:, 0] - x) ** 2 + (window[:, 1] - y) ** 2
        self._progress += int(np.argmin(d2))
        return self._progress

    # -- the command ------------------------------------------------------------------------

    def desired(self, pose: Pose, v_now: float) -> tuple[float, float]:
        """Pure pursuit with the path's speed (module docstring, part 3), before the ramps."""
        p = self.params
        assert p.speed_mps is not None and p.turn_radps is not None
        x, y, yaw = pose
        i = self._advance_progress(x, y)
        xy, s = self.path.xy, self.path.s_m
        lookahead = p.lookahead_min_m + p.lookahead_s * abs(v_now)
        j = min(int(np.searchsorted(s, s[i] + lookahead)), len(xy) - 1)
        dx, dy = xy[j, 0] - x, xy[j, 1] - y
        distance = math.hypot(dx, dy)
        to_end = math.hypot(xy[-1, 0] - x, xy[-1, 1] - y)
        if distance < 1e-6 or to_end < 0.5 * STEP_M:
            return 0.0, 0.0
        alpha = wrap_angle(math.atan2(dy, dx) - yaw)
        if abs(alpha) > p.turn_in_place_rad:
            self._turning = True
        elif abs(alpha) < p.turn_in_place_rad / 3.0:
            self._turning = False
        if self._turning:
            turn = p.turn_radps * min(1.0, abs(alpha) / 0.5)
            return 0.0, math.copysign(turn, alpha)
        kappa = 2.0 * math.sin(alpha) / distance
        v = float(self.path.speed_mps[i]) * max(math.cos(alpha), 0.0)
        # Near the end the profile's last point is 0: creep in rather than stop short of it.
        v = max(v, min(0.1 * p.speed_mps, to_end)) if i >= len(xy) - 3 else v
        if abs(kappa) > 1e-9:
            v = min(v, p.turn_radps / abs(kappa))
        return v, kappa * v

    def _align_rate(self, pose: Pose) -> float:
        """A turn on the spot towards the path's direction at the progress point."""
        p = self.params
        assert p.turn_radps is not None
        xy = self.path.xy
        i = min(self._progress, len(xy) - 2)
        if i < 0:
            return 0.0
        tangent = math.atan2(xy[i + 1, 1] - xy[i, 1], xy[i + 1, 0] - xy[i, 0])
        error = wrap_angle(tangent - pose[2])
        return math.copysign(min(p.turn_radps, 2.0 * abs(error)), error)

    def _clear(self, pose: Pose, v: float, w: float, floor_m: float) -> bool:
        """Driving (v, w) for ``hold_s`` then braking to a stop on the same arc keeps the
        footprint above ``floor_m`` from everything on the map."""
        p = self.params
        assert p.decel_mps2 is not None and p.angular_accel_radps2 is not None
        brake_s = max(abs(v) / p.decel_mps2, abs(w) / p.angular_accel_radps2)
        span_s = p.hold_s + 0.5 * brake_s  # arc length and turn are (v, w) times this
        travel = abs(v) * span_s + abs(w) * span_s * self.checker.half_diagonal_m
        n = max(1, math.ceil(travel / (0.5 * STEP_M)))
        for k in range(1, n + 1):
            after = integrate_arc(pose, v, w, span_s * k / n)
            if self.checker.clearance(*after, below=floor_m + 1e-9) <= floor_m:
                return False
        return True

    def _checked(
        self, pose: Pose, v: float, w: float, w_prev: float, dt: float
    ) -> tuple[float, float]:
        """The first command that passes the map check (module docstring, part 3).

        Keeping ``clearance_m + check_margin_m`` (no nearer than now where it is already
        nearer): the command, halved, quartered; the quartered command keeping ``clearance_m``
        plus a hair (the way on through a gap barely wider than the margins); a turn on the spot
        towards the path, keeping either. Else stop.
        """
        p = self.params
        assert p.angular_accel_radps2 is not None
        dw = p.angular_accel_radps2 * dt
        w_align = min(max(self._align_rate(pose), w_prev - dw), w_prev + dw)
        keep = p.clearance_m + p.check_margin_m
        keep = min(keep, self.checker.clearance(*pose, below=keep))
        hair = p.clearance_m + _HAIR_M
        tries = (
            (keep, (v, w)),
            (keep, (0.5 * v, 0.5 * w)),
            (keep, (0.25 * v, 0.25 * w)),
            (hair, (0.25 * v, 0.25 * w)),
            (keep, (0.0, w_align)),
            (hair, (0.0, w_align)),
        )
        for floor, cand in tries:
            if (cand[0] != 0.0 or cand[1] != 0.0) and self._clear(pose, *cand, floor):
                return cand
        self.stops += 1
        return 0.0, 0.0

    def command(self, t_s: float, pose: Pose) -> Stick:
        """The stick at ``t_s``; ``pose`` (the simulator's truth) is not used."""
        p = self.params
        assert p.accel_mps2 is not None and p.decel_mps2 is not None
        assert p.angular_accel_radps2 is not None
        obs = self.view.seen(t_s)
        v_prev, w_prev = self._commands[-1][1:] if self._commands else (0.0, 0.0)
        dt = 0.0 if self._last_t is None else max(0.0, t_s - self._last_t)
        self._last_t = t_s
        if obs is None or obs.pose is None:
            v, w = 0.0, 0.0
        else:
            now = self.predicted_pose(t_s, obs)
            v_des, w_des = self.desired(now, v_prev)
            kappa = w_des / v_des if abs(v_des) > 1e-9 else None
            v = min(max(v_des, v_prev - p.decel_mps2 * dt), v_prev + p.accel_mps2 * dt)
            v = max(v, 0.0)
            w_target = kappa * v if kappa is not None else w_des
            dw = p.angular_accel_radps2 * dt
            w = min(max(w_target, w_prev - dw), w_prev + dw)
            v, w = self._checked(now, v, w, w_prev, dt)
        self._commands.append((t_s, v, w))
        while self._commands and self._commands[0][0] < t_s - _HISTORY_S:
            self._commands.popleft()
        prof = self.profile
        return Stick(
            clamp_unit(v / prof.v_max_mps), clamp_unit(w / prof.w_max_radps), True, self.mode
        )
