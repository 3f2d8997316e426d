"""The rule-based assistant (``assist``, DESIGN 6) after ``rule-based-assist.txt``, as a pure step.

``assist_step(memory, x_o, y_o, obstacles, goal_xy_m, now_ns, params, profile)`` takes the
operator's normalised stick (DESIGN 4: x_o forward, y_o left, [-1, 1]), the scan points in {R},
the active via point in {R} (or None) and the monotonic time, and returns an ``AssistResult``:
the command (v, w), the name of the rule that fired, the suggested heading, the 3x3 activation
grid, the stick confidence, and the new ``AssistMemory`` to pass in next cycle. Nothing here
reads a clock or keeps hidden state; dt comes from the previous ``now_ns`` held in the memory.
The command pipeline applies the profile limits and the footprint sweep (DESIGN 5.10) after it.

How each part maps to the paper
-------------------------------
- **Obstacle histogram** (sec. II.B, "Histogramic In-Motion Mapping"): three sectors (LEFT,
  FRONT, RIGHT) x three distance bands (CLOSE, INTERMEDIATE, FARAWAY). The paper's two
  ultrasonic cones and their overlap become, for a scan: FRONT = the corridor the footprint
  sweeps driving straight ahead (x > 0, |y| <= ``corridor_half_width_m``), LEFT / RIGHT = the
  rest of the half-plane ahead (x > 0) on either side. A point's band is its distance from the
  origin of {R}: CLOSE up to ``close_m``, INTERMEDIATE up to ``intermediate_m``, FARAWAY up to
  ``faraway_m``; farther points are ignored. Each cycle a cell holding at least one point gains
  ``hit_increment`` (6) up to ``hit_max`` (16), every other cell loses ``miss_decrement`` (2)
  down to 0; a cell is *active* when its count is above ``activation_threshold`` (so a single
  stray reading never activates one). As in the paper these are per-cycle counts. A sector's
  level is its nearest active band (LeftO, FrontO, RightO of Fig. 5).
  Band edges from the profile (``AssistParams.from_profile``): CLOSE = r_max (the outer circle of
  the safety index, d_robot + d_safe), INTERMEDIATE = r_max + L, FARAWAY = r_max + 2 L, with L the
  footprint length; the FRONT corridor's half width is 0.75 W (the footprint plus a margin).
  Deviation (issue 11): d_safe is the distance covered in 1 s at v_max (DESIGN 3), so the bands
  are those of a robot at full speed. Each cycle they are shrunk to the robot's current speed
  (``at_speed``, from the velocity last sent): d_safe(v) = max(0.14 m, d_safe |v| / v_max), and
  every distance built on d_safe (the bands, the wall distances, ``block_m``, ``leave_clear_m``)
  moves by the same amount. For the Pioneer (d_safe 0.14 m) nothing changes. For the Jackal
  (d_safe 2 m) the full bands reach 2.5-3.5 m, so in a 7 x 4.5 m room everything was CLOSE
  and the blind operator with ``assist`` reached 0 of 100 random worlds; with the bands at its
  speed it slows where it is cluttered, the bands shrink, and it gets through (numbers in
  ``docs/assist.md``).
- **Joystick in polar form** (sec. II.C, eq. 1): J = min(sqrt(x_o^2 + y_o^2), 1), angle
  phi = atan2(y_o, x_o). **Confidence histogram** (JoystickArray): ``confidence_bins`` cells over
  the stick angle; the occupied cell builds at 1 / ``confidence_build_s`` per second (full in
  about 0.5 s), the others decay at 1 / ``confidence_decay_s`` per second (empty in about 150 ms);
  a centred stick (J below ``stick_deadzone``) occupies none. Rates are per second, so the
  behaviour does not depend on the control rate.
- **Direction to the via point** (sec. IV, Fig. 5's ``Target`` input): beta = atan2(y_g, x_g) of
  the via point in {R}, and its distance.
- **Revised rule set** (sec. IV, Fig. 5, rules 1-7 of cases 1-3): the paper's rules give a change
  of steering angle from (Joystick, LeftO, FrontO, RightO, TargetAngle). Its tables are partial
  (the comparison symbols were lost in extraction), so we keep their structure as general rules
  over a desired heading theta in {R}:
  * a side obstacle at INTERMEDIATE forbids turning towards it (cases 1 and 2: with the target on
    the obstacle's side, "change 0" or a small turn away): theta <= 0 for LEFT, theta >= 0 for
    RIGHT (``side_intermediate_rad`` = 0); at CLOSE the heading must turn away by at least
    ``side_close_rad`` (rules ``avoid-left`` / ``avoid-right``);
  * both sides CLOSE and the front clear (case 3, rules 5-7: a gap, steer gently towards the
    target, 15-25 deg): theta clamped to +-``gap_max_rad``, speed ``gap_speed`` (rule ``gap``);
  * FRONT active (the initial rule set of Fig. 4, sec. V "turned away"): at INTERMEDIATE the
    heading turns by at least ``front_turn_rad`` towards the more open side and slows to
    ``front_intermediate_speed``; at CLOSE it turns in place (rule ``avoid-front``), and keeps
    turning the same way while it does (the memory's ``front_turn``: in a corner the more open
    side swaps as the robot turns, and re-choosing every cycle rocks it in place for ever).
  The robot then turns with w = clamp(``heading_gain_per_s`` * theta, +-w_max) and drives with
  v = m v_max s max(cos theta, 0): m is the stick's magnitude J with a via point (sec. II.C: J
  "showed how fast an operator wanted the robot to go") and its forward deflection x_o without
  one, s the speed factor of the rule.
- **Heading sources** (sec. V): with a via point and the stick roughly in line with it (within
  ``align_tolerance_rad``, both angles clipped to +-90 deg, so "turn towards it" counts as in
  line), the rules "sent it towards the target destination" (rule ``goal``). Deviation (issue
  11): when not wall following, ``goal`` steers straight at the via point, past the obstacle
  rules, whenever FRONT is not CLOSE, the footprint's way towards it (``way_half_width_m``) is
  clear for ``block_m`` (even when the via point is nearer: the robot has to stop past it) and no
  single side is CLOSE on the via point's side (both CLOSE is a corridor).
  The bands are distances from the robot's centre, so in a 1 m corridor both sides are CLOSE
  all the time and FRONT turns active at every bend: the rules (``gap``'s +-15 deg,
  ``avoid-front``'s turn in place) then fought the via point at every corner, and the blind
  operator reached none of the MRPB tests. The pipeline's footprint sweep still guards the
  command. With a via point
  and the stick elsewhere, "an average between the angle to the target destination and the angle
  requested by the joystick" (rule ``blend``); without a via point the heading is the one whose
  turn rate is the stick's eq. 4 turn rate (theta = w_ref / gain), so with nothing active the
  stick passes unchanged (rule ``free``): joystick plus avoidance.
- **Detour** (deviation, issue 11): when heading for the via point (rule ``goal``) with FRONT
  active at CLOSE or INTERMEDIATE and the corridor towards the via point blocked within
  ``block_m``, the robot first looks for the heading nearest the via point, within
  ``detour_max_rad`` (90 deg) either side in ``detour_step_rad`` steps, whose way is clear for
  ``block_m`` at ``detour_half_width_m`` (the footprint's width W: half a width of margin either
  side, so the sweep does not stop it beside the obstacle) and steers there (rule ``detour``;
  a tie keeps the side of the last detour, so the robot does not swap sides in front of a
  symmetric obstacle). Every cycle starts again from the via point, so the robot turns back to
  it as soon as its way is clear. Only when no such heading exists (a pocket, a wall across
  everything ahead) does wall following begin. On the seeded random worlds these changes were
  tried on (pioneer3dx, `goal` operator, seeds 0-399 and 1000-1099): 447/500 reached with
  detours and the retreat limit below, 408/500 without; no contact either way. The tangent
  follower alone wandered round obstacle clusters and along the room's walls until the time ran
  out. ``detour_max_rad`` = 0 turns detours off.
- **Narrow detour** (deviation, issue 28): in dense clutter whose gaps are 1.2-1.5 x the
  footprint's width W no heading has the comfortable way above (2 W wide), and the robot
  wall-followed round the first obstacles for the whole episode (Jackal, ``goal`` operator,
  via point at the goal: 0 of 30 ``clutter`` worlds). The detour also considers the headings,
  ``squeeze_step_rad`` (1 deg) apart within ``detour_max_rad``, whose way is clear for
  ``block_m`` at ``squeeze_half_width_m`` (W / 2 + the footprint sweep's 3 cm margin: the
  narrowest way the sweep lets through); of their runs it takes the one nearest the via point
  and aims half its width (at most ``squeeze_centre_max_rad``) past its near edge, so through
  the middle of a narrow gap. The narrow way is taken only when it is nearer the via point
  than the comfortable one. A straight strip is a conservative test of an oblique gap: a gap g
  crossed at angle a is only g cos(a) wide. Measured (``docs/assist.md``, notes): Jackal
  ``clutter:0-29`` 0/30 -> 5/30 (5 of the 9 cylinder fields, none of the 21 baffle worlds),
  ``random:1000-1029`` 26/30 -> 27/30, 0 collisions. ``squeeze_step_rad`` = 0 turns it off.
- **Local planner** (deviation, issue 28; ``local_plan``): the narrow detour above picks a
  heading from the current scan, so it entered a 1.2 x W gap at an angle (4 cm a side against
  the sweep's 3 cm margin) and had no room to turn in place inside a column: 5 of 30
  ``clutter`` worlds. With a via point (and ``plan_cell_m`` > 0) the assistant now plans on
  the scan every cycle and the planner only replaces the *target's direction*: a grid in {R}
  (``plan_window_m`` either side, ``plan_cell_m`` cells), a cell traversable when its
  clearance is at least ``plan_clearance_min_m`` (W / 2 + 1 cm), cells nearer than
  ``plan_clearance_pref_m`` dearer (cost ~ 1 / clearance), cells no beam crossed
  ``plan_unknown_cost`` dearer, Dijkstra from the robot to the via point (or, when it lies
  outside the window, out through the window's rim towards it). The rules steer at the path's
  look-ahead point, or, when the path crosses a gap too narrow to turn in (clearance below
  ``plan_narrow_m``, the footprint's reach + the sweep's margin), first at the gap's entry
  point on its axis (where there is room to turn) and then along the axis through its middle
  (``local_plan``'s docstring). With the stick in line with the via point (rule ``plan``)
  the robot turns in place towards that point when it is more than ``plan_turn_rad`` off and
  there is room (a slow arc when not), and drives no faster than ``plan_slow_per_s`` x the
  path's clearance beyond half the width (at least ``plan_speed_min_mps``), never faster than
  the stick asks; with the stick elsewhere the paper's blend averages the stick with the
  planned direction (rule ``blend`` and the obstacle rules as before), and the override is
  untouched. The plan replaces ``goal``, ``detour`` and wall following while it finds a way;
  when the robot's own cell is not traversable (nothing to plan from) those rules decide as
  before. The memory keeps the last path (``plan_path``, every second cell), moved into this
  cycle's {R} by the velocity last sent, and cells along it cost ``keep_cost`` (0.7) times as
  much: without it the robot rocked between two gaps of about the same cost. The pipeline's
  footprint sweep still has the last word. Measured (``docs/assist.md``): Jackal, ``goal``
  operator, via point at the goal, ``clutter:0-29`` 5/30 -> 27/30, held-out
  ``clutter:13000-13039`` 39/40, ``random:1000-1029`` 27/30 -> 29/30, 0 collisions; about
  3 ms a step (``bench/bench_assist_plan.py``). ``plan_cell_m`` = 0 turns the planner off.
- **Wall following** (sec. V: "an obstacle in front while moving toward a target destination ...
  rotate to align with and then move parallel to the wall"). Entered when heading for the via
  point (rule ``goal``) with FRONT active at CLOSE or INTERMEDIATE, the corridor towards the via
  point blocked within ``block_m`` and no detour. The side is the one on which a free corridor
  opens nearest to the via point's direction (a tangent-bug choice; the side just used is kept for
  ``rejoin_s`` so the robot does not swap sides around one obstacle). The paper gives no formula;
  ours is a tangent follower: with m the nearest scan point on the wall's side (or ahead) within
  ``wall_range_m``, at angle alpha and distance d, theta = alpha -+ pi/2 (parallel to the wall),
  corrected by ``wall_gain_rad_per_m`` (``wall_distance_m`` - d) away from it; no such point (a
  corner passed) -> turn towards the wall side by ``wall_lost_turn_rad`` at
  ``front_intermediate_speed``. With FRONT CLOSE and a turn of at least ``front_turn_rad`` it
  turns in place (a sharp arc in a tight spot is what the sweep stops, for good). Rule
  ``wall-follow-right`` keeps the wall on the robot's right, ``wall-follow-left`` on its left.
  Left when the corridor towards the via point is clear for min(distance, ``leave_clear_m``) and
  the robot is at least ``progress_m`` closer to it than where it started following (Bug2's leave
  condition, so it never leaves into the obstacle it is going round), or the via point is itself
  within ``leave_clear_m`` (the clear corridor reaches it). Entry and leave check the way to the
  via point at the footprint's width plus 5 cm (``way_half_width_m``), not the FRONT sector's 0.75
  W: MRPB's corridors are about 1 m wide and the route keeps the robot's centre only 0.29 m off
  the walls, so the wider strip saw walls beside the route as "blocked". After ``wall_max_s`` of
  following without getting closer than where it began, or as soon as the via point is
  ``wall_retreat_m`` (the footprint's length) farther than where it began, it gives up and the
  next entry takes the other side (issue 11: in a pocket with the via point behind its wall the
  tangent follower went round the pocket for ever, and a follower that reached the room's wall
  followed it away from the via point).
- **Unblocking** (deviation, issue 11): the footprint sweep after the rules may refuse their
  command outright (a turn in place that would swing a corner into a box beside the robot).
  Rules that do not know it ask for the same motion for ever: the robot stalled. The pipeline
  hands the assistant the (v, w) the base was last sent; when the rules asked for motion and
  (almost) none was sent for ``unblock_after_s``, rule ``unblock`` escapes: ahead at
  min(``unblock_speed``, m) of v_max, m the speed the stick asks for (as for the rules above:
  no rule drives faster than the operator's stick, since the assistant bends or slows the
  command, never speeds it up); if the sweep refuses that too, a turn in place away from the
  turn the rules wanted; then back at that speed. A stick asking for no speed (a pure turn
  without a via point) escapes by turning only. (Before 2026-11-24 the escape went at
  ``unblock_speed`` whatever the stick asked: a replay recorded at 0.1 m/s on the Jackal sent
  0.5 m/s in 240 of 2,999 scans.) A try that moves the base runs for
  ``unblock_try_s`` and hands back to the rules; the sweep judges every try. Blocked again
  within ``unblock_repeat_s`` of an escape (the rules steered straight back into the wedge), the
  next escape starts with the try after the one that freed it, so a wedge is not escaped the
  same way for ever. On the Jackal's random worlds (seeds 0-99) the blind operator went from 27
  stalls to 76/100 reached with the escapes, and to 83/100 with the escalation.
- **Operator's override** (sec. V: "if the joystick remained fixed (roughly) in a particular
  position then that input was integrated over time and the wishes of the tele-operator overrode
  that behaviour"; avoidance "initially overrode other behaviours"): the memory integrates, like
  the confidence histogram (same build and decay rates), the time the stick has been held in one
  cell *while the rules change the command* and the stick is not in line with the via point.
  Once that reaches ``override_confidence`` the stick's own eq. 4 command goes out (rule
  ``override``). The pipeline's footprint sweep still keeps the robot off obstacles. An override
  the sweep has held still for ``override_yield_s`` is spent: the rules (and ``unblock``) drive
  again until the stick moves to another cell or is centred. (Not in the paper, whose override
  never met a robot it could not move: without it, a stick held steady at a wall stalls there
  for good and the via points are never reached.)

Rules (names reported in ``AssistResult.rule``), in the order they are tried
-----------------------------------------------------------------------------
``invalid`` (NaN / infinite stick or via point: stop), ``unknown`` (no scan point and the sensor
does not declare no-return as free, DESIGN 5.9 NO_POINTS_UNKNOWN: nothing seen is not free: stop),
``idle`` (stick centred: stop), ``reverse`` (x_o < 0: the stick's eq. 4 command; the rules look
ahead only, the sweep guards the reverse), ``override``, ``plan``, ``wall-follow-left`` /
``wall-follow-right``, ``detour``, ``avoid-front``, ``gap``, ``avoid-left`` / ``avoid-right``,
and with nothing active ``goal``, ``blend`` or ``free``; then ``unblock`` in place of any of
them that the base was refused.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np
import numpy.typing as npt
from egc_common.profiles import RobotProfile
from egc_common.scan import ObstaclePoints, obstacle_points

from egc_robot.filters.local_plan import LocalPlan, PlanSettings, moved_path, plan_target

FloatArray = npt.NDArray[np.float64]

# Sectors and bands of the 3x3 histogram: grid[sector][band].
LEFT, FRONT, RIGHT = 0, 1, 2
CLOSE, INTERMEDIATE, FARAWAY = 0, 1, 2
SECTORS = ("left", "front", "right")
BANDS = ("close", "intermediate", "faraway")

RULES = (
    "invalid",
    "unknown",
    "idle",
    "reverse",
    "override",
    "wall-follow-left",
    "wall-follow-right",
    "detour",
    "avoid-front",
    "gap",
    "avoid-left",
    "avoid-right",
    "unblock",
    "plan",
    "goal",
    "blend",
    "free",
)

_SAME = 1e-9
_KEEP_EVERY = 2  # the memory keeps every second cell of the path (``plan_keep_cost``)
_SWEEP_MARGIN_M = 0.03  # the footprint sweep's margin (safety.SweepParams.margin_m)
_PIONEER_REACH_M = math.hypot(0.2275, 0.1905)  # the Pioneer's half diagonal (DESIGN 3)
_HALF_PI = 0.5 * math.pi
Grid = tuple[tuple[int, int, int], tuple[int, int, int], tuple[int, int, int]]
BoolGrid = tuple[tuple[bool, bool, bool], tuple[bool, bool, bool], tuple[bool, bool, bool]]
_ZERO_GRID: Grid = ((0, 0, 0), (0, 0, 0), (0, 0, 0))


@dataclass(frozen=True, slots=True)
class AssistParams:
    """Every setting of the assistant, with its unit. Defaults are the Pioneer 3-DX's
    (``from_profile(PIONEER3DX)``); ``from_mapping`` reads the robot TOML's ``[assist]``."""

    # Histogram bands (m, from the origin of {R}) and the FRONT corridor's half width (m).
    close_m: float = 0.595
    intermediate_m: float = 1.05
    faraway_m: float = 1.505
    corridor_half_width_m: float = 0.28575
    # Histogram counts (per control cycle, paper sec. II.B).
    hit_increment: int = 6
    hit_max: int = 16
    miss_decrement: int = 2
    activation_threshold: int = 6
    # Joystick: centred below this magnitude (1), confidence cells, build/decay times (s).
    stick_deadzone: float = 0.05
    confidence_bins: int = 12
    confidence_build_s: float = 0.5
    confidence_decay_s: float = 0.15
    override_confidence: float = 0.9  # (1) steady-against-the-rules level for the override
    # The override stopped by the sweep this long (s): it yields to the rules until the stick
    # moves to another cell or is centred (a steady stick into a wall otherwise stalls for ever).
    override_yield_s: float = 1.0
    align_tolerance_rad: float = math.radians(45.0)
    # Steering: w = gain * heading (1/s); the rules' angles (rad) and speed factors (1).
    heading_gain_per_s: float = 1.5
    side_close_rad: float = math.radians(20.0)
    side_intermediate_rad: float = 0.0
    gap_max_rad: float = math.radians(15.0)
    gap_speed: float = 0.6
    front_turn_rad: float = math.radians(45.0)
    front_intermediate_speed: float = 0.5
    # Wall following (m, rad, rad/m, s).
    wall_distance_m: float = 0.525
    wall_range_m: float = 1.05
    wall_gain_rad_per_m: float = 2.0
    wall_correction_max_rad: float = math.radians(60.0)
    wall_lost_turn_rad: float = math.radians(60.0)
    block_m: float = 1.05
    leave_clear_m: float = 1.505
    progress_m: float = 0.05
    rejoin_s: float = 5.0
    wall_max_s: float = 30.0
    # Wall following gives up when the via point is this much farther (m) than where it began:
    # the wall leads away (a room's wall is followed for ever otherwise).
    wall_retreat_m: float = 0.455
    # Unblocking (rule ``unblock``): after ``unblock_after_s`` of asking for motion while the
    # base was sent none (the sweep refused it), try in turn ahead at ``unblock_speed`` of
    # v_max (or the stick's own speed, if that is less), a turn in place the other way, back
    # at that speed; each try runs for
    # ``unblock_try_s`` once the base moves, the next one when the sweep refuses it too.
    unblock_after_s: float = 0.25
    unblock_try_s: float = 0.5
    unblock_speed: float = 0.25
    unblock_repeat_s: float = 2.0  # blocked again within this after an escape: the next try
    unblock_below: float = 0.1  # (1) "none sent": less than this share of the motion asked for
    # The floor (m) of d_safe scaled to the current speed (``at_speed``): the paper's Pioneer's
    # d_safe, so a robot that slow or slower keeps the profile's bands.
    d_safe_min_m: float = 0.14
    # Detour (rule ``detour``): the free heading nearest the via point, searched this far (rad)
    # either side of it in steps of ``detour_step_rad`` (0: no detours).
    detour_max_rad: float = math.radians(90.0)
    detour_step_rad: float = math.radians(5.0)
    # Half width (m) of the way a detour must find clear: the footprint's width W, so half a
    # width of margin either side (a detour that grazes obstacles ends where the sweep stops it).
    detour_half_width_m: float = 0.381
    # Half width (m) of the way to the via point that wall following checks (entry, leave).
    way_half_width_m: float = 0.2405
    # Narrow detour, when no heading has the comfortable way above (dense clutter): headings
    # ``squeeze_step_rad`` apart whose way is clear at ``squeeze_half_width_m`` (half the
    # footprint's width + the footprint sweep's 3 cm margin: the narrowest way the sweep lets
    # through); steer into the clear run nearest the via point, by up to half its width
    # but at most ``squeeze_centre_max_rad`` past its near edge (0 step: no narrow detours).
    squeeze_half_width_m: float = 0.2205
    squeeze_step_rad: float = math.radians(1.0)
    squeeze_centre_max_rad: float = math.radians(10.0)
    # Local planner (rule ``plan``, module docstring; ``local_plan``): grid cell and half
    # window (m; 0 cell: no planner), traversable clearance (half the width + 1 cm), the
    # clearance above which a cell costs nothing extra, the cost weights (1), the clearance
    # below which the footprint cannot turn in place (a gap), how far ahead gaps are looked
    # for, the look-ahead on the path and along a gap's axis, where a gap's entry point may
    # lie before its middle and how near counts as there (m).
    plan_cell_m: float = 0.06
    plan_window_m: float = 2.5
    plan_clearance_min_m: float = 0.2005
    plan_clearance_pref_m: float = _PIONEER_REACH_M + _SWEEP_MARGIN_M + 0.1
    plan_clearance_weight: float = 3.0
    plan_unknown_cost: float = 1.5
    plan_heuristic_weight: float = 3.0
    plan_narrow_m: float = _PIONEER_REACH_M + _SWEEP_MARGIN_M
    plan_horizon_m: float = 1.5
    plan_lookahead_m: float = 0.5
    plan_axis_lookahead_m: float = 0.3
    plan_approach_min_m: float = 0.3
    plan_approach_max_m: float = 0.7
    plan_entry_tolerance_m: float = 0.06
    # Following the plan: turn in place above this heading error (rad); speed at most
    # ``plan_slow_per_s`` x (the path's clearance ahead - half the width), never below
    # ``plan_speed_min_mps`` (m/s) unless the stick asks for less.
    plan_turn_rad: float = math.radians(30.0)
    plan_align_rad: float = math.radians(10.0)  # the same along a gap's axis, with room
    plan_slow_per_s: float = 3.0
    plan_speed_min_mps: float = 0.15
    # A via point closer than this (m) gives no direction: joystick plus avoidance.
    goal_min_m: float = 0.05
    # dt larger than this (s) counts as this (a resumed link does not jump the confidence).
    max_dt_s: float = 0.25
    # The sensor declares "no return within range" as free (DESIGN 5.9).
    no_return_is_free: bool = False

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if f.type in ("bool", bool):
                if not isinstance(value, bool):
                    raise ValueError(f"assist.{f.name} must be true or false, got {value!r}")
                continue
            if f.type in ("int", int):
                if isinstance(value, bool) or not isinstance(value, int):
                    raise ValueError(f"assist.{f.name} must be an integer, got {value!r}")
            elif isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ValueError(f"assist.{f.name} must be a number, got {value!r}")
            if not math.isfinite(value) or value < 0:
                raise ValueError(f"assist.{f.name} must be finite and >= 0, got {value!r}")
        if not 0.0 < self.close_m < self.intermediate_m < self.faraway_m:
            raise ValueError("assist needs 0 < close_m < intermediate_m < faraway_m")
        positive = (
            "corridor_half_width_m",
            "hit_increment",
            "hit_max",
            "confidence_bins",
            "confidence_build_s",
            "confidence_decay_s",
            "heading_gain_per_s",
            "wall_distance_m",
            "wall_range_m",
            "block_m",
            "leave_clear_m",
            "wall_max_s",
            "detour_step_rad",
            "unblock_try_s",
            "override_yield_s",
            "way_half_width_m",
            "max_dt_s",
        )
        for name in positive:
            if getattr(self, name) <= 0:
                raise ValueError(f"assist.{name} must be positive")
        if self.plan_cell_m > 0.0:
            if not 0.0 < self.plan_clearance_min_m < self.plan_clearance_pref_m:
                raise ValueError("assist needs 0 < plan_clearance_min_m < plan_clearance_pref_m")
            if self.plan_window_m < 2.0 * self.plan_cell_m:
                raise ValueError("assist.plan_window_m must be at least two plan cells")
            if self.plan_unknown_cost < 1.0:
                raise ValueError("assist.plan_unknown_cost must be at least 1")
            if self.plan_approach_min_m > self.plan_approach_max_m:
                raise ValueError("assist needs plan_approach_min_m <= plan_approach_max_m")
        if self.activation_threshold >= self.hit_max:
            raise ValueError("assist.activation_threshold must be below hit_max")
        if not 0.0 < self.override_confidence <= 1.0:
            raise ValueError("assist.override_confidence must be in (0, 1]")
        if self.stick_deadzone >= 1.0:
            raise ValueError("assist.stick_deadzone must be below 1")
        for name in ("gap_speed", "front_intermediate_speed", "unblock_speed", "unblock_below"):
            if getattr(self, name) > 1.0:
                raise ValueError(f"assist.{name} must be in [0, 1]")
        for name in (
            "align_tolerance_rad",
            "side_close_rad",
            "side_intermediate_rad",
            "gap_max_rad",
            "front_turn_rad",
            "wall_correction_max_rad",
            "wall_lost_turn_rad",
            "squeeze_step_rad",
            "squeeze_centre_max_rad",
            "plan_turn_rad",
            "plan_align_rad",
        ):
            if getattr(self, name) > math.pi:
                raise ValueError(f"assist.{name} must be in [0, pi]")

    @staticmethod
    def from_profile(profile: RobotProfile, **overrides: Any) -> AssistParams:
        """Bands and distances derived from the profile (module docstring), other defaults."""
        r_max, length = profile.r_max_m, profile.length_m
        derived: dict[str, Any] = {
            "close_m": r_max,
            "intermediate_m": r_max + length,
            "faraway_m": r_max + 2.0 * length,
            "corridor_half_width_m": 0.75 * profile.width_m,
            "way_half_width_m": 0.5 * profile.width_m + 0.05,
            "squeeze_half_width_m": 0.5 * profile.width_m + 0.03,
            "wall_distance_m": 0.5 * (profile.r_min_m + r_max),
            "wall_range_m": r_max + length,
            "block_m": r_max + length,
            "leave_clear_m": r_max + 2.0 * length,
            "detour_half_width_m": profile.width_m,
            "wall_retreat_m": length,
            "plan_clearance_min_m": 0.5 * profile.width_m + 0.01,
            "plan_narrow_m": profile.half_diagonal_m + _SWEEP_MARGIN_M,
            "plan_clearance_pref_m": profile.half_diagonal_m + _SWEEP_MARGIN_M + 0.1,
        }
        derived.update(overrides)
        return AssistParams(**derived)

    def plan_settings(self) -> PlanSettings:
        """The local planner's settings (``plan_*``)."""
        return PlanSettings(
            cell_m=self.plan_cell_m,
            window_m=self.plan_window_m,
            clearance_min_m=self.plan_clearance_min_m,
            clearance_pref_m=self.plan_clearance_pref_m,
            clearance_weight=self.plan_clearance_weight,
            unknown_cost=self.plan_unknown_cost,
            heuristic_weight=self.plan_heuristic_weight,
            narrow_m=self.plan_narrow_m,
            horizon_m=self.plan_horizon_m,
            lookahead_m=self.plan_lookahead_m,
            axis_lookahead_m=self.plan_axis_lookahead_m,
            approach_min_m=self.plan_approach_min_m,
            approach_max_m=self.plan_approach_max_m,
            entry_tolerance_m=self.plan_entry_tolerance_m,
        )

    @staticmethod
    def from_mapping(
        mapping: Mapping[str, Any], profile: RobotProfile | None = None
    ) -> AssistParams:
        """The robot TOML's ``[assist]`` table over the profile's (or the default) params.

        Unknown keys, wrong types and out-of-range values raise ValueError naming the key.
        """
        if not isinstance(mapping, Mapping):
            raise ValueError("[assist] must be a table")
        known = {f.name: f.type for f in fields(AssistParams)}
        unknown = sorted(set(mapping) - set(known))
        if unknown:
            raise ValueError(
                f"[assist] has unknown keys: {', '.join(map(str, unknown))} "
                f"(known: {', '.join(sorted(known))})"
            )
        values: dict[str, Any] = {}
        for key, value in mapping.items():
            kind = known[key]
            if kind in ("float", float) and isinstance(value, int) and not isinstance(value, bool):
                value = float(value)
            values[key] = value
        base = AssistParams() if profile is None else AssistParams.from_profile(profile)
        return replace(base, **values)


