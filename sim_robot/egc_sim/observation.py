"""What an operator model sees: the operator view's content, as it arrives (DESIGN 10).

The ``sighted`` and ``route`` operator models do not read the simulator's true pose. They are
fed ``Observation``s, one per telemetry message that has *arrived* at the operator (the scan in
the robot frame, the pose, the robot's state), with ``observe(t_s, observation)``, and asked for
the stick with ``command(t_s, pose)``; the ``pose`` argument of the ``Operator`` protocol is
ignored by them (it is the simulator's truth, which no operator has).

``ViewBuffer`` models the operator's reaction time: at time t the operator acts on the newest
observation that had arrived by ``t - reaction_s``. "Newest" is by the robot's stamp, so a
telemetry message overtaken by a later one (a UDP link may reorder) never replaces it.

In a plain episode (no link) ``SimSensor`` builds the observation from the simulator at the
moment the operator is asked (``Sensing`` feeds it), so the operator sees the current view,
still through its reaction time.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
import numpy.typing as npt

from egc_sim.grid_world import Pose
from egc_sim.operators import Stick
from egc_sim.simulator import Simulator

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True, slots=True, eq=False)
class Observation:
    """One operator-view frame: the robot's telemetry of time ``stamp_s`` (robot clock, s).

    ``scan_xy`` is (N, 2) obstacle points in the robot frame {R} at that time; ``pose`` the
    robot's pose (x, y, yaw) in the world frame, None when the robot did not report one;
    ``state`` and ``reason`` the robot's safety state (DESIGN 8) as the view shows it;
    ``goal`` the active via point the robot echoes in its telemetry (DESIGN 7, world frame), None
    when it has none (then the operator steers at its own goal).
    """

    stamp_s: float
    pose: Pose | None
    scan_xy: FloatArray = field(default_factory=lambda: np.zeros((0, 2), np.float64))
    state: str = "DRIVING"
    reason: str = ""
    goal: tuple[float, float] | None = None


class ObservingOperator(Protocol):
    """An operator model fed with what arrives at the operator (module docstring)."""

    def observe(self, t_s: float, observation: Observation) -> None: ...

    def command(self, t_s: float, pose: Pose) -> Stick: ...


class ViewBuffer:
    """Observations by arrival time; ``seen(t)`` is the one the operator acts on at ``t``."""

    def __init__(self, reaction_s: float = 0.25) -> None:
        if not (math.isfinite(reaction_s) and reaction_s >= 0):
            raise ValueError(f"reaction time must be a number of seconds >= 0, got {reaction_s}")
        self.reaction_s = reaction_s
        self._pending: deque[tuple[float, Observation]] = deque()
        self._current: Observation | None = None

    def observe(self, t_s: float, observation: Observation) -> None:
        """``observation`` arrived at the operator at ``t_s`` (non-decreasing)."""
        self._pending.append((t_s, observation))

    def seen(self, t_s: float) -> Observation | None:
        """The newest observation (by stamp) that arrived by ``t_s - reaction_s``."""
        horizon = t_s - self.reaction_s + 1e-9
        pending = self._pending
        while pending and pending[0][0] <= horizon:
            obs = pending.popleft()[1]
            if self._current is None or obs.stamp_s >= self._current.stamp_s:
                self._current = obs
        return self._current


class SimSensor:
    """The current operator view in a plain episode: the simulator's scan and true pose.

    The scan is decimated like the robot's telemetry (every ``decimation``-th point). ``via``,
    when given, returns the active via point the robot echoes (``Observation.goal``).
    """

    def __init__(
        self,
        sim: Simulator,
        decimation: int = 2,
        via: Callable[[], tuple[float, float] | None] | None = None,
    ) -> None:
        self.sim = sim
        self.decimation = max(1, int(decimation))
        self.via = via

    def __call__(self, t_s: float, pose: Pose) -> Observation:
        points = self.sim.scan(stamp_ns=round(t_s * 1e9)).points()[:: self.decimation]
        goal = None if self.via is None else self.via()
        return Observation(t_s, pose, np.asarray(points, dtype=np.float64), goal=goal)


class Sensing:
    """An ``Operator`` made of an observing operator and a sensor called at every command."""

    def __init__(
        self, operator: ObservingOperator, sensor: Callable[[float, Pose], Observation]
    ) -> None:
        self.operator = operator
        self.sensor = sensor

    def command(self, t_s: float, pose: Pose) -> Stick:
        self.operator.observe(t_s, self.sensor(t_s, pose))
        return self.operator.command(t_s, pose)


def to_world(pose: Pose, xy: FloatArray) -> FloatArray:
    """Points (N, 2) in {R} of ``pose`` to the world frame."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    out = np.empty_like(xy, dtype=np.float64)
    out[:, 0] = pose[0] + c * xy[:, 0] - s * xy[:, 1]
    out[:, 1] = pose[1] + s * xy[:, 0] + c * xy[:, 1]
    return out
