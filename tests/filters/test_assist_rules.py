"""The rule-based assistant (``assist``, DESIGN 6; rule-based-assist paper): one test per rule,
the histograms with explicit times, wall following in and out, and a closed loop in the
simulator (assist, then the profile limits and the footprint sweep, as the pipeline will)."""

from __future__ import annotations

import math
from dataclasses import fields, replace

import numpy as np
import pytest
from egc_common.profiles import JACKAL, PIONEER3DX
from egc_common.scan import obstacle_points
from egc_robot.filters.assist import (
    CLOSE,
    FARAWAY,
    FRONT,
    INTERMEDIATE,
    LEFT,
    RIGHT,
    RULES,
    AssistMemory,
    AssistParams,
    AssistResult,
    assist_step,
    at_speed,
    corridor_clear,
    stick_cell,
)
from egc_robot.safety import SweepParams, limit_acceleration, limit_velocity, sweep_scale
from egc_sim.operators import GoalOperator
from egc_sim.simulator import Simulator

from tests.sim.helpers import boxed_room, grid_world

P = PIONEER3DX
# The rules of the paper and of the earlier deviations, without the local planner that now
# picks their target when there is a via point (``plan_cell_m`` = 0; the planner's own tests
# are ``test_rule_plan`` and the closed loops below, and tests/filters/test_local_plan.py).
PLANNED = AssistParams.from_profile(P)
PARAMS = replace(PLANNED, plan_cell_m=0.0)
MS = 1_000_000  # ns per ms
DT_MS = 50


def line(x0: float, y0: float, x1: float, y1: float, n: int = 60) -> np.ndarray:
    t = np.linspace(0.0, 1.0, n)[:, None]
    return np.array([x0, y0]) + t * np.array([x1 - x0, y1 - y0])


# A far point behind the robot: the scan is not empty, and it lands in no cell.
FAR_BEHIND = np.array([[-5.0, 0.0]])


def run(
    x_o: float,
    y_o: float,
    points: np.ndarray,
    goal: tuple[float, float] | None = None,
    cycles: int = 3,
    memory: AssistMemory | None = None,
    t0_ms: int = 0,
    dt_ms: int = DT_MS,
    params: AssistParams = PARAMS,
) -> AssistResult:
    """``cycles`` steps with the same inputs; the last result."""
    mem = memory or AssistMemory.initial()
    obstacles = obstacle_points(points)
    result = None
    for k in range(cycles):
        result = assist_step(mem, x_o, y_o, obstacles, goal, (t0_ms + k * dt_ms) * MS, params, P)
        mem = result.memory
    assert result is not None
    return result


# -- parameters ---------------------------------------------------------------------------------


def test_params_derived_from_the_profile():
    p = AssistParams.from_profile(P)
    assert p.close_m == pytest.approx(P.r_max_m)  # 0.595
    assert p.intermediate_m == pytest.approx(P.r_max_m + P.length_m)
    assert p.faraway_m == pytest.approx(P.r_max_m + 2 * P.length_m)
    assert p == AssistParams()  # the defaults are the Pioneer's
    j = AssistParams.from_profile(JACKAL)
    assert j.close_m == pytest.approx(JACKAL.r_max_m)
    assert j.corridor_half_width_m == pytest.approx(0.75 * JACKAL.width_m)


def test_params_from_mapping_reads_the_toml_table():
    p = AssistParams.from_mapping({"activation_threshold": 8, "heading_gain_per_s": 2}, P)
    assert p.activation_threshold == 8 and p.heading_gain_per_s == 2.0


@pytest.mark.parametrize(
    ("mapping", "message"),
    [
        ({"colse_m": 0.5}, "unknown keys: colse_m"),
        ({"activation_threshold": 6.5}, "activation_threshold must be an integer"),
        ({"close_m": 2.0}, "close_m < intermediate_m"),
        ({"gap_speed": math.nan}, "must be finite"),
        ({"no_return_is_free": 1}, "true or false"),
        ({"wall_distance_m": "far"}, "must be a number"),
        ({"unblock_speed": 1.5}, "unblock_speed must be in"),
        ({"unblock_try_s": 0}, "unblock_try_s must be positive"),
        ({"detour_step_rad": 0.0}, "detour_step_rad must be positive"),
    ],
)
def test_params_from_mapping_validates(mapping, message):
    with pytest.raises(ValueError, match=message):
        AssistParams.from_mapping(mapping)


# -- the obstacle histogram (paper sec. II.B) ---------------------------------------------------


def test_points_fall_into_sector_and_band_cells():
    pts = np.array(
        [
            [0.5, 0.0],  # front close (0.5 m)
            [0.6, 0.6],  # left intermediate (0.85 m)
            [1.0, -0.9],  # right faraway (1.35 m)
            [2.0, 0.0],  # beyond faraway: no cell
            [-0.3, 0.5],  # behind: no cell (the rules look ahead, as the paper's sensors)
        ]
    )
    r = run(0.0, 0.0, pts, cycles=1)
    counts = r.memory.counts
    assert counts[FRONT][CLOSE] == 6
    assert counts[LEFT][INTERMEDIATE] == 6
    assert counts[RIGHT][FARAWAY] == 6
    assert sum(map(sum, counts)) == 18


def test_histogram_increments_by_6_up_to_16_and_decrements_by_2_down_to_0():
    pts = np.array([[0.5, 0.0]])
    mem = AssistMemory.initial()
    seen = []
    for k in range(4):
        mem = assist_step(mem, 0.0, 0.0, pts, None, k * DT_MS * MS, PARAMS, P).memory
        seen.append(mem.counts[FRONT][CLOSE])
    assert seen == [6, 12, 16, 16]  # saturates at 16
    for k in range(4, 13):
        mem = assist_step(mem, 0.0, 0.0, FAR_BEHIND, None, k * DT_MS * MS, PARAMS, P).memory
        seen.append(mem.counts[FRONT][CLOSE])
    assert seen[4:] == [14, 12, 10, 8, 6, 4, 2, 0, 0]  # floors at 0
    assert all(c == 0 for i, row in enumerate(mem.counts) for j, c in enumerate(row))