@dataclass(frozen=True, slots=True)
class AssistMemory:
    """Everything the assistant carries from one cycle to the next (all explicit).

    ``counts``: the 3x3 obstacle histogram [sector][band]; ``confidence``: the joystick
    confidence histogram (one value in [0, 1] per angle cell; empty until the first step);
    ``stick_cell``: the cell the stick occupied last cycle (None: centred); ``contest``: how long
    (as a fraction of ``confidence_build_s``) the stick has been held in that cell against the
    rules; ``prev_stick``: last (x_o, y_o); ``last_ns``: time of the last step; ``wall_side``:
    "left" / "right" while wall following (the side the wall is on), ``wall_entry_m``: the via
    point's distance when following began; ``last_wall_side`` / ``wall_left_ns``: the side used
    last and when following ended; ``front_turn``: the way (+1 left, -1 right) ``avoid-front``
    is turning, kept while it keeps firing (0: it did not fire last cycle); ``detour``: the side
    (+1 left, -1 right) of the last detour, preferred on a tie (0: none yet); ``asked``: the
    (v, w) this step returned; ``blocked_s``: how long motion was asked for and none sent;
    ``escape``: the unblocking try under way (0 ahead, 1 turn, 2 back; -1 none), ``escape_s``
    how long it has run, ``escape_turn`` the turn the rules wanted when it began; ``freed_by``
    / ``freed_ns``: the try that last freed the robot, and when; ``override_held_s``: how long
    the sweep has held the override still; ``override_spent``: it yielded, for this stick cell;
    ``plan_path``: the local planner's last path in {R} then (every second cell; empty: none),
    ``plan_phase``: its last phase ("" none, "path", "approach", "thread").
    """

    counts: Grid = _ZERO_GRID
    confidence: tuple[float, ...] = ()
    stick_cell: int | None = None
    contest: float = 0.0
    prev_stick: tuple[float, float] = (0.0, 0.0)
    last_ns: int | None = None
    wall_side: str | None = None
    wall_entry_m: float = math.inf
    last_wall_side: str | None = None
    wall_left_ns: int | None = None
    front_turn: float = 0.0
    wall_start_ns: int | None = None
    detour: float = 0.0
    asked: tuple[float, float] = (0.0, 0.0)
    blocked_s: float = 0.0
    escape: int = -1
    escape_s: float = 0.0
    escape_turn: float = 0.0
    freed_by: int = -1
    freed_ns: int | None = None
    override_held_s: float = 0.0
    override_spent: bool = False
    plan_path: tuple[tuple[float, float], ...] = ()
    plan_phase: str = ""

    @staticmethod
    def initial() -> AssistMemory:
        return AssistMemory()


