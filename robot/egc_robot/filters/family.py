"""The filter family behind one interface (DESIGN 6, pinned names).

Every filter is called the same way, ``run_filter(name, FilterInput, settings, memory)``, and
answers with a ``FilterResult``: the command after the filter, what it changed and why, the
intermediates the view and the tests need, and the memory it wants back next cycle (only
``assist`` keeps any; the others are memoryless). The command pipeline (``pipeline``) applies
the rules common to all of them afterwards: the no-dead-lock rule and profile limits of
DESIGN 5.10, the footprint sweep, and (in the controller) the latency governor of DESIGN 9.

Inputs, all in the robot frame {R} and SI units: the operator's command after eq. 4, the scan's
obstacle points, the robot's current velocity, the active via point (or None), the time
(monotonic ns, passed in; never read here) and the loop delay tau of DESIGN 9 when the caller
knows it (``cbf``'s margin grows with it).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Final

from egc_common.messages import FILTER_NAMES
from egc_common.profiles import RobotProfile
from egc_common.scan import ObstaclePoints

from egc_robot.filters.assist import AssistMemory, AssistParams, assist_step
from egc_robot.filters.cbf import CbfParams, cbf_filter
from egc_robot.filters.dwa import DwaCase, DwaParams, dwa_filter
from egc_robot.filters.egc import EgcCase, EgcParams, EgcResult, Region, Side, egc_filter
from egc_robot.filters.ek_egc import ek_egc_filter

FILTERS: Final = FILTER_NAMES  # ("none", "egc", "ek-egc", "assist", "dwa", "cbf")
# Filtered modes an operator cycles through at run time, in this order.
SHARED_FILTERS: Final = tuple(name for name in FILTERS if name != "none")

# EGC's branches in which the paper's equations stopped the robot for being close to something.
_EGC_STOPPED_NEAR_OBSTACLE: Final = (
    EgcCase.EXPANDED,
    EgcCase.NO_INTERSECTION,
    EgcCase.ZERO_WEIGHTS,
)
_SAME: Final = 1e-9


@dataclass(frozen=True, slots=True)
class RobotState:
    """What the robot knows about its own motion: the velocity the base was last sent."""

    v_mps: float = 0.0
    w_radps: float = 0.0


@dataclass(frozen=True, slots=True)
class FilterInput:
    """One cycle's inputs to any filter of the family (DESIGN 6), all in {R}."""

    v_ref_mps: float
    w_ref_radps: float
    obstacles: ObstaclePoints
    state: RobotState = field(default_factory=RobotState)
    goal_xy_m: tuple[float, float] | None = None  # active via point in {R}
    now_ns: int = 0
    loop_delay_s: float | None = None  # tau (DESIGN 9); None: unknown (cbf takes its default)


@dataclass(frozen=True, slots=True)
class FilterResult:
    """A filter's answer: the command, what changed and why, and its intermediates."""

    name: str
    v_mps: float
    w_radps: float
    modified: bool
    reason: str  # which branch or rule decided, in a word or two (for the view and tests)
    w_si: float = 1.0
    region: Region = Region.SAFE
    side: Side | None = None
    # True when the filter stopped a moving command because something is close: the pipeline's
    # no-dead-lock rule (DESIGN 5.10) may then let a command that increases clearance through.
    stopped_near_obstacle: bool = False
    egc: EgcResult | None = None  # egc / ek-egc intermediates (ek-egc: in EK coordinates)
    detail: object | None = None  # the filter's own result type (DWA, assist)
    suggested_rad: float | None = None  # direction the filter suggests in {R} (assist)
    memory: object | None = None  # handed back on the next cycle


