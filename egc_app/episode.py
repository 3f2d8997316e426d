"""``egc-teleop episode``: headless episodes in the simulator, printed as JSON (pinned CLI).

    egc-teleop episode --map PATH --start X,Y,YAW --goal X,Y
        [--operator goal|forward|sighted|route|FILE]
        [--filter none|egc] [--profile NAME] [--max-time S] [--goal-tolerance M] [--seed N]
        [--stall-time S] [--record OUT.rrd] [--bag OUT.mcap|DIR] --json
    egc-teleop episode --batch SUITE.jsonl | --random-worlds N  [...] [--jobs J] [--out FILE]

This module is wiring (DESIGN 2): ``egc_sim`` supplies the world, the simulated robot, the
scripted operator and the episode loop; the controller is the robot's own command pipeline,
``egc_robot.pipeline.step_command`` (eq. 4 mapping, EGC in shared mode, anti-dead-lock,
profile limits, footprint sweep), called here, never copied. When the operator releases the
deadman or presses e-stop the robot's stop rule applies (``egc_robot.safety.decelerate``).

- ``--filter egc`` runs the pipeline with the EGC filter and the scripted operators select
  ``shared`` mode; ``--filter none`` turns the filter off and they select ``direct``. A joystick
  file selects its mode per row, and with ``--filter none`` shared rows are not filtered.
- ``--map`` takes a map.yaml, a .toml or .npy world, or a built-in name (``hallway``,
  ``office02``, ``random:SEED``); ``--start``/``--goal``/``--goal-tolerance`` default to the
  world's own where it has them.
- Control runs at 1 / ``--dt`` Hz (20 Hz); the simulator sub-steps within a cycle.
- ``--via`` gives the filter its via points (DESIGN 7); the robot echoes the active one in its
  telemetry and the operator view draws it, so the ``goal`` and ``sighted`` operators steer at
  the active via point while there is one, and at the goal after the last (issue 11). With
  ``--via goal`` (the default) that is the goal throughout.
- ``--record OUT.rrd`` saves the episode as the operator view shows a live run
  (``egc_operator.view.record_episode``), one telemetry message per cycle; open it with
  ``rerun OUT.rrd``.
- ``--bag OUT`` writes the episode as a ROS 2 log (``egc_sim.episode_bag``): ``/scan``,
  ``/odom`` and the driver's ``/cmd_vel`` (the command *before* the filter), stamped with the
  simulated clock; ``OUT.mcap`` is one MCAP file, any other name a ROS 2 bag directory. Replay
  it with ``egc-teleop replay OUT``.
- ``--stall-time S`` ends an episode as ``stalled`` once the robot has stood still for S
  simulated seconds (``egc_sim.episodes``); off by default, so that an episode ends only at the
  goal, at a contact or at ``--max-time``.

JSON keys: ``reached``, ``collided``, ``time_s`` (simulated), ``path_m``, ``min_clearance_m``
(smallest footprint clearance, 0 after a contact, capped at 1 m), ``interventions``, ``steps``
(control cycles), ``wall_s`` (wall-clock seconds of the episode loop, world loading excluded),
plus ``outcome`` (reached | collided | stalled | timeout), ``goal_distance_m``, ``final_pose``
and the settings. An **intervention** is a control cycle in which the pipeline's limiter was ``egc``
(the filter changed the operator's command) or ``sweep`` (the footprint check scaled it down).
Cycles limited only by the profile's velocity/acceleration limits, stopped by the deadman or
passed through by the anti-dead-lock rule do not count; in direct mode the count is 0.

The batch form runs episodes in parallel worker processes (``--jobs``, default: all cores),
shows a progress bar on stderr and writes one JSON object per line to ``--out`` (or stdout), in
input order. A suite file holds one JSON object per line with the single-episode options as
keys: ``map`` (required), ``start`` ([x, y, yaw]), ``goal`` ([x, y]), ``operator``, ``filter``,
``profile``, ``max_time``, ``goal_tolerance``, ``seed``, ``dt``, ``stall_time``, ``via``; missing keys
take the command line's values. ``--random-worlds N`` runs ``random:SEED`` for N seeds from
``--seed`` on.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import multiprocessing
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

from egc_common.cli_args import check_writable, plain_float
from egc_common.errors import UsageError
from egc_common.messages import Telemetry
from egc_common.profiles import PROFILES, get_profile
from egc_common.scan import Scan
from egc_robot.pipeline import (
    FILTERS,
    INTERVENING,
    Limiter,
    PipelineConfig,
    PipelineResult,
    step_command,
)
from egc_robot.safety import MAX_CONTROL_PERIOD_S, SweepParams, decelerate
from egc_robot.via_points import DEFAULT_TOLERANCE_M, ViaPoints, advance, to_robot_frame
from egc_sim.episode_bag import BagError, BagStep, EpisodeBag, check_bag_path
from egc_sim.episodes import ControlOutput, EpisodeResult, TraceRow, run_episode
from egc_sim.grid_world import World
from egc_sim.observation import SimSensor
from egc_sim.operators import Stick, make_operator
from egc_sim.simulator import Simulator
from egc_sim.worlds import WorldError, load_world

DEFAULT_GOAL_TOLERANCE_M = 0.3
INTERVENTIONS = INTERVENING
SUITE_KEYS = {
    "map",
    "start",
    "goal",
    "operator",
    "filter",
    "profile",
    "max_time",
    "goal_tolerance",
    "seed",
    "dt",
    "stall_time",
    "via",
}


@dataclass(frozen=True, slots=True)
class EpisodeSettings:
    """Everything one episode needs; plain values so that it crosses process boundaries."""

    map: str
    start: tuple[float, float, float] | None = None
    goal: tuple[float, float] | None = None
    operator: str = "goal"
    filter: str = "egc"
    profile: str = "pioneer3dx"
    max_time_s: float = 300.0
    goal_tolerance_m: float | None = None
    seed: int = 0
    dt_s: float = 0.05
    stall_time_s: float | None = None
    via: str = "goal"  # via points for the filter: goal | route | none (VIA_CHOICES)


VIA_CHOICES = ("goal", "route", "none")
NS_PER_S = 1_000_000_000


class PipelineController:
    """The robot's command pipeline as an episode controller (module docstring)."""

    def __init__(
        self,
        config: PipelineConfig,
        pose: Callable[[], tuple[float, float, float]] | None = None,
        via_points: Sequence[tuple[float, float]] = (),
        via_tolerance_m: float = DEFAULT_TOLERANCE_M,
    ) -> None:
        self.config = config
        self.previous = (0.0, 0.0)
        self.last_stick: Stick | None = None
        self.last_result: PipelineResult | None = None  # None while holding
        self.route = ViaPoints("map", tuple(via_points))
        self._pose = pose  # the robot's map pose (the simulator stands in for a localiser)
        self._via_tolerance_m = via_tolerance_m
        self._now_ns = 0
        self._memory: object | None = None

    def _goal_in_robot_frame(self) -> tuple[float, float] | None:
        if self._pose is None:
            return None
        pose = self._pose()
        self.route = advance(self.route, pose, self._via_tolerance_m)
        active = self.route.active
        return None if active is None else to_robot_frame(active, pose)

    def __call__(self, stick: Stick, scan: Scan, dt_s: float) -> ControlOutput:
        self.last_stick, self.last_result = stick, None
        self._now_ns += round(dt_s * NS_PER_S)
        goal_r = self._goal_in_robot_frame()
        if stick.deadman and not stick.estop:
            r = self.last_result = step_command(
                self.config,
                stick.x_o,
                stick.y_o,
                stick.mode,
                scan.points(),
                self.previous,
                dt_s,
                goal_xy_m=goal_r,
                now_ns=self._now_ns,
                memory=self._memory,
            )
            self._memory = r.memory
            out = ControlOutput(
                r.v_cmd_mps,
                r.w_cmd_radps,
                r.v_ref_mps,
                r.w_ref_radps,
                r.limiter in INTERVENTIONS,
                r.limiter.value,
                None if r.side is None else r.side.value,
            )
        else:
            self._memory = None
            v, w = decelerate(self.previous, dt_s, self.config.profile)
            limiter = Limiter.ESTOP if stick.estop else Limiter.HOLD
            out = ControlOutput(v, w, 0.0, 0.0, False, limiter.value)
        self.previous = (out.v_mps, out.w_radps)
        return out


