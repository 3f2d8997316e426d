"""Careful drives for measuring intervention (DESIGN 13): a driver that keeps clear of everything.

A test-side stand-in for issue 28's careful operator: the route is planned on the world's map with
every blocked cell inflated by the footprint's half-diagonal plus ``clearance_m`` (so the
footprint keeps that much room whatever its heading, while on the route), then followed by pure
pursuit at up to ``speed_mps``, slower in curves (lateral acceleration ``lateral_mps2``) and
near the goal, speeding up and slowing down gently, turning in place first when the route starts
behind it. Every control period the simulator's scan and the command go into the drive, in the
form ``egc-teleop replay`` reads from a log (``replay_core.LogScan`` and ``VelocitySample``), so
a drive runs through ``replay_core`` exactly as a recorded log does. ``min_clearance_m`` says
how close the footprint really came (the simulator's own measure).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from egc_common.kinematics import wrap_angle
from egc_common.profiles import RobotProfile
from egc_robot.replay_core import LogScan, Replayer, VelocitySample, scan_points, summarize
from egc_sim.grid_world import World
from egc_sim.route import RouteError, plan_route
from egc_sim.simulator import Simulator

PERIOD_S = 0.05
_NS = 1_000_000_000


@dataclass(frozen=True, slots=True)
class CarefulDrive:
    world: str
    scans: tuple[LogScan, ...]
    commands: tuple[VelocitySample, ...]
    min_clearance_m: float
    reached: bool
    duration_s: float


def _smooth(route: np.ndarray, step_m: float = 0.05, window: int = 9) -> np.ndarray:
    """The planner's 8-connected cells resampled every ``step_m`` and averaged (corners cut
    by at most a few cm, well inside the clearance)."""
    seg = np.hypot(*np.diff(route, axis=0).T)
    s = np.concatenate(([0.0], np.cumsum(seg)))
    if s[-1] <= 0.0:
        return route[:1]
    t = np.arange(0.0, s[-1], step_m)
    pts = np.column_stack((np.interp(t, s, route[:, 0]), np.interp(t, s, route[:, 1])))
    if len(pts) > window:
        k = np.ones(window) / window
        pad = window // 2
        ext = np.vstack((np.repeat(pts[:1], pad, 0), pts, np.repeat(pts[-1:], pad, 0)))
        pts = np.column_stack(
            (np.convolve(ext[:, 0], k, "valid"), np.convolve(ext[:, 1], k, "valid"))
        )
    return np.vstack((pts, route[-1:]))


def careful_drive(
    world: World,
    profile: RobotProfile,
    start: tuple[float, float, float],
    goal: tuple[float, float],
    *,
    clearance_m: float = 0.2,
    speed_mps: float = 0.8,
    lateral_mps2: float = 0.6,
    accel_mps2: float = 0.6,
    lookahead_m: float = 0.6,
    max_time_s: float = 120.0,
    seed: int = 0,
    tight: bool = False,
) -> CarefulDrive | None:
    """One drive from ``start`` to ``goal`` (module docstring); None when no route keeps the
    clearance. ``tight``: inflate by the half-width instead of the half-diagonal and do not
    keep to the middle (the route grazes the clearance; corners may cut below it, which
    ``min_clearance_m`` shows)."""
    half = profile.half_size_m[1] if tight else profile.half_diagonal_m
    inflate = half + clearance_m + 0.05
    try:
        route = plan_route(
            world.occupancy,
            world.resolution_m,
            world.origin,
            start[:2],
            goal,
            inflate,
            wall_weight=0.0 if tight else 4.0,
        )
    except RouteError:
        return None
    path = _smooth(route)
    sim = Simulator(world, profile, start, seed=seed)
    scans: list[LogScan] = []
    commands: list[VelocitySample] = []
    v = w = 0.0
    progress = 0
    t_ns = 1_000_000_000
    reached = False
    steps = int(max_time_s / PERIOD_S)
    for _ in range(steps):
        x, y, yaw = sim.pose
        if math.hypot(goal[0] - x, goal[1] - y) < 0.15:
            reached = True
            break
        scan = sim.scan(t_ns)
        window = path[progress : progress + 40]
        progress += int(np.argmin(np.hypot(window[:, 0] - x, window[:, 1] - y)))
        ahead = path[progress:]
        dist = np.hypot(ahead[:, 0] - x, ahead[:, 1] - y)
        far = np.flatnonzero(dist >= lookahead_m)
        tx, ty = ahead[far[0]] if far.size else ahead[-1]
        err = wrap_angle(math.atan2(ty - y, tx - x) - yaw)
        to_goal = math.hypot(goal[0] - x, goal[1] - y)
        if abs(err) > math.radians(50):  # turn in place towards the route first
            v_want, w_want = 0.0, math.copysign(0.6, err)
        else:
            kappa = 2.0 * math.sin(err) / max(math.hypot(tx - x, ty - y), 1e-6)
            v_want = min(speed_mps, math.sqrt(lateral_mps2 / max(abs(kappa), 1e-6)))
            v_want = min(v_want, math.sqrt(2.0 * 0.4 * to_goal) + 0.05)
            w_want = v_want * kappa
        dv = accel_mps2 * PERIOD_S
        v = min(max(v_want, v - dv), v + dv)
        w = min(max(w_want, w - 2.0 * dv), w + 2.0 * dv)
        scans.append(
            LogScan(
                t_ns,
                t_ns,
                sim.lidar_config.angle_min_rad,
                sim.lidar_config.angle_increment_rad,
                scan.range_min_m,
                scan.range_max_m,
                np.asarray(scan.ranges_m, dtype=np.float64),
            )
        )
        commands.append(VelocitySample(t_ns, v, w))
        sim.step(v, w, PERIOD_S)
        t_ns += int(PERIOD_S * _NS)
    return CarefulDrive(
        world.name,
        tuple(scans),
        tuple(commands),
        sim.min_clearance_m,
        reached,
        len(scans) * PERIOD_S,
    )


def replay_drive(drive: CarefulDrive, filter_name: str, profile: RobotProfile) -> dict:
    """The drive through ``replay_core`` as ``egc-teleop replay`` runs a log: the summary."""
    replayer = Replayer.for_filter(filter_name, profile)
    half = profile.half_size_m
    verdicts = []
    memory = None
    for scan, command in zip(drive.scans, drive.commands, strict=True):
        verdict, _, _, memory = replayer.step(scan, scan_points(scan, half), command, memory)
        verdicts.append(verdict)
    v_max, w_max = profile.v_max_mps, profile.w_max_radps
    return summarize(verdicts, filter_name, profile.name, None, (v_max, w_max)).as_dict()