def test_activation_threshold():
    pts = np.array([[0.5, 0.0]])
    one = run(0.0, 0.0, pts, cycles=1)
    assert one.memory.counts[FRONT][CLOSE] == 6 and not one.active[FRONT][CLOSE]  # 6 is not > 6
    two = run(0.0, 0.0, pts, cycles=2)
    assert two.active[FRONT][CLOSE] and two.levels == (None, CLOSE, None)
    strict = replace(PARAMS, activation_threshold=12)
    assert not run(0.0, 0.0, pts, cycles=2, params=strict).active[FRONT][CLOSE]  # 12
    assert run(0.0, 0.0, pts, cycles=3, params=strict).active[FRONT][CLOSE]  # 16


def test_a_single_stray_reading_never_activates_a_cell():
    mem = AssistMemory.initial()
    counts = []
    for k in range(5):
        pts = np.array([[0.5, 0.0]]) if k == 0 else FAR_BEHIND
        r = assist_step(mem, 1.0, 0.0, pts, None, k * DT_MS * MS, PARAMS, P)
        mem = r.memory
        counts.append(mem.counts[FRONT][CLOSE])
        assert not any(map(any, r.active))
    assert counts == [6, 4, 2, 0, 0]


# -- the joystick confidence histogram (paper sec. II.C) ----------------------------------------


def confidence_after(ms: int, dt_ms: int, stick=(1.0, 0.0)) -> float:
    pts = np.array([[5.0, 5.0]])
    mem = AssistMemory.initial()
    r = None
    for t in range(0, ms + 1, dt_ms):
        r = assist_step(mem, stick[0], stick[1], pts, None, t * MS, PARAMS, P)
        mem = r.memory
    assert r is not None
    return r.confidence


@pytest.mark.parametrize("dt_ms", [10, 50, 100])
def test_confidence_builds_in_about_half_a_second_at_any_control_rate(dt_ms):
    assert confidence_after(0, dt_ms) == 0.0  # the first cycle has no dt
    assert confidence_after(200, dt_ms) == pytest.approx(0.4)
    assert confidence_after(400, dt_ms) == pytest.approx(0.8)
    assert confidence_after(500, dt_ms) == pytest.approx(1.0)
    assert confidence_after(2000, dt_ms) == 1.0  # saturates


def test_confidence_decays_in_about_150_ms_when_the_stick_moves():
    pts = np.array([[5.0, 5.0]])
    mem = AssistMemory.initial()
    for t in range(0, 601, 10):  # steady forward for 0.6 s at 100 Hz
        mem = assist_step(mem, 1.0, 0.0, pts, None, t * MS, PARAMS, P).memory
    forward = stick_cell(0.0, PARAMS.confidence_bins)
    assert mem.confidence[forward] == 1.0
    levels = {}
    for t in range(610, 801, 10):  # the stick swings to the left
        r = assist_step(mem, 0.0, 1.0, pts, None, t * MS, PARAMS, P)
        mem = r.memory
        levels[t - 600] = mem.confidence[forward]
    assert levels[50] == pytest.approx(1.0 - 50 / 150)
    assert levels[100] == pytest.approx(1.0 - 100 / 150)
    assert levels[150] == pytest.approx(0.0, abs=1e-9)
    assert r.confidence == pytest.approx(0.4)  # the new cell builds at its own pace
    # A centred stick occupies no cell: everything decays, confidence 0.
    r = assist_step(mem, 0.0, 0.0, pts, None, 1000 * MS, PARAMS, P)
    assert r.confidence == 0.0


def test_time_comes_from_now_ns_only():
    pts = np.array([[0.5, 0.3]])
    a = run(0.6, 0.2, pts, cycles=4)
    b = run(0.6, 0.2, pts, cycles=4)
    assert a == b  # a pure function of its inputs
    # A clock that goes backwards counts as no time; a long gap counts as max_dt_s at most.
    back = assist_step(a.memory, 0.6, 0.2, pts, None, 0, PARAMS, P)
    assert back.confidence == a.confidence
    gap = assist_step(a.memory, 0.6, 0.2, pts, None, 10**12, PARAMS, P)
    assert gap.confidence == pytest.approx(
        min(a.confidence + PARAMS.max_dt_s / PARAMS.confidence_build_s, 1.0)
    )


# -- one test per rule --------------------------------------------------------------------------


def test_every_rule_has_a_test():
    names = {n for n in globals() if n.startswith("test_rule_")}
    assert names == {"test_rule_" + r.replace("-", "_") for r in RULES}


def test_rule_invalid():
    pts = np.array([[3.0, 0.0]])
    for x_o, y_o, goal in ((math.nan, 0.0, None), (1.0, math.inf, None), (1.0, 0.0, (math.nan, 1))):
        r = run(x_o, y_o, pts, goal)
        assert (r.rule, r.v_mps, r.w_radps, r.heading_rad) == ("invalid", 0.0, 0.0, None)


def test_rule_unknown():
    """No point at all and the sensor does not declare no-return free: nothing seen is not
    free (DESIGN 5.9, egc.py's NO_POINTS_UNKNOWN): stop, with or without a via point."""
    empty = np.empty((0, 2))
    for goal in (None, (2.0, 0.0)):
        r = run(1.0, 0.0, empty, goal)
        assert (r.rule, r.v_mps, r.w_radps) == ("unknown", 0.0, 0.0)
    free = replace(PARAMS, no_return_is_free=True)
    r = run(1.0, 0.0, empty, params=free)
    assert r.rule == "free" and r.v_mps == pytest.approx(P.v_max_mps)


def test_rule_idle():
    r = run(0.02, 0.01, np.array([[3.0, 0.0]]), goal=(2.0, 0.0))
    assert (r.rule, r.v_mps, r.w_radps) == ("idle", 0.0, 0.0)


def test_rule_reverse():
    r = run(-0.5, 0.2, np.array([[-1.0, 0.0]]), goal=(2.0, 0.0))
    assert r.rule == "reverse"
    assert (r.v_mps, r.w_radps) == pytest.approx((-0.5 * P.v_max_mps, 0.2 * P.w_max_radps))