def run_settings(
    settings: EpisodeSettings,
    record_trace: bool = False,
    record_path: str | None = None,
    bag_path: str | None = None,
) -> tuple[EpisodeResult, dict[str, Any]]:
    """Run one episode; returns the result and its JSON summary. Bad settings -> UsageError.

    ``record_path`` saves the operator view of the episode to a Rerun .rrd file; ``bag_path``
    writes it as a ROS 2 log (``egc_sim.episode_bag``).
    """
    try:
        world = load_world(settings.map, seed=settings.seed)
    except WorldError as exc:
        raise UsageError(f"cannot load map {settings.map!r}: {exc}") from None
    try:
        profile = get_profile(settings.profile)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    start = settings.start or world.start_pose
    if start is None:
        raise UsageError(f"map {settings.map!r} suggests no start pose: give --start X,Y,YAW")
    goal = settings.goal or world.goal
    if goal is None:
        raise UsageError(f"map {settings.map!r} suggests no goal: give --goal X,Y")
    outside = world.outside_message(goal, "goal", settings.map)
    if outside is not None:
        raise UsageError(outside)
    tolerance = settings.goal_tolerance_m or world.goal_tolerance_m or DEFAULT_GOAL_TOLERANCE_M
    mode = "direct" if settings.filter == "none" else "shared"
    # The simulated lidar declares "no return" as free: within its range it truly is.
    if settings.dt_s > MAX_CONTROL_PERIOD_S:  # the base would lag beyond the sweep's margin
        raise UsageError(f"--dt must be at most {MAX_CONTROL_PERIOD_S:g} s, got {settings.dt_s!r}")
    # The sweep's one period at the command before braking is the control period (--dt).
    config = PipelineConfig(
        profile,
        filter=settings.filter,
        no_return_is_free=True,
        sweep=SweepParams(period_s=settings.dt_s),
    )
    try:
        via = episode_via_points(settings.via, world, start, goal, 0.5 * profile.width_m)
        sim = Simulator(world, profile, start, seed=settings.seed)
        controller = PipelineController(config, lambda: sim.pose, via, min(tolerance, 0.5))

        def active_via_point() -> tuple[float, float] | None:
            # What the robot echoes in its telemetry (DESIGN 7) and the operator view draws.
            return controller.route.active

        operator = make_operator(
            settings.operator,
            goal,
            mode,
            seed=settings.seed,
            world=world,
            start=start,
            half_width_m=0.5 * profile.width_m,
            sensor=SimSensor(sim, via=active_via_point),
            via=active_via_point,
            profile=profile,
        )
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    observers: list[Callable[[TraceRow, Scan], None]] = []
    bag: EpisodeBag | None = None
    recorder: EpisodeRecorder | None = None
    try:
        if record_path is not None:
            recorder = EpisodeRecorder(record_path, world, goal, controller)
            observers.append(recorder)
        if bag_path is not None:
            try:
                bag = EpisodeBag(bag_path)
            except BagError as exc:
                raise UsageError(f"--bag {exc}") from None
            observers.append(_bag_observer(bag, sim))
        t0 = time.perf_counter()
        result = run_episode(
            sim,
            operator,
            controller,
            goal,
            tolerance,
            settings.max_time_s,
            settings.dt_s,
            record_trace,
            settings.stall_time_s,
            _each(observers),
        )
    finally:
        if recorder is not None:
            recorder.close()
        if bag is not None:
            bag.close()
    wall_s = time.perf_counter() - t0
    summary = {
        **result.summary(),
        "wall_s": round(wall_s, 4),
        "map": settings.map,
        "world": world.name,
        "start": list(start),
        "goal": list(goal),
        "goal_tolerance_m": tolerance,
        "operator": settings.operator,
        "filter": settings.filter,
        "profile": settings.profile,
        "seed": settings.seed,
        "via": settings.via,
        "via_points": len(via),
    }
    return result, summary