@dataclass(frozen=True, slots=True)
class FilterSettings:
    """Parameters of every filter, built once from the profile and the robot's config.

    ``dwa``, ``assist`` and ``cbf`` default to their ``from_profile`` parameters (with the
    driver's "no return is free" declaration of ``egc``); the robot TOML's ``[dwa]``,
    ``[assist]`` and ``[cbf]`` tables override them.
    """

    profile: RobotProfile
    egc: EgcParams
    dwa: DwaParams | None = None
    assist: AssistParams | None = None
    cbf: CbfParams | None = None

    def __post_init__(self) -> None:
        free = self.egc.no_return_is_free
        if self.dwa is None:
            object.__setattr__(
                self, "dwa", DwaParams.from_profile(self.profile, no_return_is_free=free)
            )
        if self.assist is None:
            object.__setattr__(
                self, "assist", AssistParams.from_profile(self.profile, no_return_is_free=free)
            )
        if self.cbf is None:
            object.__setattr__(
                self, "cbf", CbfParams.from_profile(self.profile, no_return_is_free=free)
            )

    @property
    def ek_length_m(self) -> float:
        """L = v_max / w_max of the profile (DESIGN 6, ek-egc)."""
        return self.profile.v_max_mps / self.profile.w_max_radps


FilterFn = Callable[[FilterInput, FilterSettings, object | None], FilterResult]


def _changed(v: float, w: float, inp: FilterInput) -> bool:
    return abs(v - inp.v_ref_mps) > _SAME or abs(w - inp.w_ref_radps) > _SAME


def _from_egc(name: str, res: EgcResult) -> FilterResult:
    return FilterResult(
        name=name,
        v_mps=res.v_mps,
        w_radps=res.w_radps,
        modified=res.modified,
        reason=res.case.value,
        w_si=res.w_si,
        region=res.region,
        side=res.side,
        stopped_near_obstacle=res.case in _EGC_STOPPED_NEAR_OBSTACLE and res.w_si == 0.0,
        egc=res,
    )


def _run_none(inp: FilterInput, settings: FilterSettings, memory: object | None) -> FilterResult:
    return FilterResult("none", inp.v_ref_mps, inp.w_ref_radps, False, "direct")


def run_egc(
    v_ref_mps: float, w_ref_radps: float, obstacles: ObstaclePoints, settings: FilterSettings
) -> FilterResult:
    """``run_filter("egc", ...)`` from the only inputs EGC reads (the robot's command path
    calls it without building a ``FilterInput``)."""
    return _from_egc("egc", egc_filter(v_ref_mps, w_ref_radps, obstacles, settings.egc))


def _run_egc(inp: FilterInput, settings: FilterSettings, memory: object | None) -> FilterResult:
    return run_egc(inp.v_ref_mps, inp.w_ref_radps, inp.obstacles, settings)


def _run_ek_egc(inp: FilterInput, settings: FilterSettings, memory: object | None) -> FilterResult:
    res = ek_egc_filter(
        inp.v_ref_mps, inp.w_ref_radps, inp.obstacles, settings.egc, settings.ek_length_m
    )
    return _from_egc("ek-egc", res)


def _run_dwa(inp: FilterInput, settings: FilterSettings, memory: object | None) -> FilterResult:
    assert settings.dwa is not None
    res = dwa_filter(
        inp.v_ref_mps,
        inp.w_ref_radps,
        inp.obstacles,
        inp.state.v_mps,
        inp.state.w_radps,
        inp.goal_xy_m,
        settings.profile,
        settings.dwa,
    )
    seen = res.case in (DwaCase.CHOSEN, DwaCase.NO_ADMISSIBLE)
    moving = abs(inp.v_ref_mps) > _SAME or abs(inp.w_ref_radps) > _SAME
    return FilterResult(
        name="dwa",
        v_mps=res.v_mps,
        w_radps=res.w_radps,
        modified=res.modified,
        reason=res.case.value,
        w_si=0.0 if res.stopped else 1.0,
        region=Region.UNSAFE if res.stopped else Region.SAFE,
        stopped_near_obstacle=res.stopped and seen and moving,
        detail=res,
    )


# Assist's rules that stop for lack of information, not because something is close.
_ASSIST_BLIND = ("invalid", "unknown", "idle")


