"""Scripted operators: stick deflection from time and pose, as a person at the joystick would.

Each operator returns a ``Stick``: x_o (forward) and y_o (left) deflection in [-1, 1] after the
deadzone (DESIGN 4), the deadman button, the mode the operator selected (``direct`` | ``shared``,
paper sec. 2.3) and the e-stop button. The robot's pipeline maps the deflection to (v, w) by the
paper's eq. 4; operators know nothing about the robot's speeds.

- ``ForwardOperator``: the stick held straight forward, the paper's Fig. 9 experiment.
- ``GoalOperator``: a naive operator who steers at the goal and cannot see obstacles: turn rate
  proportional to the heading error, forward deflection ``cos(error)`` (turning in place while
  the goal is behind). Given ``target`` (the active via point the robot echoes in its
  telemetry, DESIGN 7, which the operator view draws), it steers at that one while there is
  one: blind to the obstacles, not to the marker on the screen (issue 11). Without via points,
  or with the single via point at the goal, that is the same thing.
- ``sighted`` (``sighted.SightedOperator``) and ``route`` (``route.RouteOperator``): the models
  of the network-delay experiments (DESIGN 10), fed with what the operator view shows
  (``observation``) rather than the true pose.
- ``careful`` (``careful.CarefulOperator``): the careful driver of DESIGN 13, who plans with
  clearance on the map, drives smoothly and keeps the footprint 0.2 m from everything; also
  fed with the operator view.
- ``ReplayOperator``: a recorded joystick file, played back on the simulated clock. The file
  format is the one the operator process reads (``egc_common.joystick_file``): CSV with header
  ``t_s,x,y[,deadman][,mode][,estop][,reset]``; ``t_s`` non-decreasing seconds from the start,
  ``x``/``y`` in [-1, 1], ``deadman``/``estop``/``reset`` 0 or 1 (defaults 1, 0, 0), ``mode``
  ``direct`` or ``shared`` (default ``shared``); ``#`` comments and blank lines ignored. Each row
  holds until the next (zero-order hold); before the first row and after the last one the stick
  is centred with the deadman released.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

from egc_common.joystick import clamp_unit
from egc_common.joystick_file import JoystickFileError, JoystickTrack, load_joystick_file
from egc_common.kinematics import wrap_angle

from egc_sim.grid_world import Pose, World

if TYPE_CHECKING:
    from egc_common.profiles import RobotProfile

    from egc_sim.observation import Observation, ObservingOperator

OBSERVING = ("sighted", "route", "careful")  # models fed with the operator view

MODES = ("direct", "shared")


@dataclass(frozen=True, slots=True)
class Stick:
    """One sample of the operator's joystick."""

    x_o: float
    y_o: float
    deadman: bool = True
    mode: str = "shared"
    estop: bool = False


class Operator(Protocol):
    def command(self, t_s: float, pose: Pose) -> Stick: ...


def check_mode(mode: str) -> str:
    if mode not in MODES:
        raise ValueError(f"operator mode must be direct or shared, got {mode!r}")
    return mode


@dataclass(frozen=True, slots=True)
class ForwardOperator:
    """Constant forward deflection (default full stick), no turning."""

    mode: str = "shared"
    x_o: float = 1.0

    def __post_init__(self) -> None:
        check_mode(self.mode)

    def command(self, t_s: float, pose: Pose) -> Stick:
        return Stick(clamp_unit(self.x_o), 0.0, True, self.mode)


@dataclass(frozen=True, slots=True)
class GoalOperator:
    """Steers at ``goal`` (x_m, y_m) from the true pose; blind to obstacles.

    y_o = clamp(gain * heading error / pi), x_o = max(cos(heading error), 0). ``target``
    (optional) returns the active via point the view shows, steered at instead while not None.
    """

    goal: tuple[float, float]
    mode: str = "shared"
    gain: float = 2.0
    target: Callable[[], tuple[float, float] | None] | None = None

    def __post_init__(self) -> None:
        check_mode(self.mode)
        if not (math.isfinite(self.gain) and self.gain > 0):
            raise ValueError("goal operator gain must be positive")

    def command(self, t_s: float, pose: Pose) -> Stick:
        x, y, yaw = pose
        via = None if self.target is None else self.target()
        gx, gy = self.goal if via is None else via
        error = wrap_angle(math.atan2(gy - y, gx - x) - yaw)
        return Stick(
            max(math.cos(error), 0.0), clamp_unit(self.gain * error / math.pi), True, self.mode
        )


class ReplayOperator:
    """Plays a joystick file back on the simulated clock (format in the module docstring)."""

    def __init__(self, track: JoystickTrack) -> None:
        self.track = track

    @classmethod
    def from_file(cls, path: str | Path) -> ReplayOperator:
        return cls(JoystickTrack(load_joystick_file(path)))

    def command(self, t_s: float, pose: Pose) -> Stick:
        s = self.track.at(t_s)
        return Stick(s.x, s.y, s.deadman, s.mode, s.estop)