def _bag_observer(bag: EpisodeBag, sim: Simulator) -> Callable[[TraceRow, Scan], None]:
    """Each cycle into the log: the scan, the simulator's odometry and base twist at the start
    of the cycle, and the driver's command before the filter (``v_ref``, ``w_ref``)."""

    def observe(row: TraceRow, scan: Scan) -> None:
        bag.write(
            BagStep(
                round(row.t_s * NS_PER_S),
                scan,
                sim.odometry,
                sim.twist,
                (row.v_ref_mps, row.w_ref_radps),
            )
        )

    return observe


def _each(
    observers: Sequence[Callable[[TraceRow, Scan], None]],
) -> Callable[[TraceRow, Scan], None] | None:
    """One observer calling ``observers`` in order; None when there are none."""
    if not observers:
        return None
    if len(observers) == 1:
        return observers[0]

    def observe(row: TraceRow, scan: Scan) -> None:
        for observer in observers:
            observer(row, scan)

    return observe


def episode_via_points(
    via: str,
    world: World,
    start: tuple[float, float, float],
    goal: tuple[float, float],
    half_width_m: float,
) -> list[tuple[float, float]]:
    """The via points an episode gives its filter (issue 11): none, the goal, or the corners of
    a route planned on the world's map (what an operator who knows the building would click)."""
    if via == "none":
        return []
    if via == "goal":
        return [goal]
    if via == "route":
        from egc_sim.route import plan_route, via_points_on_route

        route = plan_route(
            world.occupancy,
            world.resolution_m,
            world.origin,
            (start[0], start[1]),
            goal,
            half_width_m + 0.1,
        )
        return via_points_on_route(route)
    raise ValueError(f"via must be one of {', '.join(VIA_CHOICES)}, got {via!r}")