def test_rule_free():
    """No via point and nothing active: the stick's eq. 4 command, unchanged."""
    r = run(0.8, 0.3, np.array([[5.0, 0.0], [0.0, 3.0]]))
    assert r.rule == "free" and not r.modified
    assert (r.v_mps, r.w_radps) == pytest.approx((0.8 * P.v_max_mps, 0.3 * P.w_max_radps))


def test_rule_goal():
    """Stick in line with the via point, nothing in the way: steer at the via point."""
    goal = (3.0, 1.0)
    beta = math.atan2(1.0, 3.0)
    r = run(1.0, 0.2, np.array([[-3.0, 0.0]]), goal)
    assert r.rule == "goal" and r.heading_rad == pytest.approx(beta)
    assert r.goal_bearing_rad == pytest.approx(beta)
    assert r.w_radps == pytest.approx(min(PARAMS.heading_gain_per_s * beta, P.w_max_radps))
    assert r.v_mps == pytest.approx(1.0 * P.v_max_mps * math.cos(beta))  # J = min(|stick|, 1)


def test_rule_blend():
    """Via point to the left, stick forward-right (not in line): the average of the two."""
    r = run(0.7, -0.7, np.array([[-3.0, 0.0]]), goal=(0.0, 2.0))
    assert r.rule == "blend"
    assert r.heading_rad == pytest.approx(math.radians((90 - 45) / 2))
    assert r.w_radps > 0.0


def test_rule_avoid_front():
    wall = line(0.5, -1.0, 0.5, 1.0)  # a wall 0.5 m ahead: FRONT CLOSE
    wall = np.vstack([wall, line(0.3, -0.5, 0.6, -0.5)])  # and something on the right
    r = run(1.0, 0.0, wall)
    assert r.rule == "avoid-front" and r.levels[FRONT] == CLOSE
    assert r.v_mps == 0.0 and r.w_radps > 0.0  # turns in place, towards the open left
    # FRONT at INTERMEDIATE: slows and turns by at least front_turn_rad.
    far = run(1.0, 0.0, line(0.9, -0.2, 0.9, 0.2, 10))
    assert far.rule == "avoid-front" and far.levels == (None, INTERMEDIATE, None)
    assert abs(far.heading_rad) == pytest.approx(PARAMS.front_turn_rad)
    assert 0.0 < far.v_mps < P.v_max_mps * PARAMS.front_intermediate_speed


def test_avoid_front_keeps_its_turn_while_turning_in_place():
    """In a corner the open side swaps as the robot turns; it keeps turning the same way."""
    left_close = np.vstack([line(0.5, -0.2, 0.5, 0.2, 10), line(0.3, 0.45, 0.5, 0.45, 10)])
    first = run(1.0, 0.0, left_close)
    assert first.rule == "avoid-front" and first.w_radps < 0.0  # right is more open
    right_close = np.vstack([line(0.5, -0.2, 0.5, 0.2, 10), line(0.3, -0.45, 0.5, -0.45, 10)])
    again = run(1.0, 0.0, right_close, memory=first.memory, t0_ms=1000, cycles=3)
    assert again.rule == "avoid-front" and again.w_radps < 0.0  # still right


def test_rule_gap():
    """Both sides CLOSE, front clear (paper case 3): through the gap, heading clamped."""
    pts = np.vstack([line(0.1, 0.45, 0.5, 0.45, 10), line(0.1, -0.45, 0.5, -0.45, 10)])
    r = run(1.0, 0.0, pts, goal=(3.0, 1.5))
    assert r.rule == "gap" and r.levels == (CLOSE, None, CLOSE)
    assert r.heading_rad == pytest.approx(PARAMS.gap_max_rad)
    assert r.v_mps == pytest.approx(
        math.hypot(1.0, 0.0) * P.v_max_mps * PARAMS.gap_speed * math.cos(PARAMS.gap_max_rad)
    )


def test_rule_avoid_left():
    # Left at INTERMEDIATE: the stick's left turn is held at straight ahead (case 1, change 0).
    inter = np.array([[0.7, 0.6]] * 3)
    r = run(0.8, 0.5, inter)
    assert r.rule == "avoid-left" and r.levels == (INTERMEDIATE, None, None)
    assert r.w_radps == 0.0 and r.heading_rad == 0.0 and r.modified
    # Left CLOSE: turn away by at least side_close_rad.
    close = np.array([[0.3, 0.45]] * 3)
    r = run(0.8, 0.0, close)
    assert r.rule == "avoid-left" and r.levels[LEFT] == CLOSE
    assert r.heading_rad == pytest.approx(-PARAMS.side_close_rad) and r.w_radps < 0.0
    # Turning away already: nothing to change.
    assert run(0.8, -0.5, inter).rule == "free"


def test_rule_avoid_right():
    inter = np.array([[0.7, -0.6]] * 3)
    r = run(0.8, -0.5, inter)
    assert r.rule == "avoid-right" and r.levels == (None, None, INTERMEDIATE)
    assert r.w_radps == 0.0
    close = np.array([[0.3, -0.45]] * 3)
    r = run(0.8, 0.0, close, goal=(3.0, -1.0))  # with a via point on the obstacle's side
    assert r.rule == "avoid-right"
    assert r.heading_rad == pytest.approx(PARAMS.side_close_rad) and r.w_radps > 0.0


def test_no_via_point_is_joystick_plus_avoidance():
    free = run(0.6, -0.4, np.array([[4.0, 0.0]]))
    assert free.rule == "free" and not free.modified
    near = run(0.6, 0.4, np.array([[0.3, 0.45]] * 3))
    assert near.rule == "avoid-left" and near.modified and near.goal_bearing_rad is None
    assert near.v_mps > 0.0  # speed from the stick's forward deflection


# -- detours ------------------------------------------------------------------------------------

# A wall across the way to a via point 3 m ahead; its left end is nearer the via point's line.
WALL_OPEN_LEFT = line(0.9, -1.5, 0.9, 0.2)
WALL_OPEN_RIGHT = line(0.9, -0.2, 0.9, 1.5)


def _clear(points: np.ndarray, heading: float) -> bool:
    return corridor_clear(
        obstacle_points(points), heading, PARAMS.block_m, PARAMS.detour_half_width_m
    )


