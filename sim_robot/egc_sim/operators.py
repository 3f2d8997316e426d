"""Scripted operators: stick deflection from time and pose, as a person at the joystick would.

Each operator returns a ``Stick``: x_o (forward) and y_o (left) deflection in [-1, 1] after the
deadzone (DESIGN 4), the deadman button, the mode the operator selected (``direct`` | ``shared``,
paper sec. 2.3) and the e-stop button. The robot's pipeline maps the deflection to (v, w) by the
paper's eq. 4; operators know nothing about the robot's speeds.

- ``ForwardOperator``: the stick held straight forward, the paper's Fig. 9 experiment.
- ``GoalOperator``: a naive operator who steers at the goal and cannot see obstacles: turn rate
  proportional to the heading error, forward deflection ``cos(error)`` (turning in place while
  the goal is behind).
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
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

from egc_common.joystick import clamp_unit
from egc_common.joystick_file import JoystickFileError, JoystickTrack, load_joystick_file
from egc_common.kinematics import wrap_angle

from egc_sim.grid_world import Pose

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


def _check_mode(mode: str) -> str:
    if mode not in MODES:
        raise ValueError(f"operator mode must be direct or shared, got {mode!r}")
    return mode


@dataclass(frozen=True, slots=True)
class ForwardOperator:
    """Constant forward deflection (default full stick), no turning."""

    mode: str = "shared"
    x_o: float = 1.0

    def __post_init__(self) -> None:
        _check_mode(self.mode)

    def command(self, t_s: float, pose: Pose) -> Stick:
        return Stick(clamp_unit(self.x_o), 0.0, True, self.mode)


@dataclass(frozen=True, slots=True)
class GoalOperator:
    """Steers at ``goal`` (x_m, y_m) from the true pose; blind to obstacles.

    y_o = clamp(gain * heading error / pi), x_o = max(cos(heading error), 0).
    """

    goal: tuple[float, float]
    mode: str = "shared"
    gain: float = 2.0

    def __post_init__(self) -> None:
        _check_mode(self.mode)
        if not (math.isfinite(self.gain) and self.gain > 0):
            raise ValueError("goal operator gain must be positive")

    def command(self, t_s: float, pose: Pose) -> Stick:
        x, y, yaw = pose
        error = wrap_angle(math.atan2(self.goal[1] - y, self.goal[0] - x) - yaw)
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


def make_operator(spec: str, goal: tuple[float, float] | None, mode: str) -> Operator:
    """``forward``, ``goal`` (needs the goal) or the path of a joystick file.

    ``mode`` is what the scripted operators select; a file carries its own per-row mode.
    Raises ValueError (a ``JoystickFileError`` for files) with a clear message.
    """
    if spec == "forward":
        return ForwardOperator(mode)
    if spec == "goal":
        if goal is None:
            raise ValueError("the goal operator needs a goal")
        return GoalOperator(goal, mode)
    try:
        return ReplayOperator.from_file(spec)
    except JoystickFileError as exc:
        raise JoystickFileError(
            f"operator {spec!r} is neither forward, goal nor a joystick file: {exc}"
        ) from None