# ---------------------------------------------------------------------------------------------
# Command line


def _floats(text: str, n: int, what: str) -> tuple[float, ...]:
    parts = str(text).split(",")
    try:
        values = tuple(plain_float(p) for p in parts)
    except ValueError:
        values = ()
    if len(values) != n or not all(math.isfinite(v) for v in values):
        raise UsageError(f"{what} must be {n} comma-separated finite numbers, got {text!r}")
    return values


def parse_start(text: str) -> tuple[float, float, float]:
    x, y, yaw = _floats(text, 3, "--start X,Y,YAW")
    return x, y, yaw


def parse_goal(text: str) -> tuple[float, float]:
    x, y = _floats(text, 2, "--goal X,Y")
    return x, y


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--map", help="map.yaml, .toml or .npy world, or a built-in name")
    parser.add_argument("--start", help="start pose X,Y,YAW (m, m, rad); default: the map's")
    parser.add_argument("--goal", help="goal X,Y (m); default: the map's")
    parser.add_argument(
        "--operator",
        default="goal",
        help="goal | forward | sighted | route | careful | a joystick CSV file (default goal)",
    )
    parser.add_argument(
        "--filter",
        default="egc",
        help=f"{' | '.join(FILTERS)} (default egc; none is direct mode)",
    )
    parser.add_argument(
        "--via",
        default="goal",
        help="via points for the filter: goal (one, at the goal; default) | route (corners of "
        "a route planned on the map) | none",
    )
    parser.add_argument(
        "--profile", default="pioneer3dx", help=f"robot profile: {', '.join(sorted(PROFILES))}"
    )
    parser.add_argument("--max-time", type=float, default=300.0, help="simulated seconds (300)")
    parser.add_argument(
        "--goal-tolerance",
        type=float,
        help=f"metres (default: the map's or {DEFAULT_GOAL_TOLERANCE_M})",
    )
    parser.add_argument("--seed", type=int, default=0, help="world and noise seed (0)")
    parser.add_argument("--dt", type=float, default=0.05, help="control period in s (0.05, 20 Hz)")
    parser.add_argument(
        "--stall-time", type=float, help="end as 'stalled' after S s standing still (default off)"
    )
    parser.add_argument(
        "--record", metavar="OUT.rrd", help="save the episode's operator view (Rerun .rrd)"
    )
    parser.add_argument(
        "--bag",
        metavar="OUT.mcap|DIR",
        help="write the episode as a ROS 2 log: /scan, /odom and the driver's /cmd_vel (before "
        "the filter); OUT.mcap is one MCAP file, another name a bag directory",
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    batch = parser.add_argument_group("batch")
    batch.add_argument("--batch", metavar="SUITE.jsonl", help="run the episodes of a suite file")
    batch.add_argument(
        "--random-worlds", type=int, metavar="N", help="run N random worlds, seeds --seed..."
    )
    batch.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="worker processes")
    batch.add_argument("--out", help="write JSON lines here (default stdout)")