def _run_assist(inp: FilterInput, settings: FilterSettings, memory: object | None) -> FilterResult:
    assert settings.assist is not None
    p = settings.profile
    mem = memory if isinstance(memory, AssistMemory) else AssistMemory.initial()
    # The stick, back from eq. 4 (the pipeline hands every filter the same velocity reference).
    x_o = inp.v_ref_mps / p.v_max_mps
    y_o = inp.w_ref_radps / p.w_max_radps
    res = assist_step(
        mem,
        x_o,
        y_o,
        inp.obstacles,
        inp.goal_xy_m,
        inp.now_ns,
        settings.assist,
        p,
        (inp.state.v_mps, inp.state.w_radps),
    )
    stopped = abs(res.v_mps) <= _SAME and abs(res.w_radps) <= _SAME
    moving = abs(inp.v_ref_mps) > _SAME or abs(inp.w_ref_radps) > _SAME
    return FilterResult(
        name="assist",
        v_mps=res.v_mps,
        w_radps=res.w_radps,
        modified=res.modified,
        reason=res.rule,
        w_si=0.0 if stopped and moving else 1.0,
        region=Region.UNSAFE if stopped and moving else Region.SAFE,
        stopped_near_obstacle=stopped and moving and res.rule not in _ASSIST_BLIND,
        detail=res,
        memory=res.memory,
        suggested_rad=res.heading_rad,
    )


def _run_cbf(inp: FilterInput, settings: FilterSettings, memory: object | None) -> FilterResult:
    assert settings.cbf is not None
    res = cbf_filter(
        inp.v_ref_mps,
        inp.w_ref_radps,
        inp.obstacles,
        inp.state.v_mps,
        inp.state.w_radps,
        inp.loop_delay_s,
        settings.profile,
        settings.cbf,
    )
    if not res.modified:  # DESIGN 13: unchanged, the operator's very values
        return FilterResult(
            "cbf", inp.v_ref_mps, inp.w_ref_radps, False, res.case.value, detail=res
        )
    stopped = res.v_mps == 0.0 and res.w_radps == 0.0
    moving = abs(inp.v_ref_mps) > _SAME or abs(inp.w_ref_radps) > _SAME
    return FilterResult(
        name="cbf",
        v_mps=res.v_mps,
        w_radps=res.w_radps,
        modified=True,
        reason=res.case.value,
        w_si=0.0 if stopped and moving else 1.0,
        region=Region.UNSAFE if stopped and moving else Region.CONDITIONAL,
        # Never: the barriers let every motion that approaches nothing through (DESIGN 13), so
        # the pipeline's escape rule, which looks at the end of a 1 s arc only, is not needed.
        stopped_near_obstacle=False,
        detail=res,
    )


_REGISTRY: dict[str, FilterFn] = {
    "none": _run_none,
    "egc": _run_egc,
    "ek-egc": _run_ek_egc,
    "assist": _run_assist,
    "dwa": _run_dwa,
    "cbf": _run_cbf,
}


def available_filters() -> tuple[str, ...]:
    """The filters this build runs, in DESIGN 6's order."""
    return tuple(name for name in FILTERS if name in _REGISTRY)


def run_filter(
    name: str, inp: FilterInput, settings: FilterSettings, memory: object | None = None
) -> FilterResult:
    """Run filter ``name`` of the family on one cycle's inputs."""
    try:
        fn = _REGISTRY[name]
    except KeyError:
        raise ValueError(f"unknown filter {name!r} (known: {', '.join(FILTERS)})") from None
    return fn(inp, settings, memory)


def invalid_input(name: str, inp: FilterInput) -> FilterResult | None:
    """A stop for a command that is not a number (DESIGN 5.9), or None when it is fine."""
    if math.isfinite(inp.v_ref_mps) and math.isfinite(inp.w_ref_radps):
        return None
    return FilterResult(name, 0.0, 0.0, True, "invalid_input", 0.0, Region.UNSAFE)
