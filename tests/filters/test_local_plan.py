"""The local planner ``assist`` steers by (``filters.local_plan``, issue 28): a way round what
the scan shows, gaps entered along their axis, and the last path kept."""

from __future__ import annotations

import math

import numpy as np
import pytest
from egc_common.profiles import JACKAL
from egc_common.scan import obstacle_points
from egc_robot.filters.assist import AssistParams
from egc_robot.filters.local_plan import moved_path, plan_target

SETTINGS = AssistParams.from_profile(JACKAL).plan_settings()
HALF_W = 0.5 * JACKAL.width_m


def segment(x0: float, y0: float, x1: float, y1: float, step: float = 0.02) -> np.ndarray:
    n = max(int(math.hypot(x1 - x0, y1 - y0) / step), 1) + 1
    t = np.linspace(0.0, 1.0, n)[:, None]
    return np.array([x0, y0]) + t * np.array([x1 - x0, y1 - y0])


def wall_with_gap(x: float, gap_y: tuple[float, float], reach: float = 1.8) -> np.ndarray:
    """A corridor 2 reach wide along x (side walls from x = -1 m, past the planner's window),
    closed at x by a wall across it with an opening between gap_y[0] and gap_y[1]."""
    return np.vstack(
        (
            segment(x, -reach, x, gap_y[0]),
            segment(x, gap_y[1], x, reach),
            segment(-1.0, -reach, 4.0, -reach),
            segment(-1.0, reach, 4.0, reach),
            segment(-1.0, -reach, -1.0, reach),
        )
    )


def test_a_wall_across_the_way_is_passed_through_its_gap():
    gap = (0.6, 0.6 + 1.3 * JACKAL.width_m)  # a gap 1.3 W wide, off to the left
    plan = plan_target(obstacle_points(wall_with_gap(1.5, gap)), (4.0, 0.0), SETTINGS)
    assert plan is not None
    crossing = plan.path_xy_m[np.argmin(np.abs(plan.path_xy_m[:, 0] - 1.5))]
    assert gap[0] + HALF_W <= crossing[1] + SETTINGS.cell_m
    assert crossing[1] - SETTINGS.cell_m <= gap[1] - HALF_W
    # Every cell of the path leaves the robot's half width clear.
    pts = wall_with_gap(1.5, gap)
    d = np.hypot(*(plan.path_xy_m[:, None, :] - pts[None, :, :]).transpose(2, 0, 1)).min(axis=1)
    assert d.min() >= SETTINGS.clearance_min_m - 1e-9


def test_a_gap_is_approached_on_its_axis_then_threaded_through_its_middle():
    gap = (0.6, 0.6 + 1.2 * JACKAL.width_m)
    middle = 0.5 * (gap[0] + gap[1])
    points = obstacle_points(wall_with_gap(1.2, gap))
    # The robot is below the gap's axis: it heads for the entry point on the axis first.
    plan = plan_target(points, (4.0, middle), SETTINGS)
    assert plan is not None and plan.phase == "approach" and plan.gap is not None
    (mx, my), (nx, ny) = plan.gap
    assert (mx, my) == pytest.approx((1.2, middle), abs=0.03)
    assert (nx, ny) == pytest.approx((1.0, 0.0), abs=0.05)
    tx, ty = plan.target_xy_m
    assert ty == pytest.approx(middle, abs=0.03) and tx < 1.2 - SETTINGS.approach_min_m + 1e-9
    # On the axis (in the robot's frame: the gap dead ahead), it steers along the axis.
    ahead = obstacle_points(wall_with_gap(1.2, (gap[0] - middle, gap[1] - middle)))
    on_axis = plan_target(ahead, (4.0, 0.0), SETTINGS)
    assert on_axis is not None and on_axis.phase == "thread"
    assert on_axis.target_xy_m[1] == pytest.approx(0.0, abs=0.03)


def test_a_wall_beside_the_path_is_not_a_gap():
    points = obstacle_points(segment(-1.0, -0.3, 3.0, -0.3))  # a wall 0.3 m to the right
    plan = plan_target(points, (2.5, 0.0), SETTINGS)
    assert plan is not None and plan.gap is None and plan.phase == "path"


def test_a_via_point_outside_the_window_is_approached_through_its_rim():
    plan = plan_target(obstacle_points(np.array([[-3.0, 3.0]])), (20.0, 0.0), SETTINGS)
    assert plan is not None
    end = plan.path_xy_m[-1]
    assert end[0] == pytest.approx(SETTINGS.window_m, abs=SETTINGS.cell_m)
    assert abs(end[1]) <= SETTINGS.cell_m
    assert plan.target_xy_m == pytest.approx((SETTINGS.lookahead_m, 0.0), abs=SETTINGS.cell_m)


def test_no_plan_when_the_robot_itself_has_no_clearance():
    points = obstacle_points(np.array([[0.1, 0.0]]))
    assert plan_target(points, (3.0, 0.0), SETTINGS) is None


def test_the_last_path_moves_with_the_robot():
    path = ((1.0, 0.0), (1.0, 1.0))
    # Straight ahead 0.5 m: everything comes 0.5 m nearer.
    ahead = np.array(moved_path(path, 1.0, 0.0, 0.5))
    np.testing.assert_allclose(ahead, [[0.5, 0.0], [0.5, 1.0]], atol=1e-12)
    # A quarter turn left in place: ahead is now on the right.
    turned = np.array(moved_path(path, 0.0, math.pi / 2, 1.0))
    np.testing.assert_allclose(turned, [[0.0, -1.0], [1.0, -1.0]], atol=1e-12)
    # An arc: the robot ends on the circle, facing along it.
    r, angle = 2.0, 0.3
    arc = np.array(moved_path(((r * math.sin(angle), r * (1 - math.cos(angle))),), r, 1.0, angle))
    np.testing.assert_allclose(arc, [[0.0, 0.0]], atol=1e-12)


def test_the_last_path_is_kept_between_two_ways_of_about_the_same_cost():
    # A post dead ahead: round it on the left or on the right, the same length either way.
    post = np.array(
        [[1.5 + 0.15 * math.cos(a), 0.15 * math.sin(a)] for a in np.linspace(0, 2 * math.pi, 40)]
    )
    points = obstacle_points(post)
    for side in (1.0, -1.0):
        kept = tuple((x, side * 0.6 * math.sin(math.pi * x / 3.0)) for x in np.arange(0, 3.0, 0.1))
        plan = plan_target(points, (3.0, 0.0), SETTINGS, kept)
        assert plan is not None
        beside = plan.path_xy_m[np.argmin(np.abs(plan.path_xy_m[:, 0] - 1.5))]
        assert math.copysign(1.0, beside[1]) == side