@dataclass(frozen=True, slots=True)
class AssistResult:
    """One cycle of the assistant: the command before the pipeline's limits and sweep."""

    v_mps: float
    w_radps: float
    memory: AssistMemory
    rule: str
    heading_rad: float | None  # suggested heading in {R}; None when stopping
    active: BoolGrid  # [sector][band], sectors (left, front, right), bands (close, inter, far)
    confidence: float  # the occupied joystick cell's confidence, 0 when centred
    modified: bool  # (v, w) differs from the stick's eq. 4 command
    v_ref_mps: float = 0.0
    w_ref_radps: float = 0.0
    levels: tuple[int | None, int | None, int | None] = (None, None, None)  # nearest active band
    goal_bearing_rad: float | None = None


# -- pieces -----------------------------------------------------------------------------------


def cell_hits(obstacles: ObstaclePoints, params: AssistParams) -> BoolGrid:
    """Which of the 9 cells hold at least one point this cycle (module docstring)."""
    x, y, r2 = obstacles.x, obstacles.y, obstacles.r2
    ahead = x > 0.0
    half = params.corridor_half_width_m
    sector_masks = (ahead & (y > half), ahead & (np.abs(y) <= half), ahead & (y < -half))
    edges = (params.close_m, params.intermediate_m, params.faraway_m)
    band_masks = []
    lower = -1.0
    for edge in edges:
        band_masks.append((r2 > lower) & (r2 <= edge * edge))
        lower = edge * edge
    rows = []
    for s in sector_masks:
        rows.append(tuple(bool(np.any(s & b)) for b in band_masks))
    return (rows[0], rows[1], rows[2])  # type: ignore[return-value]