def test_rule_detour():
    """Something across the way to the via point: steer for the nearest heading whose way is
    clear at the footprint's width plus margin, on the open side."""
    r = run(1.0, 0.0, WALL_OPEN_LEFT, goal=(3.0, 0.0))
    assert r.rule == "detour"
    assert math.radians(20) < r.heading_rad < math.radians(60) and r.w_radps > 0.0
    assert _clear(WALL_OPEN_LEFT, r.heading_rad)
    nearer = r.heading_rad - PARAMS.detour_step_rad
    assert not _clear(WALL_OPEN_LEFT, nearer) and not _clear(WALL_OPEN_LEFT, -nearer)
    assert r.memory.detour == 1.0 and r.memory.wall_side is None
    right = run(1.0, 0.0, WALL_OPEN_RIGHT, goal=(3.0, 0.0))
    assert right.rule == "detour" and right.heading_rad < 0.0 and right.memory.detour == -1.0


def test_a_detour_keeps_its_side_in_front_of_a_symmetric_obstacle():
    block = line(0.9, -0.5, 0.9, 0.5)
    for side in (1.0, -1.0):
        memory = replace(AssistMemory.initial(), detour=side)
        r = run(1.0, 0.0, block, goal=(3.0, 0.0), memory=memory)
        assert r.rule == "detour" and math.copysign(1.0, r.heading_rad) == side


def test_a_detour_ends_once_the_way_to_the_via_point_is_clear():
    detouring = run(1.0, 0.0, WALL_OPEN_LEFT, goal=(3.0, 0.0)).memory
    past = line(-0.5, -1.0, 0.2, -1.0)  # the wall now behind, on the right
    r = run(1.0, 0.0, past, goal=(2.5, -0.3), memory=detouring, t0_ms=1000)
    assert r.rule == "goal" and r.heading_rad == pytest.approx(math.atan2(-0.3, 2.5))


def test_a_narrow_detour_goes_through_the_middle_of_a_gap_little_wider_than_the_robot():
    """Dense clutter (issue 28): a wall across the way with one gap of 1.3 footprint widths,
    off the via point's line. No heading near it has the comfortable way (a width of margin),
    so the assistant steers through the gap: the way nearest the via point that the robot
    fits through at the sweep's margin, aimed at the middle of the clear run of headings."""
    gap, centre = 1.3 * P.width_m, 0.2
    wall = np.vstack(
        [
            line(0.6, -1.5, 0.6, centre - 0.5 * gap, 150),
            line(0.6, centre + 0.5 * gap, 0.6, 1.5, 150),
        ]
    )
    r = run(1.0, 0.0, wall, goal=(3.0, 0.0))
    assert r.rule == "detour" and r.memory.wall_side is None
    assert r.heading_rad == pytest.approx(math.atan2(centre, 0.6), abs=math.radians(2.0))
    assert corridor_clear(
        obstacle_points(wall), r.heading_rad, PARAMS.block_m, PARAMS.squeeze_half_width_m
    )
    assert not _clear(wall, r.heading_rad)  # no comfortable way through it
    # Narrow detours off (squeeze_step_rad 0): the comfortable way round the wall, as before.
    off = replace(PARAMS, squeeze_step_rad=0.0)
    wide = run(1.0, 0.0, wall, goal=(3.0, 0.0), params=off)
    assert wide.rule == "detour" and abs(wide.heading_rad) > math.radians(45.0)
    assert _clear(wall, wide.heading_rad)


# -- wall following -------------------------------------------------------------------------------

# Wall following on its own: the scenes above have a detour, so these tests turn detours off.
NO_DETOUR = replace(PARAMS, detour_max_rad=0.0)
# A pocket: a wall across the way and walls on both sides. No heading within 90 degrees of the
# via point is clear, so even with detours on the robot follows a wall out of it.
POCKET = np.vstack(
    [line(0.9, -1.5, 0.9, 1.5), line(-0.5, 0.6, 0.9, 0.6), line(-0.5, -0.6, 0.9, -0.6)]
)


def test_wall_following_begins_where_no_detour_is_clear():
    r = run(1.0, 0.0, POCKET, goal=(3.0, 0.2))
    assert r.rule.startswith("wall-follow") and r.memory.wall_side is not None


def test_wall_following_gives_up_when_the_via_point_falls_behind():
    following = run(1.0, 0.0, WALL_OPEN_LEFT, goal=(3.0, 0.0), params=NO_DETOUR).memory
    assert following.wall_side == "right" and following.wall_entry_m == pytest.approx(3.0)
    wall = line(-0.5, -PARAMS.wall_distance_m, 0.6, -PARAMS.wall_distance_m, 80)
    # Closer than entry + wall_retreat_m: still following.
    near = 3.0 + 0.8 * PARAMS.wall_retreat_m
    stay = run(
        1.0, 0.0, wall, goal=(near, 0.0), memory=following, t0_ms=1000, cycles=1, params=NO_DETOUR
    )
    assert stay.rule == "wall-follow-right"
    far = 3.0 + 1.2 * PARAMS.wall_retreat_m
    gone = run(
        1.0, 0.0, wall, goal=(far, 0.0), memory=following, t0_ms=1000, cycles=1, params=NO_DETOUR
    )
    assert gone.memory.wall_side is None and not gone.rule.startswith("wall-follow")
    assert gone.memory.last_wall_side == "left"  # gave up: the other side next time


def test_rule_wall_follow_right():
    r = run(1.0, 0.0, WALL_OPEN_LEFT, goal=(3.0, 0.0), params=NO_DETOUR)
    assert r.rule == "wall-follow-right"  # goes round by the left: the wall on its right
    assert r.memory.wall_side == "right" and r.memory.wall_entry_m == pytest.approx(3.0)
    assert r.heading_rad > math.radians(45) and r.w_radps > 0.0


def test_rule_wall_follow_left():
    r = run(1.0, 0.0, WALL_OPEN_RIGHT, goal=(3.0, 0.0), params=NO_DETOUR)
    assert r.rule == "wall-follow-left"
    assert r.heading_rad < -math.radians(45) and r.w_radps < 0.0


