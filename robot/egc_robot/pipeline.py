"""The robot's command pipeline, one control cycle, as a pure function.

joystick deflection -> eq. 4 -> filter (EGC in shared mode) -> anti-dead-lock rule ->
profile velocity and acceleration limits -> footprint sweep (DESIGN 4, 5, 5.10).

The robot process, the headless episode runner and the benchmarks all call ``step_command``;
none of them has a copy of it. Watchdog, staleness and e-stop are the state machine's job
(``state_machine``); when it says stop, the process calls ``safety.decelerate`` instead.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field

import numpy.typing as npt
from egc_common.joystick import JoystickMapping, deflection_to_velocity
from egc_common.profiles import RobotProfile
from egc_common.scan import ObstaclePoints, obstacle_points

from egc_robot.filters.egc import EgcCase, EgcParams, EgcResult, Region, Side, egc_filter
from egc_robot.safety import (
    SweepParams,
    increases_clearance,
    limit_acceleration,
    limit_velocity,
    sweep_scale,
)

FILTERS = ("none", "egc")
MODES = ("direct", "shared")

# Cases in which the paper's equations stopped the robot for being close to something; the
# anti-dead-lock rule may then let through a reference command that increases clearance.
_STOPPED_NEAR_OBSTACLE = (EgcCase.EXPANDED, EgcCase.NO_INTERSECTION, EgcCase.ZERO_WEIGHTS)
_CLEARANCE_HORIZON_S = 1.0
_SAME = 1e-9


class Limiter(enum.Enum):
    """What limited the command sent to the base this cycle (shown in the operator view)."""

    NONE = "none"
    EGC = "egc"
    SWEEP = "sweep"
    LIMITS = "limits"
    LATENCY = "latency"  # the latency governor (DESIGN 9) capped the speed
    WATCHDOG = "watchdog"
    HOLD = "hold"
    ESTOP = "estop"


@dataclass(frozen=True, slots=True)
class PipelineConfig:
    profile: RobotProfile
    mapping: JoystickMapping = field(default_factory=JoystickMapping)
    filter: str = "egc"
    horizon_s: float | None = None
    no_return_is_free: bool = False
    sweep: SweepParams = field(default_factory=SweepParams)
    egc_params: EgcParams = field(init=False, repr=False, compare=False)  # derived, once

    def __post_init__(self) -> None:
        if self.filter not in FILTERS:
            raise ValueError(f"unknown filter {self.filter!r} (known: {', '.join(FILTERS)})")
        if self.horizon_s is not None and not (
            math.isfinite(self.horizon_s) and self.horizon_s > 0
        ):
            raise ValueError("horizon must be a positive number of seconds")
        p = self.profile
        params = EgcParams.from_profile(p.r_min_m, p.r_max_m, p.v_max_mps, self.horizon_s)
        if self.no_return_is_free:
            params = EgcParams(params.r_min_m, params.r_max_m, params.horizon_s, True)
        object.__setattr__(self, "egc_params", params)


@dataclass(frozen=True, slots=True)
class PipelineResult:
    v_ref_mps: float
    w_ref_radps: float
    v_cmd_mps: float
    w_cmd_radps: float
    limiter: Limiter
    filtered: EgcResult | None
    sweep_scale: float = 1.0
    escape: bool = False

    @property
    def w_si(self) -> float:
        return 1.0 if self.filtered is None else self.filtered.w_si

    @property
    def region(self) -> Region:
        return Region.SAFE if self.filtered is None else self.filtered.region

    @property
    def side(self) -> Side | None:
        return None if self.filtered is None else self.filtered.side


def filter_velocity(
    config: PipelineConfig,
    v_ref_mps: float,
    w_ref_radps: float,
    mode: str,
    points: npt.ArrayLike | ObstaclePoints,
    previous_cmd: tuple[float, float] | None,
    dt_s: float,
) -> PipelineResult:
    """One cycle from a velocity reference (after eq. 4) to the command for the base.

    ``previous_cmd`` is what the base was last sent; None skips the acceleration limits (for
    stateless tools such as ``egc-teleop filter``).
    """
    profile = config.profile
    obstacles = obstacle_points(points)
    pts = obstacles.xy
    shared = mode == "shared" and config.filter == "egc"
    filtered: EgcResult | None = None
    v, w = v_ref_mps, w_ref_radps
    escape = False
    if shared:
        filtered = egc_filter(v_ref_mps, w_ref_radps, obstacles, config.egc_params)
        v, w = filtered.v_mps, filtered.w_radps
        if (
            filtered.case in _STOPPED_NEAR_OBSTACLE
            and filtered.w_si == 0.0
            and increases_clearance(v_ref_mps, w_ref_radps, _CLEARANCE_HORIZON_S, pts, profile)
        ):
            v, w, escape = v_ref_mps, w_ref_radps, True  # DESIGN 5.10: no dead-lock

    after_filter = (v, w)
    v, w = limit_velocity(v, w, profile)
    if previous_cmd is not None:
        v, w = limit_acceleration(v, w, previous_cmd, dt_s, profile)
    limited = abs(v - after_filter[0]) > _SAME or abs(w - after_filter[1]) > _SAME

    scale = sweep_scale(v, w, obstacles, profile, config.sweep) if shared else 1.0
    if scale < 1.0:
        v, w = scale * v, scale * w
        limiter = Limiter.SWEEP
    elif (
        filtered is not None
        and not escape
        and (abs(after_filter[0] - v_ref_mps) > _SAME or abs(after_filter[1] - w_ref_radps) > _SAME)
    ):
        limiter = Limiter.EGC
    elif limited:
        limiter = Limiter.LIMITS
    else:
        limiter = Limiter.NONE
    return PipelineResult(v_ref_mps, w_ref_radps, v, w, limiter, filtered, scale, escape)


def step_command(
    config: PipelineConfig,
    x_o: float,
    y_o: float,
    mode: str,
    points: npt.ArrayLike | ObstaclePoints,
    previous_cmd: tuple[float, float],
    dt_s: float,
) -> PipelineResult:
    """One cycle from normalised stick deflection (x_o forward, y_o left) to the base command."""
    p = config.profile
    v_ref, w_ref = deflection_to_velocity(x_o, y_o, p.v_max_mps, p.w_max_radps, config.mapping)
    return filter_velocity(config, v_ref, w_ref, mode, points, previous_cmd, dt_s)