def _settings_from_args(args: argparse.Namespace) -> EpisodeSettings:
    if args.filter not in FILTERS:
        raise UsageError(f"--filter must be one of {', '.join(FILTERS)}, got {args.filter!r}")
    if args.via not in VIA_CHOICES:
        raise UsageError(f"--via must be one of {', '.join(VIA_CHOICES)}, got {args.via!r}")
    if args.profile not in PROFILES:
        raise UsageError(
            f"--profile must be one of {', '.join(sorted(PROFILES))}, got {args.profile!r}"
        )
    for name, value in (
        ("--max-time", args.max_time),
        ("--dt", args.dt),
        ("--stall-time", 1.0 if args.stall_time is None else args.stall_time),
    ):
        if not (math.isfinite(value) and value > 0):
            raise UsageError(f"{name} must be a positive number, got {value}")
    if args.goal_tolerance is not None and not (
        math.isfinite(args.goal_tolerance) and args.goal_tolerance > 0
    ):
        raise UsageError(f"--goal-tolerance must be a positive number, got {args.goal_tolerance}")
    return EpisodeSettings(
        map=args.map or "",
        start=parse_start(args.start) if args.start is not None else None,
        goal=parse_goal(args.goal) if args.goal is not None else None,
        operator=args.operator,
        filter=args.filter,
        profile=args.profile,
        max_time_s=args.max_time,
        goal_tolerance_m=args.goal_tolerance,
        seed=args.seed,
        dt_s=args.dt,
        stall_time_s=args.stall_time,
        via=args.via,
    )


class EpisodeRecorder:
    """Saves an episode as the operator view would show it live (``egc_operator.view``).

    Each cycle becomes the ``Telemetry`` message the robot process would publish (commands,
    w_SI, region, side, limiter, the guide circles, the scan, the true pose), handed to the
    view's ``on_telemetry``; the world map is logged once.
    """

    def __init__(
        self, path: str, world: World, goal: tuple[float, float], controller: PipelineController
    ) -> None:
        try:  # Rerun is imported only when a recording is asked for
            from egc_operator.view import record_episode
        except ImportError as exc:
            raise UsageError(
                f"--record needs the operator view (egc_operator.view): {exc}"
            ) from None
        self.controller = controller
        self.view = record_episode(path, "sim", recording_name=f"episode on {world.name}")
        self.view.set_world(world.occupancy[::-1], world.resolution_m, world.origin, goal)
        self.cycle = 0

    def __call__(self, row: TraceRow, scan: Scan) -> None:
        r = self.controller.last_result
        stick = self.controller.last_stick
        filtered = None if r is None or r.filter_name != "egc" else r.filtered
        self.view.on_telemetry(
            Telemetry(
                seq=self.cycle,
                stamp_ns=round(row.t_s * 1e9),
                state="DRIVING" if r is not None else "HOLD",
                mode=stick.mode if stick is not None else "shared",
                v_ref=row.v_ref_mps,
                w_ref=row.w_ref_radps,
                v_cmd=row.v_cmd_mps,
                w_cmd=row.w_cmd_radps,
                w_si=1.0 if r is None else r.w_si,
                region="safe" if r is None else r.region.value,
                side=row.side,
                limiter=row.limiter,
                igc=None if filtered is None else filtered.igc,
                agc=None if filtered is None else filtered.agc,
                egc=None if filtered is None else filtered.egc,
                r_rc=0.0 if filtered is None else filtered.r_rc_m,
                scan_xy=scan.points().astype("float32"),
                pose=(row.x_m, row.y_m, row.yaw_rad),
                profile=self.controller.config.profile.name,
                cycle=self.cycle,
            )
        )
        self.cycle += 1

    def close(self) -> None:
        self.view.close()