def make_operator(
    spec: str,
    goal: tuple[float, float] | None,
    mode: str,
    *,
    seed: int = 0,
    world: World | None = None,
    start: Pose | None = None,
    half_width_m: float = 0.2,
    sensor: Callable[[float, Pose], Observation] | None = None,
    via: Callable[[], tuple[float, float] | None] | None = None,
    profile: RobotProfile | None = None,
) -> Operator:
    """``forward``, ``goal`` (needs the goal), ``sighted[:K=V,...]`` (the goal),
    ``route[:K=V,...]`` (the goal, the world and the start), ``careful[:K=V,...]`` (the goal,
    the world, the start and the robot ``profile``) or the path of a joystick file.

    ``mode`` is what the scripted operators select; a file carries its own per-row mode.
    ``sighted`` and ``route`` observe the operator view (``observation``): with ``sensor`` (a
    plain episode) they are wrapped to sense it at every command, without it they are returned
    as they are for the caller to ``observe``. Their options: ``sighted:reaction_s=0.5,
    noise_std=0.1,...`` (``sighted.SightedParams``), ``route:map=building,reaction_s=...``
    (``route.RouteParams``; ``map=building`` plans on the map without its furniture),
    ``careful:speed_mps=0.5,clearance_m=0.3,...`` (``careful.CarefulParams``).
    ``seed`` seeds the steering noise; ``half_width_m`` is the robot's (route inflation, sighted
    corridor). ``via`` returns the active via point the robot echoes (the ``goal`` operator
    steers at it; ``sighted`` reads it from its ``sensor``'s observations). Raises ValueError (a
    ``JoystickFileError`` for files) with a clear message.
    """
    if spec == "forward":
        return ForwardOperator(mode)
    if spec == "goal":
        if goal is None:
            raise ValueError("the goal operator needs a goal")
        return GoalOperator(goal, mode, target=via)
    name, _, options = spec.partition(":")
    if name in OBSERVING:
        observing = _make_observing(
            name, options, goal, mode, seed, world, start, half_width_m, profile
        )
        if sensor is None:
            return observing
        from egc_sim.observation import Sensing

        return Sensing(observing, sensor)
    try:
        return ReplayOperator.from_file(spec)
    except JoystickFileError as exc:
        raise JoystickFileError(
            f"operator {spec!r} is neither forward, goal nor a joystick file "
            f"(nor sighted, route or careful): {exc}"
        ) from None


_BOOLEANS = {"1": True, "true": True, "yes": True, "0": False, "false": False, "no": False}


def _options(name: str, text: str) -> dict[str, str]:
    out: dict[str, str] = {}
    for item in filter(None, (i.strip() for i in text.split(","))):
        key, sep, value = item.partition("=")
        if not sep or not key.strip() or key.strip() in out:
            raise ValueError(f"operator {name}: options are KEY=VALUE separated by commas")
        out[key.strip()] = value.strip()
    return out


def _make_observing(
    name: str,
    options: str,
    goal: tuple[float, float] | None,
    mode: str,
    seed: int,
    world: World | None,
    start: Pose | None,
    half_width_m: float,
    profile: RobotProfile | None = None,
) -> ObservingOperator:
    from dataclasses import fields, replace

    from egc_sim.route import RouteOperator, RouteParams
    from egc_sim.sighted import SightedOperator, SightedParams

    if goal is None:
        raise ValueError(f"the {name} operator needs a goal")
    opts = _options(name, options)
    if name == "careful":
        return _make_careful(opts, goal, mode, world, start, profile)
    building = False
    if name == "route":
        map_choice = opts.pop("map", "full")
        if map_choice not in ("full", "building"):
            raise ValueError("operator route: map must be full or building")
        building = map_choice == "building"
    params_type: type[SightedParams] | type[RouteParams] = (
        SightedParams if name == "sighted" else RouteParams
    )
    names = {f.name: f.type for f in fields(params_type)}
    defaults: SightedParams | RouteParams = (
        SightedParams(corridor_m=half_width_m + 0.1) if name == "sighted" else RouteParams()
    )
    changes: dict[str, float | int | bool] = {}
    for key, value in opts.items():
        if key not in names:
            raise ValueError(
                f"operator {name}: unknown option {key!r} (known: {', '.join(sorted(names))})"
            )
        if names[key] in (bool, "bool"):
            if value.lower() not in _BOOLEANS:
                raise ValueError(f"operator {name}: {key} must be 1 or 0, got {value!r}")
            changes[key] = _BOOLEANS[value.lower()]
            continue
        try:
            changes[key] = int(value) if key == "bins" else float(value)
        except ValueError:
            raise ValueError(f"operator {name}: {key}={value!r} is not a number") from None
    params = replace(defaults, **changes)  # type: ignore[arg-type]
    if isinstance(params, SightedParams):
        return SightedOperator(goal, mode, seed, params)
    if world is None or start is None:
        raise ValueError("the route operator needs the map and the start")
    return RouteOperator.on_world(world, start, goal, half_width_m, mode, params, building)


def _make_careful(
    opts: dict[str, str],
    goal: tuple[float, float],
    mode: str,
    world: World | None,
    start: Pose | None,
    profile: RobotProfile | None,
) -> ObservingOperator:
    from dataclasses import fields

    from egc_sim.careful import CarefulOperator, CarefulParams

    known = {f.name for f in fields(CarefulParams)}
    values: dict[str, float] = {}
    for key, value in opts.items():
        if key not in known:
            raise ValueError(
                f"operator careful: unknown option {key!r} (known: {', '.join(sorted(known))})"
            )
        try:
            values[key] = float(value)
        except ValueError:
            raise ValueError(f"operator careful: {key}={value!r} is not a number") from None
    params = CarefulParams(**values)
    if world is None or start is None or profile is None:
        raise ValueError("the careful operator needs the map, the start and the robot profile")
    return CarefulOperator.on_world(world, start, goal, profile, mode, params)
