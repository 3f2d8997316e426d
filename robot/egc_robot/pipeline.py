"""The robot's command pipeline, one control cycle, as a pure function.

joystick deflection -> eq. 4 -> filter of the family (DESIGN 6; shared mode) -> anti-dead-lock
rule -> profile velocity and acceleration limits -> footprint sweep (DESIGN 4, 5, 5.10, 6).
Every filter runs inside the same pipeline; ``filters.family`` holds the one interface.

The robot process, the headless episode runner and the benchmarks all call ``step_command``;
none of them has a copy of it. Watchdog, staleness and e-stop are the state machine's job
(``state_machine``); when it says stop, the process calls ``safety.decelerate`` instead.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy.typing as npt
from egc_common.joystick import JoystickMapping, deflection_to_velocity
from egc_common.profiles import RobotProfile
from egc_common.scan import ObstaclePoints, obstacle_points

from egc_robot.filters.assist import AssistParams
from egc_robot.filters.cbf import CbfParams
from egc_robot.filters.dwa import DwaParams
from egc_robot.filters.egc import EgcParams, EgcResult, Region, Side
from egc_robot.filters.family import (
    FilterInput,
    FilterResult,
    FilterSettings,
    RobotState,
    available_filters,
    run_egc,
    run_filter,
)
from egc_robot.safety import (
    SweepParams,
    brake_along,
    horizon_scale,
    increases_clearance,
    limit_acceleration,
    limit_velocity,
    reachable,
    sweep_scale,
)

FILTERS = available_filters()
MODES = ("direct", "shared")

_CLEARANCE_HORIZON_S = 1.0
_SAME = 1e-9


class Limiter(enum.Enum):
    """What limited the command sent to the base this cycle (shown in the operator view)."""

    NONE = "none"
    EGC = "egc"  # the filters of DESIGN 6 changed the command: each under its own name
    EK_EGC = "ek-egc"
    ASSIST = "assist"
    DWA = "dwa"
    CBF = "cbf"
    SWEEP = "sweep"
    LIMITS = "limits"
    LATENCY = "latency"  # the latency governor (DESIGN 9) capped the speed
    WATCHDOG = "watchdog"
    HOLD = "hold"
    ESTOP = "estop"


_LIMITER_OF_FILTER = {limiter.value: limiter for limiter in Limiter}

# Limiters that mean "the shared-autonomy layer changed the operator's command" (an intervention).
INTERVENING = (
    Limiter.EGC,
    Limiter.EK_EGC,
    Limiter.ASSIST,
    Limiter.DWA,
    Limiter.CBF,
    Limiter.SWEEP,
)
INTERVENING_NAMES = tuple(limiter.value for limiter in INTERVENING)


# The longest prediction horizon kT accepted (s): r_max / v_max is a few seconds on every
# profile; beyond a minute the predicted point leaves any map.
MAX_HORIZON_S = 60.0


@dataclass(frozen=True, slots=True)
class PipelineConfig:
    profile: RobotProfile
    mapping: JoystickMapping = field(default_factory=JoystickMapping)
    filter: str = "egc"
    horizon_s: float | None = None
    no_return_is_free: bool = False
    sweep: SweepParams = field(default_factory=SweepParams)
    dwa: DwaParams | None = None  # None: from the profile
    assist: AssistParams | None = None
    cbf: CbfParams | None = None
    egc_params: EgcParams = field(init=False, repr=False, compare=False)  # derived, once
    settings: FilterSettings = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.filter not in FILTERS:
            raise ValueError(f"unknown filter {self.filter!r} (known: {', '.join(FILTERS)})")
        if self.horizon_s is not None and not 0.0 < self.horizon_s <= MAX_HORIZON_S:
            # also false for NaN; 1e300 overflowed the prediction and passed every command
            raise ValueError(f"horizon must be a number of seconds in (0, {MAX_HORIZON_S:g}]")
        p = self.profile
        params = EgcParams.from_profile(p.r_min_m, p.r_max_m, p.v_max_mps, self.horizon_s)
        if self.no_return_is_free:
            params = EgcParams(params.r_min_m, params.r_max_m, params.horizon_s, True)
        object.__setattr__(self, "egc_params", params)
        object.__setattr__(
            self, "settings", FilterSettings(p, params, self.dwa, self.assist, self.cbf)
        )


@dataclass(frozen=True, slots=True)
class PipelineResult:
    v_ref_mps: float
    w_ref_radps: float
    v_cmd_mps: float
    w_cmd_radps: float
    limiter: Limiter
    family: FilterResult | None  # what the filter of DESIGN 6 said (None: no filter ran)
    sweep_scale: float = 1.0
    escape: bool = False

    @property
    def filter_name(self) -> str:
        return "none" if self.family is None else self.family.name

    @property
    def filtered(self) -> EgcResult | None:
        """The guide circles of egc / ek-egc (ek-egc: in EK coordinates), else None."""
        return None if self.family is None else self.family.egc

    @property
    def memory(self) -> object | None:
        """What the filter wants back next cycle (assist's histograms)."""
        return None if self.family is None else self.family.memory

    @property
    def w_si(self) -> float:
        return 1.0 if self.family is None else self.family.w_si

    @property
    def region(self) -> Region:
        return Region.SAFE if self.family is None else self.family.region

    @property
    def side(self) -> Side | None:
        return None if self.family is None else self.family.side


def filter_velocity(
    config: PipelineConfig,
    v_ref_mps: float,
    w_ref_radps: float,
    mode: str,
    points: npt.ArrayLike | ObstaclePoints,
    previous_cmd: tuple[float, float] | None,
    dt_s: float,
    *,
    filter_name: str | None = None,
    goal_xy_m: tuple[float, float] | None = None,
    now_ns: int = 0,
    memory: object | None = None,
    loop_delay_s: float | None = None,
) -> PipelineResult:
    """One cycle from a velocity reference (after eq. 4) to the command for the base.

    ``previous_cmd`` is what the base was last sent (None skips the acceleration limits, for
    stateless tools such as ``egc-teleop filter``). ``filter_name`` overrides the configured
    filter of shared mode (the operator's choice); ``goal_xy_m`` is the active via point in {R};
    ``memory`` is the previous cycle's ``PipelineResult.memory`` for the same filter;
    ``loop_delay_s`` the loop delay tau of DESIGN 9 when known (``cbf``'s margin grows with it).
    """
    profile = config.profile
    obstacles = obstacle_points(points)
    pts = obstacles.xy
    name = config.filter if filter_name is None else filter_name
    shared = mode == "shared" and name != "none"
    family: FilterResult | None = None
    v, w = v_ref_mps, w_ref_radps
    escape = False
    if shared:
        if name == "egc":  # the default filter reads only these (and keeps no memory)
            family = run_egc(v_ref_mps, w_ref_radps, obstacles, config.settings)
        else:
            state = RobotState(*previous_cmd) if previous_cmd is not None else RobotState()
            inp = FilterInput(
                v_ref_mps, w_ref_radps, obstacles, state, goal_xy_m, now_ns, loop_delay_s
            )
            family = run_filter(name, inp, config.settings, memory)
        v, w = family.v_mps, family.w_radps
        if family.stopped_near_obstacle and increases_clearance(
            v_ref_mps, w_ref_radps, _CLEARANCE_HORIZON_S, pts, profile
        ):
            v, w, escape = v_ref_mps, w_ref_radps, True  # DESIGN 5.10: no dead-lock

    after_filter = (v, w)
    v, w = limit_velocity(v, w, profile)
    if previous_cmd is not None:
        v, w = limit_acceleration(v, w, previous_cmd, dt_s, profile)
    limited = abs(v - after_filter[0]) > _SAME or abs(w - after_filter[1]) > _SAME

    scale = 1.0
    if shared:
        scale = min(
            sweep_scale(v, w, obstacles, profile, config.sweep),
            horizon_scale(v, w, obstacles, profile, config.sweep),
        )
    if scale < 1.0:
        v, w = scale * v, scale * w
        if previous_cmd is not None and not reachable(v, w, previous_cmd, dt_s, profile):
            # More braking than the base can do: it would still be faster than the sweep
            # assumed. Brake as hard as it can on the arc the previous cycle checked.
            v, w = brake_along(previous_cmd, dt_s, profile)
        limiter = Limiter.SWEEP
    elif (
        family is not None
        and not escape
        and (abs(after_filter[0] - v_ref_mps) > _SAME or abs(after_filter[1] - w_ref_radps) > _SAME)
    ):
        limiter = _LIMITER_OF_FILTER[family.name]
    elif limited:
        limiter = Limiter.LIMITS
    else:
        limiter = Limiter.NONE
    return PipelineResult(v_ref_mps, w_ref_radps, v, w, limiter, family, scale, escape)


def step_command(
    config: PipelineConfig,
    x_o: float,
    y_o: float,
    mode: str,
    points: npt.ArrayLike | ObstaclePoints,
    previous_cmd: tuple[float, float],
    dt_s: float,
    *,
    filter_name: str | None = None,
    goal_xy_m: tuple[float, float] | None = None,
    now_ns: int = 0,
    memory: object | None = None,
    loop_delay_s: float | None = None,
) -> PipelineResult:
    """One cycle from normalised stick deflection (x_o forward, y_o left) to the base command."""
    p = config.profile
    v_ref, w_ref = deflection_to_velocity(x_o, y_o, p.v_max_mps, p.w_max_radps, config.mapping)
    return filter_velocity(
        config,
        v_ref,
        w_ref,
        mode,
        points,
        previous_cmd,
        dt_s,
        filter_name=filter_name,
        goal_xy_m=goal_xy_m,
        now_ns=now_ns,
        memory=memory,
        loop_delay_s=loop_delay_s,
    )