def run(args: argparse.Namespace) -> int:
    base = _settings_from_args(args)
    if args.batch or args.random_worlds is not None:
        if args.record:
            raise UsageError("--record saves a single episode; it cannot be used with a batch")
        if args.bag:
            raise UsageError("--bag writes a single episode; it cannot be used with a batch")
        return _run_batch(args, base)
    if args.out is not None:
        raise UsageError(
            "--out writes a batch's JSON lines (--batch or --random-worlds); a single episode "
            "prints to stdout"
        )
    if not base.map:
        raise UsageError("--map is required (a map.yaml, a .toml world or a built-in name)")
    if args.record:
        check_writable(args.record, "--record")
    if args.bag:
        try:
            check_bag_path(args.bag)
        except BagError as exc:
            raise UsageError(f"--bag {exc}") from None
    _, summary = run_settings(base, record_path=args.record, bag_path=args.bag)
    if args.bag:
        summary["bag"] = args.bag
    if args.json:
        print(json.dumps(summary, allow_nan=False))
    else:
        print(
            f"{summary['outcome']} after {summary['time_s']:.1f} s simulated, "
            f"{summary['path_m']:.2f} m, min clearance {summary['min_clearance_m']:.3f} m, "
            f"{summary['interventions']} interventions in {summary['steps']} cycles "
            f"({summary['wall_s']:.2f} s wall)"
        )
    return 0


# ---------------------------------------------------------------------------------------------
# Batch


def _suite_settings(path: str, base: EpisodeSettings) -> list[EpisodeSettings]:
    try:
        lines = Path(path).read_text(encoding="utf-8").splitlines()
    except OSError as exc:
        raise UsageError(f"cannot read suite {path}: {exc.strerror or exc}") from None
    out = []
    for no, line in enumerate(lines, start=1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        where = f"{path}:{no}"
        try:
            item = json.loads(line)
        except json.JSONDecodeError as exc:
            raise UsageError(f"{where}: not JSON ({exc.msg})") from None
        if not isinstance(item, dict) or "map" not in item:
            raise UsageError(f"{where}: expected an object with at least a 'map' key")
        unknown = sorted(set(item) - SUITE_KEYS)
        if unknown:
            raise UsageError(f"{where}: unknown key(s) {', '.join(unknown)}")
        try:
            out.append(_apply_suite_item(item, base))
        except (TypeError, ValueError, UsageError) as exc:
            raise UsageError(f"{where}: {exc}") from None
    if not out:
        raise UsageError(f"suite {path} holds no episodes")
    return out


def _apply_suite_item(item: dict[str, Any], base: EpisodeSettings) -> EpisodeSettings:
    def numbers(key: str, n: int) -> tuple[float, ...]:
        value = item[key]
        if isinstance(value, str):
            return _floats(value, n, key)
        if not isinstance(value, list) or len(value) != n:
            raise ValueError(f"{key} must be a list of {n} numbers")
        return _floats(",".join(str(v) for v in value), n, key)

    s = replace(base, map=str(item["map"]))
    if "start" in item:
        x, y, yaw = numbers("start", 3)
        s = replace(s, start=(x, y, yaw))
    if "goal" in item:
        gx, gy = numbers("goal", 2)
        s = replace(s, goal=(gx, gy))
    for key, field in (
        ("operator", "operator"),
        ("filter", "filter"),
        ("profile", "profile"),
        ("via", "via"),
    ):
        if key in item:
            s = replace(s, **{field: str(item[key])})
    if s.filter not in FILTERS:
        raise ValueError(f"filter must be one of {', '.join(FILTERS)}")
    if s.via not in VIA_CHOICES:
        raise ValueError(f"via must be one of {', '.join(VIA_CHOICES)}")
    for key, field in (
        ("max_time", "max_time_s"),
        ("goal_tolerance", "goal_tolerance_m"),
        ("dt", "dt_s"),
        ("stall_time", "stall_time_s"),
    ):
        if key in item:
            value = float(item[key])
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{key} must be a positive number")
            s = replace(s, **{field: value})
    if "seed" in item:
        s = replace(s, seed=int(item["seed"]))
    return s


def _run_one_safely(settings: EpisodeSettings) -> dict[str, Any]:
    """Worker: one episode; a bad episode becomes an error record instead of ending the batch."""
    try:
        return run_settings(settings)[1]
    except UsageError as exc:
        return {"error": str(exc), **{k: v for k, v in asdict(settings).items() if v is not None}}


def _worker_init() -> None:
    """Worker: a terminal's Ctrl-C (SIGINT to the whole process group) is the batch's to
    answer; it stops its workers itself (``Pool.terminate``: SIGTERM), with no traceback each."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _stop_on_sigterm(signum: int, _frame: object) -> None:
    signal.signal(signal.SIGTERM, signal.SIG_IGN)  # a second one must not cut the cleanup short
    raise SystemExit(128 + signum)


@contextlib.contextmanager
def _sigterm_stops_the_batch() -> Iterator[None]:
    """While the pool runs, SIGTERM raises SystemExit(143) in the main thread, so the pool's
    ``with`` terminates the workers on the way out. (SIGTERM's default action ended this process
    alone: the workers, children of the fork server, ran their episodes on for minutes.) A
    handler someone else installed, or a batch run off the main thread, is left as it is."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.getsignal(signal.SIGTERM)
    if previous not in (signal.SIG_DFL, None):
        yield
        return
    signal.signal(signal.SIGTERM, _stop_on_sigterm)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)