def update_counts(counts: Grid, hits: BoolGrid, params: AssistParams) -> Grid:
    """+hit_increment up to hit_max on a hit, -miss_decrement down to 0 otherwise (per cycle)."""
    out = []
    for row_c, row_h in zip(counts, hits, strict=True):
        out.append(
            tuple(
                min(c + params.hit_increment, params.hit_max)
                if h
                else max(c - params.miss_decrement, 0)
                for c, h in zip(row_c, row_h, strict=True)
            )
        )
    return (out[0], out[1], out[2])  # type: ignore[return-value]


def activation(counts: Grid, params: AssistParams) -> BoolGrid:
    rows = [tuple(c > params.activation_threshold for c in row) for row in counts]
    return (rows[0], rows[1], rows[2])  # type: ignore[return-value]


def levels_of(active: BoolGrid) -> tuple[int | None, int | None, int | None]:
    """Nearest active band per sector (LeftO, FrontO, RightO), None when none is active."""
    out: list[int | None] = []
    for row in active:
        out.append(next((band for band, on in enumerate(row) if on), None))
    return (out[0], out[1], out[2])


def stick_cell(phi_rad: float, bins: int) -> int:
    """The confidence cell of a stick angle; cell 0 is centred on straight forward."""
    width = 2.0 * math.pi / bins
    return round(phi_rad / width) % bins


