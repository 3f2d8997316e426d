"""The headless episode engine (DESIGN 2: ``egc-teleop episode``, the experiments and the arena
share it): one episode in the simulator, driven by a scripted operator through the robot's own
command pipeline, summarised as a JSON-ready dict.

``egc_sim`` supplies the world, the simulated robot, the scripted operator and the episode loop;
the controller is the robot's own command pipeline, ``egc_robot.pipeline.step_command`` (eq. 4
mapping, EGC in shared mode, anti-dead-lock, profile limits, footprint sweep), called here, never
copied. When the operator releases the deadman or presses e-stop the robot's stop rule applies
(``egc_robot.safety.decelerate``).

- ``filter="egc"`` runs the pipeline with the EGC filter and the scripted operators select
  ``shared`` mode; ``filter="none"`` turns the filter off and they select ``direct``. A joystick
  file selects its mode per row, and with ``none`` shared rows are not filtered.
- ``map`` is a map.yaml, a .toml or .npy world, or a built-in name (``hallway``, ``office02``,
  ``random:SEED``); ``start``/``goal``/``goal_tolerance_m`` default to the world's own where it
  has them.
- Control runs at 1 / ``dt_s`` Hz (20 Hz); the simulator sub-steps within a cycle.
- ``via`` gives the filter its via points (DESIGN 7): ``goal`` (one, at the goal), ``route``
  (the corners of a route planned on the map) or ``none``. The robot echoes the active one in
  its telemetry and the operator view draws it, so the ``goal`` and ``sighted`` operators steer
  at the active via point while there is one, and at the goal after the last (issue 11).
- ``record_path`` saves the episode as the operator view shows a live run
  (``egc_operator.view.record_episode``), one telemetry message per cycle.
- ``bag_path`` writes the episode as a ROS 2 log (``egc_sim.episode_bag``): ``/scan``,
  ``/odom`` and the driver's ``/cmd_vel`` (the command *before* the filter), stamped with the
  simulated clock; a path ending in ``.mcap`` is one MCAP file, any other a ROS 2 bag
  directory.
- ``stall_time_s`` ends an episode as ``stalled`` once the robot has stood still that long
  (``egc_sim.episodes``); None (the default) ends an episode only at the goal, at a contact or
  at ``max_time_s``.

Summary keys: ``reached``, ``collided``, ``time_s`` (simulated), ``path_m``, ``min_clearance_m``
(smallest footprint clearance, 0 after a contact, capped at 1 m), ``interventions``, ``steps``
(control cycles), ``wall_s`` (wall-clock seconds of the episode loop, world loading excluded),
plus ``outcome`` (reached | collided | stalled | timeout), ``goal_distance_m``, ``final_pose``
and the settings. An **intervention** is a control cycle in which the pipeline's limiter was
``egc`` (the filter changed the operator's command) or ``sweep`` (the footprint check scaled it
down). Cycles limited only by the profile's velocity/acceleration limits, stopped by the deadman
or passed through by the anti-dead-lock rule do not count; in direct mode the count is 0.
DESIGN 13's metrics (``egc_robot.intervention``): ``commands`` (cycles through the pipeline),
``changed``, ``changed_share``, ``mean_cut`` and ``hold_s``, each against what direct mode would
have sent on the same cycle.

Bad settings raise ``UsageError`` with one line for the user. Many episodes in worker
processes: ``egc_experiments.episode_batch``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from egc_common.cli_args import plain_float
from egc_common.errors import UsageError
from egc_common.messages import Telemetry
from egc_common.profiles import get_profile
from egc_common.scan import Scan
from egc_robot.intervention import InterventionTally
from egc_robot.pipeline import (
    INTERVENING,
    Limiter,
    PipelineConfig,
    PipelineResult,
    step_command,
)
from egc_robot.safety import MAX_CONTROL_PERIOD_S, SweepParams, decelerate
from egc_robot.via_points import DEFAULT_TOLERANCE_M, ViaPoints, advance, to_robot_frame
from egc_sim.episode_bag import BagError, BagStep, EpisodeBag
from egc_sim.episodes import ControlOutput, EpisodeResult, TraceRow, run_episode
from egc_sim.grid_world import World
from egc_sim.observation import SimSensor
from egc_sim.operators import Stick, make_operator
from egc_sim.simulator import Simulator
from egc_sim.worlds import WorldError, load_world

DEFAULT_GOAL_TOLERANCE_M = 0.3
INTERVENTIONS = INTERVENING


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
        profile = config.profile
        self.tally = InterventionTally(profile.v_max_mps, profile.w_max_radps)  # DESIGN 13

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
            self.tally.add(r, dt_s)
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
    writes it as a ROS 2 log (module docstring).
    """
    try:
        profile = get_profile(settings.profile)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    try:  # a random world sized for the robot (RandomFieldParams.for_reach)
        world = load_world(
            settings.map,
            seed=settings.seed,
            reach_m=profile.footprint.reach_m,
            footprint=profile.footprint,
        )
    except WorldError as exc:
        raise UsageError(f"cannot load map {settings.map!r}: {exc}") from None
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
        via = episode_via_points(settings.via, world, start, goal, profile.half_size_m[1])
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
            half_width_m=profile.half_size_m[1],
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
            observers.append(bag_observer(bag, sim))
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
        # DESIGN 13: commands, changed, changed_share, mean_cut, hold_s
        **controller.tally.as_dict(),
    }
    return result, summary


def bag_observer(bag: EpisodeBag, sim: Simulator) -> Callable[[TraceRow, Scan], None]:
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


def parse_floats(text: str, n: int, what: str) -> tuple[float, ...]:
    """``n`` comma-separated plain, finite numbers (``egc_common.cli_args.plain_float``);
    UsageError naming ``what`` otherwise."""
    parts = str(text).split(",")
    try:
        values = tuple(plain_float(p) for p in parts)
    except ValueError:
        values = ()
    if len(values) != n or not all(math.isfinite(v) for v in values):
        raise UsageError(f"{what} must be {n} comma-separated finite numbers, got {text!r}")
    return values


def parse_start(text: str) -> tuple[float, float, float]:
    x, y, yaw = parse_floats(text, 3, "--start X,Y,YAW")
    return x, y, yaw


def parse_goal(text: str) -> tuple[float, float]:
    x, y = parse_floats(text, 2, "--goal X,Y")
    return x, y


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