def run_batch(
    settings: Sequence[EpisodeSettings], jobs: int, progress: bool = True
) -> Iterator[dict[str, Any]]:
    """Summaries of the episodes, in input order, computed by ``jobs`` worker processes.

    SIGINT (KeyboardInterrupt) or SIGTERM (SystemExit 143) in the main thread, or closing the
    generator, terminates the workers before the exception goes on. A caller that does work
    between summaries should close the generator on the way out (``contextlib.closing``).
    """
    from tqdm import tqdm

    bar = tqdm(total=len(settings), unit="episode", file=sys.stderr, disable=not progress)
    try:
        if jobs <= 1 or len(settings) <= 1:
            for s in settings:
                yield _run_one_safely(s)
                bar.update()
            return
        # Not fork: workers forked from a process with other threads (a Zenoh runtime, a test
        # harness's servers) can inherit a lock held at that instant and hang; a batch in CI
        # hung so with two of its three episodes done. The fork server starts clean.
        ctx = multiprocessing.get_context("forkserver" if sys.platform == "linux" else "spawn")
        with (
            _sigterm_stops_the_batch(),
            ctx.Pool(min(jobs, len(settings)), initializer=_worker_init) as pool,
        ):
            for summary in pool.imap(_run_one_safely, settings):
                yield summary
                bar.update()
    finally:
        bar.close()


def _run_batch(args: argparse.Namespace, base: EpisodeSettings) -> int:
    if args.batch and args.random_worlds is not None:
        raise UsageError("give either --batch or --random-worlds, not both")
    if args.jobs < 1:
        raise UsageError(f"--jobs must be at least 1, got {args.jobs}")
    if args.out is not None:  # now, not as a traceback after the suite is read or run
        check_writable(args.out, "--out")
    if args.batch:
        suite = _suite_settings(args.batch, base)
    else:
        if args.random_worlds < 1:
            raise UsageError(f"--random-worlds must be at least 1, got {args.random_worlds}")
        if args.map or args.start or args.goal:
            raise UsageError("--random-worlds makes its own maps: drop --map/--start/--goal")
        suite = [
            replace(base, map=f"random:{seed}", seed=seed)
            for seed in range(base.seed, base.seed + args.random_worlds)
        ]
    try:
        out = open(args.out, "w", encoding="utf-8") if args.out else sys.stdout  # noqa: SIM115
    except OSError as exc:  # checked above; the folder may have gone since
        raise UsageError(f"--out {args.out}: {exc.strerror or exc}") from None
    counts = {"reached": 0, "collided": 0, "stalled": 0, "timeout": 0, "error": 0}
    t0 = time.perf_counter()
    done = 0
    try:
        with contextlib.closing(run_batch(suite, args.jobs)) as summaries:
            for summary in summaries:
                counts[summary.get("outcome", "error")] += 1
                out.write(json.dumps(summary, allow_nan=False) + "\n")
                out.flush()
                done += 1
    except (KeyboardInterrupt, SystemExit):
        print(
            f"egc-teleop episode: stopped; {done} of {len(suite)} episodes written, "
            "the workers ended",
            file=sys.stderr,
        )
        raise
    finally:
        if out is not sys.stdout:
            out.close()
    print(
        f"{len(suite)} episodes: {counts['reached']} reached, {counts['collided']} collided, "
        f"{counts['stalled']} stalled, {counts['timeout']} timed out, {counts['error']} failed "
        f"({time.perf_counter() - t0:.1f} s wall, {args.jobs} jobs)",
        file=sys.stderr,
    )
    return 2 if counts["error"] else 0