def update_confidence(
    confidence: tuple[float, ...], cell: int | None, dt_s: float, params: AssistParams
) -> tuple[float, ...]:
    """Occupied cell +dt / build_s, others -dt / decay_s, within [0, 1] (sec. II.C)."""
    if len(confidence) != params.confidence_bins:
        confidence = (0.0,) * params.confidence_bins
    up = dt_s / params.confidence_build_s
    down = dt_s / params.confidence_decay_s
    return tuple(
        min(c + up, 1.0) if i == cell else max(c - down, 0.0) for i, c in enumerate(confidence)
    )


def corridor_clear(
    obstacles: ObstaclePoints, heading_rad: float, length_m: float, half_width_m: float
) -> bool:
    """No point in the strip of ``half_width_m`` either side of the ray at ``heading_rad``,
    from the origin out to ``length_m`` ahead."""
    if len(obstacles) == 0:
        return True
    c, s = math.cos(heading_rad), math.sin(heading_rad)
    u = obstacles.x * c + obstacles.y * s
    v = -obstacles.x * s + obstacles.y * c
    return not bool(np.any((u > 0.0) & (u <= length_m) & (np.abs(v) <= half_width_m)))


def _wrap(a: float) -> float:
    return math.atan2(math.sin(a), math.cos(a))


def _clip(a: float, lo: float, hi: float) -> float:
    return max(lo, min(hi, a))


def _circular_mean(a: float, b: float) -> float:
    return math.atan2(math.sin(a) + math.sin(b), math.cos(a) + math.cos(b))