def test_wall_following_is_entered_only_on_the_way_to_the_via_point():
    # No via point: plain avoidance.
    assert run(1.0, 0.0, WALL_OPEN_LEFT).rule == "avoid-front"
    # Via point off to the side with its way clear: no wall following.
    assert not run(1.0, 0.0, WALL_OPEN_LEFT, goal=(0.0, 3.0)).rule.startswith("wall")


def test_wall_following_parallel_to_a_wall_on_the_right():
    """Following with the wall at the follow distance on the right: drive straight along it."""
    following = run(1.0, 0.0, WALL_OPEN_LEFT, goal=(3.0, 0.0), params=NO_DETOUR).memory
    wall = line(-0.5, -PARAMS.wall_distance_m, 0.6, -PARAMS.wall_distance_m, 80)
    r = run(
        1.0, 0.0, wall, goal=(3.0, -0.3), memory=following, t0_ms=1000, cycles=1, params=NO_DETOUR
    )
    assert r.rule == "wall-follow-right"
    assert r.heading_rad == pytest.approx(0.0, abs=0.05)
    assert r.v_mps > 0.9 * P.v_max_mps


def test_wall_following_turns_in_place_with_something_right_ahead():
    """FRONT CLOSE and a sharp turn: turning on an arc there is what the sweep would stop."""
    r = run(1.0, 0.0, line(0.45, -0.8, 0.45, 0.2, 40), goal=(3.0, 0.0), params=NO_DETOUR)
    assert r.rule == "wall-follow-right" and r.levels[FRONT] == CLOSE
    assert r.v_mps == 0.0 and r.w_radps == pytest.approx(P.w_max_radps)


def test_wall_following_leaves_when_the_way_is_clear_and_closer():
    following = run(1.0, 0.0, WALL_OPEN_LEFT, goal=(3.0, 0.0), params=NO_DETOUR).memory
    beside = line(-0.5, -0.6, 0.4, -0.6, 20)  # the obstacle now on the right, way ahead clear
    # Farther from the via point than where following began (within wall_retreat_m): keep
    # following (Bug2 rule).
    kw = {"memory": following, "t0_ms": 1000, "params": NO_DETOUR}
    stay = run(1.0, 0.0, beside, goal=(3.3, 0.0), cycles=6, **kw)
    assert stay.rule == "wall-follow-right"
    # Closer and the way clear: leave, and steer at the via point at once (the footprint's way
    # to it is clear, so the wall still counted ahead in the histogram does not hold it back).
    leave = run(1.0, 0.0, beside, goal=(2.0, 0.1), cycles=1, **kw)
    assert leave.memory.wall_side is None and leave.rule == "goal"
    assert leave.levels[FRONT] is not None
    leave = run(1.0, 0.0, beside, goal=(2.0, 0.1), cycles=6, **kw)
    assert leave.rule == "goal" and leave.memory.wall_side is None
    assert leave.memory.last_wall_side == "right"
    # Blocked again soon after: the same side again (no swapping round one obstacle).
    again = run(
        1.0,
        0.0,
        WALL_OPEN_RIGHT,
        goal=(3.0, 0.0),
        memory=leave.memory,
        t0_ms=2000,
        params=NO_DETOUR,
    )
    assert again.rule == "wall-follow-right"


# -- the operator's override ----------------------------------------------------------------------


def test_rule_override():
    """Stick held steady straight at a wall, no via point: the avoidance acts first, and after
    about 0.5 s of the stick held against it, the operator's command goes out."""
    wall = line(0.5, -1.0, 0.5, 1.0)
    mem = AssistMemory.initial()
    rules = {}
    for t in range(0, 1001, DT_MS):
        r = assist_step(mem, 1.0, 0.0, wall, None, t * MS, PARAMS, P)
        mem = r.memory
        rules[t] = r
    assert rules[100].rule == "avoid-front" and rules[100].v_mps == 0.0
    assert rules[400].rule == "avoid-front"
    first = min(t for t, r in rules.items() if r.rule == "override")
    assert 450 <= first <= 600
    assert all(r.rule == "override" for t, r in rules.items() if t >= first)
    last = rules[1000]
    assert (last.v_mps, last.w_radps) == pytest.approx((P.v_max_mps, 0.0))
    assert last.confidence == 1.0 and not last.modified


def test_override_yields_when_the_sweep_holds_it_still():
    """The override sent, the base held still (the sweep): after ``override_yield_s`` the rules
    drive again, and stay in charge while the stick stays in its cell; a stick moved to another
    cell may win again. (An outside check: a steady stick held a Jackal at a wall for good.)"""
    wall = line(0.5, -1.0, 0.5, 1.0)
    mem = AssistMemory.initial()
    rules = {}
    r = None
    for t in range(0, 4001, DT_MS):
        # The base moves as the rules ask, and not at all when the override asks (the sweep).
        sent = (0.0, 0.0) if r is None or r.rule == "override" else (r.v_mps, r.w_radps)
        r = assist_step(mem, 1.0, 0.0, wall, None, t * MS, PARAMS, P, sent=sent)
        mem = r.memory
        rules[t] = r
    first = min(t for t, r in rules.items() if r.rule == "override")
    last = max(t for t, r in rules.items() if r.rule == "override")
    yield_ms = PARAMS.override_yield_s * 1000
    assert yield_ms - 2 * DT_MS <= last - first <= yield_ms + DT_MS
    assert all(r.rule != "override" for t, r in rules.items() if t > last)
    assert mem.override_spent
    # The stick moved to another cell: the operator asks again, and wins again.
    again = []
    for t in range(4000 + DT_MS, 6001, DT_MS):
        sent = (r.v_mps, r.w_radps) if r.rule != "override" else (0.0, 0.0)
        r = assist_step(mem, 1.0, 0.6, wall, None, t * MS, PARAMS, P, sent=sent)
        mem = r.memory
        again.append(r.rule)
    assert "override" in again


