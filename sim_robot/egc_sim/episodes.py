"""A headless episode: operator -> controller -> simulated robot, until goal, contact or time.

The loop is fixed-rate (``dt_s``, 20 Hz by default), in simulated time. Each control cycle:

1. stop with ``reached`` if the robot's centre is within ``goal_tolerance_m`` of the goal;
2. stop if ``max_time_s`` has elapsed;
3. the operator reads the true pose and returns a ``Stick``;
4. the lidar scans from the current pose;
5. the controller turns (stick, scan) into a velocity command;
6. the simulator drives it for ``dt_s``; stop with ``collided`` on contact;
7. optionally, stop as ``stalled`` once the robot has stood still for ``stall_time_s``. With a
   scripted operator (a function of the pose) and a noise-free lidar a robot that stands still
   for one cycle sees the same inputs in the next one, so it would stand still until the time
   runs out; the option saves that time in large batches. Off by default.

The controller is the robot's side and is *passed in*: sim_robot does not depend on the robot
package (DESIGN 2). The episode engine (``egc_experiments.episode``) wires in the robot's own
command pipeline. A controller reports whether it ``intervened`` (changed the operator's
command for safety) so that the episode can count interventions without knowing how.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from egc_common.scan import Scan

from egc_sim.grid_world import Pose
from egc_sim.operators import Operator, Stick
from egc_sim.simulator import Simulator

OUTCOMES = ("reached", "collided", "stalled", "timeout")


@dataclass(frozen=True, slots=True)
class ControlOutput:
    """One control cycle's result: the command for the base and what the controller did."""

    v_mps: float
    w_radps: float
    v_ref_mps: float
    w_ref_radps: float
    intervened: bool
    limiter: str = "none"
    side: str | None = None


class Controller(Protocol):
    def __call__(self, stick: Stick, scan: Scan, dt_s: float) -> ControlOutput: ...


@dataclass(frozen=True, slots=True)
class TraceRow:
    """One control cycle, for figures and tests: pose before the cycle and the commands."""

    t_s: float
    x_m: float
    y_m: float
    yaw_rad: float
    x_o: float
    y_o: float
    v_ref_mps: float
    w_ref_radps: float
    v_cmd_mps: float
    w_cmd_radps: float
    limiter: str
    side: str | None


@dataclass(frozen=True, slots=True)
class EpisodeResult:
    outcome: str
    time_s: float
    path_m: float
    min_clearance_m: float
    interventions: int
    steps: int
    final_pose: Pose
    goal_distance_m: float
    trace: tuple[TraceRow, ...] = ()

    @property
    def reached(self) -> bool:
        return self.outcome == "reached"

    @property
    def collided(self) -> bool:
        return self.outcome == "collided"

    def summary(self) -> dict[str, Any]:
        """The pinned JSON keys (without ``wall_s``, which the caller measures) and a few more."""
        return {
            "reached": self.reached,
            "collided": self.collided,
            "time_s": round(self.time_s, 6),
            "path_m": round(self.path_m, 6),
            "min_clearance_m": round(self.min_clearance_m, 6),
            "interventions": self.interventions,
            "steps": self.steps,
            "outcome": self.outcome,
            "goal_distance_m": round(self.goal_distance_m, 6),
            "final_pose": [round(v, 6) for v in self.final_pose],
        }


def run_episode(
    sim: Simulator,
    operator: Operator,
    controller: Controller,
    goal: tuple[float, float],
    goal_tolerance_m: float,
    max_time_s: float,
    dt_s: float = 0.05,
    record_trace: bool = False,
    stall_time_s: float | None = None,
    observer: Callable[[TraceRow, Scan], None] | None = None,
) -> EpisodeResult:
    """Run the loop of the module docstring and summarise it.

    ``observer`` (e.g. a recorder for the operator view) sees every cycle's row and scan.
    """
    if not (math.isfinite(dt_s) and dt_s > 0):
        raise ValueError("control period must be positive")
    still_since: float | None = None
    steps = 0
    interventions = 0
    trace: list[TraceRow] = []
    outcome = "timeout"
    # Count cycles rather than add up dt, so that max_time_s is met exactly.
    max_steps = math.floor(max_time_s / dt_s + 1e-9)

    def distance() -> float:
        return math.hypot(sim.pose[0] - goal[0], sim.pose[1] - goal[1])

    while True:
        if distance() <= goal_tolerance_m:
            outcome = "reached"
            break
        if steps >= max_steps:
            break
        pose = sim.pose
        t = sim.time_s
        stick = operator.command(t, pose)
        scan = sim.scan(stamp_ns=round(t * 1e9))
        out = controller(stick, scan, dt_s)
        if record_trace or observer is not None:
            row = TraceRow(
                t,
                *pose,
                stick.x_o,
                stick.y_o,
                out.v_ref_mps,
                out.w_ref_radps,
                out.v_mps,
                out.w_radps,
                out.limiter,
                out.side,
            )
            if record_trace:
                trace.append(row)
            if observer is not None:
                observer(row, scan)
        sim.step(out.v_mps, out.w_radps, dt_s)
        steps += 1
        interventions += int(out.intervened)
        if sim.collided:
            outcome = "collided"
            break
        if stall_time_s is not None:
            if sim.pose != pose:
                still_since = None
            elif still_since is None:
                still_since = t
            elif sim.time_s - still_since >= stall_time_s - 1e-9:
                outcome = "stalled"
                break
    return EpisodeResult(
        outcome=outcome,
        time_s=sim.time_s,
        path_m=sim.path_m,
        min_clearance_m=sim.min_clearance_m,
        interventions=interventions,
        steps=steps,
        final_pose=sim.pose,
        goal_distance_m=distance(),
        trace=tuple(trace),
    )