def _choose_wall_side(
    obstacles: ObstaclePoints, beta: float, params: AssistParams, memory: AssistMemory, now_ns: int
) -> str:
    """Side the wall will be on: the robot turns the way a clear corridor opens nearest to the
    via point's direction (5 deg steps); the side used within ``rejoin_s`` is kept."""
    if (
        memory.last_wall_side is not None
        and memory.wall_left_ns is not None
        and (now_ns - memory.wall_left_ns) * 1e-9 <= params.rejoin_s
    ):
        return memory.last_wall_side
    step = math.radians(5.0)
    for k in range(1, 37):
        left_open = corridor_clear(
            obstacles, beta + k * step, params.block_m, params.corridor_half_width_m
        )
        right_open = corridor_clear(
            obstacles, beta - k * step, params.block_m, params.corridor_half_width_m
        )
        if left_open and not right_open:
            return "right"  # turning left keeps the wall on the right
        if right_open and not left_open:
            return "left"
        if left_open and right_open:
            break
    return "right" if beta >= 0.0 else "left"


def _wall_heading(
    obstacles: ObstaclePoints, side: str, params: AssistParams, profile: RobotProfile
) -> tuple[float, bool]:
    """Tangent follower (module docstring): heading and whether the wall was found."""
    s = 1.0 if side == "left" else -1.0
    x, y, r2 = obstacles.x, obstacles.y, obstacles.r2
    mask = (
        (r2 <= params.wall_range_m * params.wall_range_m)
        & (s * y >= -params.corridor_half_width_m)
        & (x >= profile.footprint.bounds[0])  # not behind the back of the robot
    )
    if not bool(np.any(mask)):
        return s * params.wall_lost_turn_rad, False
    idx = np.flatnonzero(mask)
    i = int(idx[np.argmin(r2[idx])])
    d = math.sqrt(float(r2[i]))
    alpha = math.atan2(float(y[i]), float(x[i]))
    tangent = alpha - s * _HALF_PI
    correction = _clip(
        params.wall_gain_rad_per_m * (params.wall_distance_m - d),
        -params.wall_correction_max_rad,
        params.wall_correction_max_rad,
    )
    return _wrap(tangent - s * correction), True


def _way_is_free(
    obstacles: ObstaclePoints,
    bearing: float,
    levels: tuple[int | None, int | None, int | None],
    params: AssistParams,
) -> bool:
    """Steer straight at the via point past the obstacle rules (module docstring): FRONT not
    CLOSE, no single CLOSE side on the via point's side (both CLOSE is a corridor) and the
    footprint's way towards it clear for ``block_m``."""
    left, front, right = levels
    if front == CLOSE:  # something right ahead: the obstacle rules (turn in place) decide
        return False
    if left == CLOSE and right != CLOSE and bearing > 0.0:
        return False
    if right == CLOSE and left != CLOSE and bearing < 0.0:
        return False
    # The whole of block_m, even when the via point is nearer: past it the robot has to stop.
    return corridor_clear(obstacles, bearing, params.block_m, params.way_half_width_m)


def _free_heading(
    obstacles: ObstaclePoints, bearing: float, params: AssistParams, prefer: float
) -> float | None:
    """The heading nearest ``bearing`` (within ``detour_max_rad``) whose footprint-wide way is
    clear for ``block_m``; on a tie of the two sides, ``prefer`` (+1 left, -1 right, 0 none)."""
    n = int(params.detour_max_rad / params.detour_step_rad)
    order = (1.0, -1.0) if prefer >= 0.0 else (-1.0, 1.0)
    for k in range(1, n + 1):
        for sign in order:
            h = bearing + sign * k * params.detour_step_rad
            if corridor_clear(obstacles, h, params.block_m, params.detour_half_width_m):
                return _wrap(h)
    return None


def _narrow_heading(
    obstacles: ObstaclePoints, bearing: float, params: AssistParams, prefer: float
) -> float | None:
    """The narrow detour (``squeeze_*``): None when no heading within ``detour_max_rad`` of
    ``bearing`` has its way clear at ``squeeze_half_width_m`` for ``block_m``. Otherwise the
    run of clear headings nearest ``bearing`` (a tie: the side ``prefer``), and in it the
    heading half its width, at most ``squeeze_centre_max_rad``, past its near edge: through
    the middle of a narrow gap, not along one of its sides (a gap little wider than the robot
    leaves it centimetres either side, and the sweep stops a robot that grazes one)."""
    if params.squeeze_step_rad <= 0.0 or params.detour_max_rad <= 0.0:
        return None
    n = int(params.detour_max_rad / params.squeeze_step_rad)
    offsets = np.arange(-n, n + 1) * params.squeeze_step_rad
    if len(obstacles) == 0:
        return _wrap(bearing)
    near = (obstacles.r2 <= params.block_m * params.block_m) & (obstacles.x > -params.block_m)
    x, y = obstacles.x[near], obstacles.y[near]
    headings = bearing + offsets
    c, s = np.cos(headings)[:, None], np.sin(headings)[:, None]
    u = x[None, :] * c + y[None, :] * s
    v = -x[None, :] * s + y[None, :] * c
    hit = (u > 0.0) & (u <= params.block_m) & (np.abs(v) <= params.squeeze_half_width_m)
    clear = ~hit.any(axis=1)
    if not bool(clear.any()):
        return None
    # Runs of clear headings: [first, last] index pairs.
    edges = np.diff(np.concatenate(([0], clear.astype(np.int8), [0])))
    firsts, lasts = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
    best: tuple[float, float, float] | None = None  # (distance, side rank, heading)
    for a, b in zip(firsts.tolist(), lasts.tolist(), strict=True):
        lo, hi = float(offsets[a]), float(offsets[b])
        half = min(0.5 * (hi - lo), params.squeeze_centre_max_rad)
        if lo <= 0.0 <= hi:  # the via point's own direction is in the run
            distance, off = 0.0, _clip(0.0, lo + half, hi - half)
        elif lo > 0.0:
            distance, off = lo, lo + half
        else:
            distance, off = -hi, hi - half
        rank = 0.0 if prefer == 0.0 or math.copysign(1.0, off) == prefer else 1.0
        if best is None or (distance, rank) < best[:2]:
            best = (distance, rank, off)
    assert best is not None
    return _wrap(bearing + best[2])


def _avoid(
    theta: float,
    levels: tuple[int | None, int | None, int | None],
    params: AssistParams,
    front_turn: float = 0.0,
) -> tuple[float, float, str | None]:
    """The obstacle rules over a desired heading: (heading, speed factor, rule or None).

    ``front_turn`` is the way ``avoid-front`` turned last cycle: it keeps turning that way
    (otherwise a robot in a corner swaps sides as it turns and never gets out).
    """
    left, front, right = levels
    if front is not None and front <= INTERMEDIATE:
        # More open side: the farther nearest band (None = nothing active) wins; tie -> theta.
        lo = 3 if left is None else left
        ro = 3 if right is None else right
        sign = 1.0 if lo > ro else -1.0 if ro > lo else (1.0 if theta >= 0.0 else -1.0)
        if front == CLOSE:
            if front_turn != 0.0:
                sign = 1.0 if front_turn > 0.0 else -1.0
            return sign * _HALF_PI, 0.0, "avoid-front"
        turned = sign * max(sign * theta, params.front_turn_rad)
        return turned, params.front_intermediate_speed, "avoid-front"
    upper, lower = math.inf, -math.inf
    if left == CLOSE:
        upper = -params.side_close_rad
    elif left == INTERMEDIATE:
        upper = params.side_intermediate_rad
    if right == CLOSE:
        lower = params.side_close_rad
    elif right == INTERMEDIATE:
        lower = -params.side_intermediate_rad
    if lower > upper:  # both sides close (case 3): a gap
        return _clip(theta, -params.gap_max_rad, params.gap_max_rad), params.gap_speed, "gap"
    if theta > upper:
        return upper, 1.0, "avoid-left"
    if theta < lower:
        return lower, 1.0, "avoid-right"
    return theta, 1.0, None