def test_a_moving_stick_never_overrides():
    wall = line(0.5, -1.0, 0.5, 1.0)
    mem = AssistMemory.initial()
    for t in range(0, 3001, DT_MS):
        y_o = 0.0 if (t // 200) % 2 == 0 else 0.6  # moves between two cells every 0.2 s
        r = assist_step(mem, 1.0, y_o, wall, None, t * MS, PARAMS, P)
        mem = r.memory
        assert r.rule != "override"


def test_a_stick_in_line_with_the_via_point_is_not_an_override():
    """The blind operator holds the stick at the via point; the rules keep steering."""
    mem = AssistMemory.initial()
    for t in range(0, 3001, DT_MS):
        r = assist_step(mem, 1.0, 0.0, WALL_OPEN_LEFT, (3.0, 0.0), t * MS, PARAMS, P)
        mem = r.memory
        assert r.rule == "detour" or t < 100
    assert r.confidence == 1.0


def test_override_against_the_via_point():
    """Stick held steady to the left, away from a via point ahead: after ~0.5 s the stick wins."""
    pts = np.array([[-3.0, 0.0]])
    early = run(0.3, 0.9, pts, goal=(3.0, 0.0), cycles=4)
    assert early.rule == "blend"
    late = run(0.3, 0.9, pts, goal=(3.0, 0.0), cycles=16)
    assert late.rule == "override"
    assert (late.v_mps, late.w_radps) == pytest.approx((0.3 * P.v_max_mps, 0.9 * P.w_max_radps))


# -- properties -----------------------------------------------------------------------------------


def test_output_within_the_profile_limits():
    rng = np.random.default_rng(7)
    for profile in (PIONEER3DX, JACKAL):
        params = AssistParams.from_profile(profile)
        mem = AssistMemory.initial()
        for k in range(400):
            pts = rng.uniform(-3.0, 3.0, size=(rng.integers(1, 30), 2))
            goal = None if k % 3 == 0 else tuple(rng.uniform(-5.0, 5.0, size=2))
            x_o, y_o = rng.uniform(-1.2, 1.2, size=2)
            r = assist_step(mem, x_o, y_o, pts, goal, k * DT_MS * MS, params, profile)
            mem = r.memory
            assert r.rule in RULES
            assert abs(r.v_mps) <= profile.v_max_mps + 1e-12
            assert abs(r.w_radps) <= profile.w_max_radps + 1e-12
            assert math.isfinite(r.v_mps) and math.isfinite(r.w_radps)


# -- closed loop in the simulator -----------------------------------------------------------------


def drive(sim: Simulator, goal_world, params: AssistParams, max_time_s: float, tolerance_m: float):
    """Goal operator -> assist (via point = the goal, in {R} from odometry) -> profile limits ->
    footprint sweep -> simulator, at 20 Hz. Returns (reached, rules in order)."""
    operator = GoalOperator(goal_world)
    mem = AssistMemory.initial()
    previous = (0.0, 0.0)
    sweep = SweepParams()
    rules: list[str] = []
    dt = 0.05
    for _ in range(round(max_time_s / dt)):
        if math.dist(sim.pose[:2], goal_world) <= tolerance_m:
            return True, rules
        stick = operator.command(sim.time_s, sim.pose)
        scan = sim.scan()
        x, y, yaw = sim.odometry
        dx, dy = goal_world[0] - x, goal_world[1] - y
        goal = (math.cos(yaw) * dx + math.sin(yaw) * dy, -math.sin(yaw) * dx + math.cos(yaw) * dy)
        p = replace(params, no_return_is_free=scan.no_return_is_free)
        r = assist_step(
            mem, stick.x_o, stick.y_o, scan.obstacles(), goal, round(sim.time_s * 1e9), p, P
        )
        mem = r.memory
        rules.append(r.rule)
        v, w = limit_velocity(r.v_mps, r.w_radps, P)
        v, w = limit_acceleration(v, w, previous, dt, P)
        s = sweep_scale(v, w, scan.obstacles(), P, sweep)
        previous = (s * v, s * w)
        sim.step(*previous, dt)
        assert not sim.collided, f"contact at {sim.pose}"
    return False, rules


def test_rule_plan():
    """With a via point and the stick in line with it, the planner picks the target: a wall
    across the way with one opening off to the side is crossed through the opening, on its
    axis, slowly, turning in place first when the target is far off the robot's heading."""
    gap = (0.5, 0.5 + 1.3 * P.width_m)
    wall = np.vstack((line(1.5, -3.0, 1.5, gap[0], 200), line(1.5, gap[1], 1.5, 3.0, 200)))
    r = run(1.0, 0.0, wall, goal=(4.0, 0.0), params=PLANNED)
    assert r.rule == "plan"
    # Towards the opening (left), not at the via point straight through the wall.
    assert r.heading_rad is not None and r.heading_rad > math.radians(20.0)
    assert r.memory.plan_path, "the path is kept for the next cycle"
    if abs(r.heading_rad) > PLANNED.plan_turn_rad:
        assert r.v_mps == 0.0 and r.w_radps > 0.0  # room to turn: in place first
    else:
        assert 0.0 < r.v_mps <= max(PLANNED.plan_speed_min_mps, P.v_max_mps)
    # The stick elsewhere: the paper's blend of the stick and the planned direction.
    blend = run(0.3, 1.0, wall, goal=(4.0, 0.0), params=PLANNED)
    assert blend.rule != "plan"
    # Without a via point there is nothing to plan to.
    assert run(1.0, 0.0, wall, params=PLANNED).rule != "plan"


@pytest.mark.parametrize("params", [PARAMS, PLANNED], ids=["rules", "planned"])
def test_closed_loop_goal_behind_a_single_obstacle_is_reached(params):
    occ = boxed_room(6.0, 4.0)
    occ[30:50, 50:70] = True  # a 1.0 m x 1.0 m block at x 2.5-3.5, y 1.5-2.5
    world = grid_world(occ)
    start, goal = (1.0, 2.0, 0.0), (5.0, 2.1)
    sim = Simulator(world, P, start)
    reached, rules = drive(sim, goal, params, 120.0, 0.3)
    assert reached and not sim.collided
    assert sim.min_clearance_m > 0.0
    if params.plan_cell_m > 0.0:
        assert set(rules) <= {"plan", "unblock"} and "plan" in rules
    else:
        around = [i for i, r in enumerate(rules) if r == "detour"]
        assert around, "the block ahead on the way to the via point is passed by a detour"
        assert "goal" in rules[around[-1] :], "and the robot heads for the via point once clear"
    # The straight line costs 4 m at 0.14 m/s (29 s); round the block well within 2x that.
    assert sim.time_s < 60.0


# -- the bands at the robot's speed ---------------------------------------------------------------


def test_bands_shrink_to_the_speed_for_a_fast_robot_and_not_for_the_pioneer():
    jackal = AssistParams.from_profile(JACKAL)
    full = at_speed(jackal, JACKAL, JACKAL.v_max_mps)
    assert full == jackal  # at v_max: d_safe = v_max * 1 s, the profile's bands
    half = at_speed(jackal, JACKAL, 1.0)  # d_safe(1 m/s) = 1 m: every distance moves by 1 m
    assert half.close_m == pytest.approx(jackal.close_m - 1.0)
    assert half.faraway_m - half.close_m == pytest.approx(jackal.faraway_m - jackal.close_m)
    assert half.block_m == pytest.approx(jackal.block_m - 1.0)
    assert half.wall_distance_m == pytest.approx(jackal.wall_distance_m - 0.5)
    still = at_speed(jackal, JACKAL, 0.0)  # floored at d_safe_min_m
    assert still.close_m == pytest.approx(JACKAL.d_robot_m + jackal.d_safe_min_m)
    assert at_speed(jackal, JACKAL, -1.0) == half  # reversing: the same speed
    assert at_speed(jackal, JACKAL, math.nan) == jackal
    for v in (0.0, 0.07, P.v_max_mps):  # the Pioneer's d_safe is the floor: nothing moves
        assert at_speed(PARAMS, P, v) == PARAMS


def test_bands_set_below_d_safe_in_the_robot_toml_stay_valid_at_any_speed():
    """A Jackal TOML with close_m = 1.0 (less than its 2 m d_safe) used to raise in the
    control cycle once the robot slowed: CLOSE went below zero."""
    small = AssistParams.from_mapping({"close_m": 1.0, "wall_distance_m": 0.6}, JACKAL)
    for v in (0.0, 0.5, 1.0, JACKAL.v_max_mps):
        shrunk = at_speed(small, JACKAL, v)
        assert JACKAL.d_robot_m <= shrunk.close_m <= small.close_m
        assert shrunk.faraway_m - shrunk.close_m == pytest.approx(small.faraway_m - small.close_m)
        assert 0.0 < shrunk.wall_distance_m <= small.wall_distance_m
    assert at_speed(small, JACKAL, 0.0).close_m == pytest.approx(JACKAL.d_robot_m)


@pytest.mark.parametrize("profile", [P, JACKAL], ids=lambda p: p.name)
@pytest.mark.parametrize(
    "toml",
    [
        {},
        {"close_m": 1.0, "wall_distance_m": 0.6},
        {"close_m": 0.5, "block_m": 0.3},
        {"leave_clear_m": 0.2},
    ],
)
def test_bands_at_any_speed_pass_the_params_own_validation(profile, toml):
    """at_speed skips __post_init__ (it runs every cycle): its output must pass it anyway."""
    params = AssistParams.from_mapping(toml, profile)
    for v in np.linspace(-profile.v_max_mps, profile.v_max_mps, 41):
        shrunk = at_speed(params, profile, float(v))
        revalidated = AssistParams(**{f.name: getattr(shrunk, f.name) for f in fields(shrunk)})
        assert revalidated == shrunk
        assert shrunk.close_m <= params.close_m and shrunk.block_m <= params.block_m


def test_a_fast_robot_sees_a_box_as_close_only_at_speed():
    jackal = AssistParams.from_profile(JACKAL)
    box = line(1.5, -0.2, 1.5, 0.2, 20)
    fast = assist_step(
        AssistMemory.initial(), 1.0, 0.0, box, None, 0, jackal, JACKAL, (JACKAL.v_max_mps, 0.0)
    )
    slow = assist_step(AssistMemory.initial(), 1.0, 0.0, box, None, 0, jackal, JACKAL, (0.3, 0.0))
    assert fast.levels == slow.levels == (None, None, None)  # one cycle: nothing active yet
    mem_fast, mem_slow = fast.memory, slow.memory
    for k in range(1, 4):
        fast = assist_step(mem_fast, 1.0, 0.0, box, None, k * 50 * MS, jackal, JACKAL, (2.0, 0.0))
        slow = assist_step(mem_slow, 1.0, 0.0, box, None, k * 50 * MS, jackal, JACKAL, (0.3, 0.0))
        mem_fast, mem_slow = fast.memory, slow.memory
    assert fast.levels[FRONT] == CLOSE and slow.levels[FRONT] == FARAWAY


# -- unblocking -----------------------------------------------------------------------------------


def _blocked(memory_changes: dict, sent=(0.0, 0.0)) -> AssistResult:
    """Wall following (3 cycles up to t = 100 ms), then one step at t = 150 ms with the memory
    changed as given and the base having been sent ``sent`` last cycle."""
    following = run(1.0, 0.0, WALL_OPEN_LEFT, goal=(3.0, 0.0), params=NO_DETOUR).memory
    memory = replace(following, **memory_changes)
    return assist_step(memory, 1.0, 0.0, WALL_OPEN_LEFT, (3.0, 0.0), 150 * MS, NO_DETOUR, P, sent)


def test_rule_unblock():
    """The sweep refused the rules' motion for unblock_after_s: escape ahead slowly; when the
    sweep refuses that too, a turn in place the other way, then back; a try that moves runs for
    unblock_try_s, then the rules take over again."""
    asked = {"asked": (0.0, 0.5)}  # the rules turned left in place last cycle
    first = _blocked({**asked, "blocked_s": 0.0})
    assert first.rule == "wall-follow-right"  # refused for one cycle only
    assert first.memory.blocked_s == pytest.approx(0.05)
    ahead = _blocked({**asked, "blocked_s": PARAMS.unblock_after_s})
    assert ahead.rule == "unblock" and ahead.memory.escape == 0
    assert (ahead.v_mps, ahead.w_radps) == (PARAMS.unblock_speed * P.v_max_mps, 0.0)
    assert ahead.memory.escape_turn > 0.0  # remembers the way the rules wanted to turn
    # Ahead refused as well: turn in place the other way (right).
    escaping = {"asked": (ahead.v_mps, 0.0), "escape": 0, "escape_turn": 0.5}
    turn = _blocked(escaping)
    assert turn.rule == "unblock" and turn.memory.escape == 1 and turn.v_mps == 0.0
    assert turn.w_radps == pytest.approx(-0.5 * P.w_max_radps)
    # The turn refused too: back.
    back = _blocked({"asked": (0.0, turn.w_radps), "escape": 1, "escape_turn": 0.5})
    assert back.rule == "unblock" and back.memory.escape == 2
    assert back.v_mps == -PARAMS.unblock_speed * P.v_max_mps
    # A try that moves keeps going until unblock_try_s, then the rules again.
    going = _blocked({**escaping, "escape_s": 0.1}, sent=(ahead.v_mps, 0.0))
    assert going.rule == "unblock" and going.memory.escape == 0
    assert going.memory.escape_s == pytest.approx(0.15)
    done = _blocked({**escaping, "escape_s": PARAMS.unblock_try_s}, sent=(ahead.v_mps, 0.0))
    assert done.rule == "wall-follow-right" and done.memory.escape == -1
    # Motion sent: nothing refused, no escape; no feedback at all: no escape either.
    moving = _blocked({**asked, "blocked_s": PARAMS.unblock_after_s}, sent=(0.05, 0.3))
    assert moving.rule == "wall-follow-right" and moving.memory.blocked_s == 0.0
    assert _blocked({**asked, "blocked_s": 5.0}, sent=None).rule == "wall-follow-right"


def test_unblock_blocked_again_soon_after_an_escape_tries_the_next_one():
    """The turn the other way freed the robot, then the rules turned it straight back into the
    wedge: within unblock_repeat_s the next escape starts with the try after that one."""
    asked = {"asked": (0.0, 0.5), "blocked_s": PARAMS.unblock_after_s, "freed_by": 1}
    soon = _blocked({**asked, "freed_ns": 150 * MS - int(0.5 * PARAMS.unblock_repeat_s * 1e9)})
    assert soon.rule == "unblock" and soon.memory.escape == 2 and soon.v_mps < 0.0
    late = _blocked({**asked, "freed_ns": 150 * MS - int(2.0 * PARAMS.unblock_repeat_s * 1e9)})
    assert late.rule == "unblock" and late.memory.escape == 0 and late.v_mps > 0.0
    # A try that runs its full time is remembered as the one that freed the robot.
    freed = _blocked(
        {"asked": (0.0, -0.5), "escape": 1, "escape_s": PARAMS.unblock_try_s, "escape_turn": 0.5},
        sent=(0.0, -0.5),
    )
    assert freed.memory.escape == -1 and freed.memory.freed_by == 1
    assert freed.memory.freed_ns == 150 * MS


def test_no_rule_drives_faster_than_the_stick_asks():
    """Assist bends or slows the operator's command, it never speeds it up: whatever the rule,
    |v| <= m v_max, m the stick's magnitude with a via point and its forward deflection |x_o|
    without one (module docstring). The base is sent nothing (the sweep refusing everything),
    so ``unblock`` escapes as well; a stick held for 2 s per draw lets it begin."""
    rng = np.random.default_rng(11)
    rules = set()
    for profile in (PIONEER3DX, JACKAL):
        params = AssistParams.from_profile(profile)
        mem = AssistMemory.initial()
        t_ms = 0
        for k in range(60):
            pts = rng.uniform(-2.0, 2.0, size=(rng.integers(1, 30), 2))
            goal = None if k % 2 == 0 else tuple(rng.uniform(-4.0, 4.0, size=2))
            x_o, y_o = rng.uniform(-0.3, 0.6), rng.uniform(-0.6, 0.6)
            asks = math.hypot(x_o, y_o) if goal is not None else abs(x_o)
            for _ in range(40):
                r = assist_step(mem, x_o, y_o, pts, goal, t_ms * MS, params, profile, (0.0, 0.0))
                mem, t_ms = r.memory, t_ms + DT_MS
                rules.add(r.rule)
                assert abs(r.v_mps) <= asks * profile.v_max_mps + 1e-12, (r.rule, x_o, y_o, goal)
    assert "unblock" in rules


def test_unblock_moves_at_the_speed_the_stick_asks_for_when_that_is_less():
    """A stick asking for 10 % of v_max (no via point): the escape ahead and back go at that
    speed, not at unblock_speed (25 %), and still move; a stick asking for no speed at all (a
    pure turn) escapes by turning."""
    box = line(0.5, -1.0, 0.5, 1.0)  # FRONT CLOSE: the rules turn in place
    for x_o in (0.1, 0.6):
        speed = min(PARAMS.unblock_speed, x_o) * P.v_max_mps
        r = run(x_o, 0.0, box)
        assert r.rule == "avoid-front" and r.v_mps == 0.0 and r.w_radps != 0.0
        mem = replace(r.memory, blocked_s=PARAMS.unblock_after_s)
        ahead = assist_step(mem, x_o, 0.0, box, None, 150 * MS, PARAMS, P, (0.0, 0.0))
        assert ahead.rule == "unblock" and ahead.memory.escape == 0
        assert ahead.v_mps == pytest.approx(speed) and ahead.w_radps == 0.0
        mem = replace(r.memory, asked=(0.0, r.w_radps), escape=1, escape_turn=r.w_radps)
        back = assist_step(mem, x_o, 0.0, box, None, 150 * MS, PARAMS, P, (0.0, 0.0))
        assert back.rule == "unblock" and back.memory.escape == 2
        assert back.v_mps == pytest.approx(-speed)
    turning = run(0.0, 0.8, box)
    mem = replace(turning.memory, asked=(0.0, turning.w_radps), blocked_s=1.0)
    escape = assist_step(mem, 0.0, 0.8, box, None, 150 * MS, PARAMS, P, (0.0, 0.0))
    assert escape.rule == "unblock" and escape.v_mps == 0.0 and escape.w_radps != 0.0