_PARAM_NAMES = tuple(f.name for f in fields(AssistParams))


def at_speed(params: AssistParams, profile: RobotProfile, speed_mps: float) -> AssistParams:
    """The params with every distance built on d_safe shrunk to the current speed's (module
    docstring): d_safe(v) = max(``d_safe_min_m``, d_safe |v| / v_max), never above d_safe.

    With the profile's own distances nothing shrinks below the footprint length d_robot. A
    robot TOML that sets some of them smaller than d_safe keeps them valid: the bands shrink no
    further than CLOSE = d_robot (all three together, so their order stays) and no other
    distance below d_robot or its configured value, whichever is smaller.
    """
    d_safe, d_robot = profile.d_safe_m, profile.d_robot_m
    floor = min(d_safe, params.d_safe_min_m)
    reach = max(floor, min(d_safe, abs(speed_mps) * d_safe / profile.v_max_mps))
    offset = min(d_safe - reach, params.close_m - d_robot)
    if not offset > 0.0:  # also a NaN speed: the full bands
        return params

    def shrunk(value: float, by: float) -> float:
        return max(value - by, min(value, d_robot))

    # Valid by construction (0 < offset <= close_m - d_robot keeps the bands positive and in
    # order; every other distance stays >= min(value, d_robot) > 0), so the copy skips
    # __post_init__'s validation, which cost a quarter of the step below top speed.
    out = object.__new__(AssistParams)
    for name in _PARAM_NAMES:
        object.__setattr__(out, name, getattr(params, name))
    for name, value in (
        ("close_m", params.close_m - offset),
        ("intermediate_m", params.intermediate_m - offset),
        ("faraway_m", params.faraway_m - offset),
        ("wall_distance_m", shrunk(params.wall_distance_m, 0.5 * offset)),
        ("wall_range_m", shrunk(params.wall_range_m, offset)),
        ("block_m", shrunk(params.block_m, offset)),
        ("leave_clear_m", shrunk(params.leave_clear_m, offset)),
    ):
        object.__setattr__(out, name, value)
    return out


def _motion(command: tuple[float, float], profile: RobotProfile) -> float:
    """How much a (v, w) moves, as fractions of the profile's limits."""
    return abs(command[0]) / profile.v_max_mps + abs(command[1]) / profile.w_max_radps


# -- the step ---------------------------------------------------------------------------------


def assist_step(
    memory: AssistMemory,
    x_o: float,
    y_o: float,
    obstacles: ObstaclePoints | npt.ArrayLike,
    goal_xy_m: tuple[float, float] | None,
    now_ns: int,
    params: AssistParams,
    profile: RobotProfile,
    sent: tuple[float, float] | None = None,
) -> AssistResult:
    """One cycle of the assistant (module docstring). ``sent`` is the (v, w) the base was sent
    last cycle: its speed shrinks the bands (``at_speed``), and a motion asked for but not sent
    is what ``unblock`` answers (None: the profile's bands, no unblocking)."""
    if sent is not None:
        params = at_speed(params, profile, sent[0])
    obs = obstacle_points(obstacles)
    if memory.last_ns is None or now_ns <= memory.last_ns:
        dt = 0.0
    else:
        dt = min((now_ns - memory.last_ns) * 1e-9, params.max_dt_s)

    counts = update_counts(memory.counts, cell_hits(obs, params), params)
    active = activation(counts, params)
    levels = levels_of(active)

    stick_ok = math.isfinite(x_o) and math.isfinite(y_o)
    goal_ok = goal_xy_m is None or (math.isfinite(goal_xy_m[0]) and math.isfinite(goal_xy_m[1]))
    xs = max(-1.0, min(1.0, x_o)) if stick_ok else 0.0
    ys = max(-1.0, min(1.0, y_o)) if stick_ok else 0.0
    magnitude = min(math.hypot(xs, ys), 1.0)
    phi = math.atan2(ys, xs)
    centred = magnitude < params.stick_deadzone
    cell = None if centred else stick_cell(phi, params.confidence_bins)
    confidence = update_confidence(memory.confidence, cell, dt, params)
    conf = 0.0 if cell is None else confidence[cell]
    spent = memory.override_spent and cell is not None and cell == memory.stick_cell
    v_ref, w_ref = profile.v_max_mps * xs, profile.w_max_radps * ys

    kept_path: tuple[tuple[float, float], ...] = ()
    plan_phase = ""

    def result(
        v: float,
        w: float,
        rule: str,
        heading: float | None,
        contest: float = 0.0,
        wall: tuple[str | None, float] = (None, math.inf),
        bearing: float | None = None,
        gave_up: bool = False,
        detour: float = 0.0,
        unblock: tuple[float, int, float, float, int, int | None] = (0.0, -1, 0.0, 0.0, -1, None),
        override_held_s: float = 0.0,
    ) -> AssistResult:
        turning = rule == "avoid-front" and heading is not None and v == 0.0
        turn = math.copysign(1.0, heading) if turning and heading is not None else 0.0
        last_side, left_ns = memory.last_wall_side, memory.wall_left_ns
        start_ns = memory.wall_start_ns if memory.wall_side is not None else now_ns
        if memory.wall_side is not None and wall[0] is None:  # following just ended
            last_side, left_ns = memory.wall_side, now_ns
            if gave_up:  # round and round: the other side next time
                last_side = "left" if memory.wall_side == "right" else "right"
        elif wall[0] is not None:
            last_side = wall[0]
        if wall[0] is None:
            start_ns = None
        new_memory = AssistMemory(
            counts,
            confidence,
            cell,
            contest,
            (xs, ys),
            now_ns,
            wall[0],
            wall[1],
            last_side,
            left_ns,
            turn,
            start_ns,
            detour,
            (v, w),
            *unblock,
            override_held_s,
            spent,
            kept_path,
            plan_phase,
        )
        modified = abs(v - v_ref) > _SAME or abs(w - w_ref) > _SAME
        return AssistResult(
            v, w, new_memory, rule, heading, active, conf, modified, v_ref, w_ref, levels, bearing
        )

    if not (stick_ok and goal_ok):
        return result(0.0, 0.0, "invalid", None)
    if len(obs) == 0 and not params.no_return_is_free:
        return result(0.0, 0.0, "unknown", None)
    if centred:
        # A pause keeps the wall following.
        return result(0.0, 0.0, "idle", None, wall=(memory.wall_side, memory.wall_entry_m))
    if xs < 0.0:
        return result(v_ref, w_ref, "reverse", phi)

    gain = params.heading_gain_per_s
    bearing: float | None = None
    distance = math.inf
    if goal_xy_m is not None:
        distance = math.hypot(goal_xy_m[0], goal_xy_m[1])
        if distance >= params.goal_min_m:
            bearing = math.atan2(goal_xy_m[1], goal_xy_m[0])
    aligned = (
        bearing is not None
        and abs(_clip(phi, -_HALF_PI, _HALF_PI) - _clip(bearing, -_HALF_PI, _HALF_PI))
        <= params.align_tolerance_rad
    )

    # The rules' proposal.
    wall: tuple[str | None, float] = (None, math.inf)
    gave_up = False
    speed_scale = 1.0
    if bearing is None:
        theta_d, source, drive = w_ref / gain, "free", xs
    elif aligned:
        theta_d, source, drive = bearing, "goal", magnitude
    else:
        theta_d, source, drive = _circular_mean(phi, bearing), "blend", magnitude

    rule: str
    theta: float
    detour_heading: float | None = None
    detour_turn = memory.detour
    plan: LocalPlan | None = None
    if bearing is not None and goal_xy_m is not None and params.plan_cell_m > 0.0 and len(obs):
        previous = memory.plan_path
        if sent is not None:
            previous = moved_path(previous, sent[0], sent[1], dt)
        plan = plan_target(
            obs, goal_xy_m, params.plan_settings(), previous, memory.plan_phase == "thread"
        )
    if plan is not None:
        plan_phase = plan.phase
        kept_path = tuple((float(x), float(y)) for x, y in plan.path_xy_m[::_KEEP_EVERY].tolist())
    if plan is not None and source == "blend":
        # The planner replaces the target's direction; the stick still pulls (sec. V).
        theta_d = _circular_mean(phi, math.atan2(plan.target_xy_m[1], plan.target_xy_m[0]))
    if plan is not None and source == "goal":
        theta, rule = math.atan2(plan.target_xy_m[1], plan.target_xy_m[0]), "plan"
        cap = max(
            params.plan_speed_min_mps,
            params.plan_slow_per_s * (plan.clearance_ahead_m - 0.5 * profile.width_m),
        )
        if plan.phase == "approach":  # slow down onto the entry point: the turn is made there
            reach_m = math.hypot(plan.target_xy_m[0], plan.target_xy_m[1])
            cap = min(cap, max(params.plan_speed_min_mps, params.plan_slow_per_s * reach_m))
        speed_scale = min(1.0, cap / max(drive * profile.v_max_mps, _SAME))
        # Along a gap's axis the robot lines up closely before it drives (the gap leaves it
        # centimetres); elsewhere only a large turn is made in place.
        turn_rad = params.plan_align_rad if plan.phase == "thread" else params.plan_turn_rad
        if abs(theta) > turn_rad:
            if len(obs) == 0 or float(obs.r2.min()) >= params.plan_narrow_m**2:
                speed_scale = 0.0  # room to turn: face the target first (an arc is swept wide)
            else:  # no room to turn in place: a slow arc
                speed_scale = min(speed_scale, params.plan_speed_min_mps / profile.v_max_mps)
    elif source == "goal" and bearing is not None:
        side = memory.wall_side
        front = levels[FRONT]
        if side is None:
            blocked = not corridor_clear(
                obs, bearing, min(distance, params.block_m), params.way_half_width_m
            )
            if front is not None and front <= INTERMEDIATE and blocked and abs(bearing) < _HALF_PI:
                wide = _free_heading(obs, bearing, params, memory.detour)
                narrow = _narrow_heading(obs, bearing, params, memory.detour)
                # The way nearest the via point that the robot fits through; the comfortable
                # one when it is as near (module docstring, "Narrow detour").
                if narrow is not None and (
                    wide is None or abs(_wrap(narrow - bearing)) < abs(_wrap(wide - bearing))
                ):
                    detour_heading = narrow
                else:
                    detour_heading = wide
                if detour_heading is None:
                    side = _choose_wall_side(obs, bearing, params, memory, now_ns)
                    wall = (side, distance)
        else:
            clear = corridor_clear(
                obs, bearing, min(distance, params.leave_clear_m), params.way_half_width_m
            )
            following_s = (
                0.0 if memory.wall_start_ns is None else (now_ns - memory.wall_start_ns) * 1e-9
            )
            if clear and (
                distance <= memory.wall_entry_m - params.progress_m
                or distance <= params.leave_clear_m
            ):
                side = None
            elif (following_s > params.wall_max_s and distance > memory.wall_entry_m) or (
                distance > memory.wall_entry_m + params.wall_retreat_m
            ):
                side, gave_up = None, True
            else:
                wall = (side, memory.wall_entry_m)
        if side is None and detour_heading is not None:
            theta, rule = detour_heading, "detour"
            detour_turn = math.copysign(1.0, _wrap(detour_heading - bearing))
            if front == CLOSE and abs(theta) >= params.front_turn_rad:
                speed_scale = 0.0
        elif side is not None:
            theta, found = _wall_heading(obs, side, params, profile)
            rule = f"wall-follow-{side}"
            if front == CLOSE and abs(theta) >= params.front_turn_rad:
                speed_scale = 0.0  # a sharp turn with something right ahead: turn in place
            elif not found:
                speed_scale = params.front_intermediate_speed
        elif _way_is_free(obs, bearing, levels, params):
            # The way to the via point is clear for the footprint: go (sec. V, "when there were
            # no objects in the way ... sent it towards the target destination").
            theta, rule = bearing, source
        else:
            theta, speed_scale, avoided = _avoid(theta_d, levels, params, memory.front_turn)
            rule = avoided or source
    else:
        theta, speed_scale, avoided = _avoid(theta_d, levels, params, memory.front_turn)
        rule = avoided or source

    if rule == "free":
        v, w = v_ref, w_ref
    else:
        w = _clip(gain * theta, -profile.w_max_radps, profile.w_max_radps)
        v = drive * profile.v_max_mps * speed_scale * max(math.cos(theta), 0.0)

    # The operator's override: the stick held in one cell against the rules (module docstring).
    changes = abs(v - v_ref) > _SAME or abs(w - w_ref) > _SAME
    same_cell = cell is not None and cell == memory.stick_cell
    if changes and same_cell and not aligned:
        contest = min(memory.contest + dt / params.confidence_build_s, 1.0)
    elif same_cell and not aligned:
        contest = max(memory.contest - dt / params.confidence_decay_s, 0.0)
    else:
        contest = 0.0
    # Motion asked for last cycle and (almost) none sent: the sweep refused it.
    refused = sent is not None and _motion(sent, profile) < params.unblock_below * _motion(
        memory.asked, profile
    )
    if spent:
        contest = 0.0
    if contest >= params.override_confidence and conf >= params.override_confidence:
        held_s = memory.override_held_s + dt if refused else 0.0
        if held_s < params.override_yield_s:
            return result(
                v_ref,
                w_ref,
                "override",
                phi,
                contest,
                (None, math.inf),
                bearing,
                override_held_s=held_s,
            )
        spent, contest = True, 0.0
    blocked_s, escape, escape_s = 0.0, -1, 0.0
    freed_by, freed_ns = memory.freed_by, memory.freed_ns
    if memory.escape >= 0:  # an escape under way: its try runs out, or the sweep refuses it
        escape, escape_s = memory.escape, memory.escape_s + dt
        if refused:
            escape, escape_s = (escape + 1) % 3, 0.0
        elif escape_s >= params.unblock_try_s:
            escape, freed_by, freed_ns = -1, escape, now_ns
    elif refused:
        blocked_s = memory.blocked_s + dt
        if blocked_s >= params.unblock_after_s and (abs(v) > _SAME or abs(w) > _SAME):
            # Blocked again soon after an escape: the rules undid it, so try the next one.
            again = freed_ns is not None and (now_ns - freed_ns) * 1e-9 <= params.unblock_repeat_s
            escape = (freed_by + 1) % 3 if again else 0
    escape_turn = 0.0
    if escape >= 0:
        # The turn the rules wanted when the escape began: the escape turns the other way.
        wanted = w if abs(w) > _SAME else theta
        escape_turn = memory.escape_turn if memory.escape >= 0 else wanted
        # Never faster than the stick asks (``drive``: m with a via point, x_o without one); a
        # stick asking for no speed at all (a pure turn) escapes by turning only.
        speed = min(params.unblock_speed, drive) * profile.v_max_mps
        if speed <= _SAME:
            escape = 1
        if escape == 0:
            v, w = speed, 0.0
        elif escape == 1:
            v, w = 0.0, -math.copysign(0.5 * profile.w_max_radps, escape_turn or 1.0)
        else:
            v, w = -speed, 0.0
        rule = "unblock"
    return result(
        v,
        w,
        rule,
        theta,
        contest,
        wall,
        bearing,
        gave_up,
        detour_turn,
        (blocked_s, escape, escape_s, escape_turn, freed_by, freed_ns),
    )
