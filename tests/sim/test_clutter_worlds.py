"""Dense-clutter worlds (``egc_sim.clutter_field``, issue 28 item 5): seeded, solvable for the
robot, every way through gaps of 1.2-1.5 x its width, the straight line blocked."""

from __future__ import annotations

import math

import numpy as np
import pytest
from egc_common.profiles import get_profile
from egc_sim.clutter_field import (
    KINDS,
    ClutterParams,
    clutter_world,
    line_blocked,
)
from egc_sim.collision import FootprintChecker
from egc_sim.field_world import linked
from egc_sim.grid_world import World
from egc_sim.worlds import WorldError, builtin_names, load_world
from scipy import ndimage

SEEDS = range(12)


def _clearance(w: World) -> np.ndarray:
    return np.asarray(ndimage.distance_transform_edt(~w.occupancy)) * w.resolution_m


def widest_gap_m(w: World) -> float:
    """The narrowest gap on the widest way from start to goal, measured on the grid: twice
    the largest disc radius that still links them (bisection on the distance transform).
    The transform measures from cell centres to occupied cell centres, so a gap g between
    surfaces reads about g + 1 cell."""
    clearance = _clearance(w)
    start, goal = w.start_pose[:2], w.goal
    lo, hi = 0.0, float(clearance.max())
    assert linked(clearance, lo + 1e-9, start, goal, w.resolution_m)
    while hi - lo > 0.1 * w.resolution_m:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if linked(clearance, mid, start, goal, w.resolution_m) else (lo, mid)
    return 2.0 * lo - w.resolution_m


@pytest.mark.parametrize("profile", ["jackal", "husky", "turtlebot4"])
def test_every_way_leads_through_gaps_of_one_point_two_to_one_point_five_widths(profile):
    """Sized for the robot: the widest way from start to goal narrows to a gap between 1.2 and
    1.5 x the footprint's width (2 cells of grid tolerance), so there is a way, and no way
    round the clutter that is wider."""
    fp = get_profile(profile).footprint
    params = ClutterParams.for_robot(fp.width_m, fp.reach_m)
    tol = 2 * params.resolution_m
    for seed in SEEDS:
        w = load_world(f"clutter:{seed}", footprint=fp)
        gap = widest_gap_m(w)
        assert 1.2 * fp.width_m - tol <= gap <= 1.5 * fp.width_m + tol, (profile, seed, gap)


@pytest.mark.parametrize("profile", ["jackal", "husky", "turtlebot4"])
def test_clutter_worlds_are_solvable_start_clear_and_block_the_straight_line(profile):
    fp = get_profile(profile).footprint
    params = ClutterParams.for_robot(fp.width_m, fp.reach_m)
    for seed in SEEDS:
        w = load_world(f"clutter:{seed}", footprint=fp)
        clearance = _clearance(w)
        start, goal = w.start_pose[:2], w.goal
        # A disc of half the width + a little links start and goal ...
        assert linked(clearance, params.passage_m, start, goal, w.resolution_m), seed
        # ... but cannot slide along the straight line between them.
        assert line_blocked(clearance, params.passage_m, start, goal, w.resolution_m), seed
        t = np.linspace(0.0, 1.0, 800)
        line = [
            (start[0] + u * (goal[0] - start[0]), start[1] + u * (goal[1] - start[1])) for u in t
        ]
        assert not any(w.blocked_at(x, y) for x, y in line[:5] + line[-5:]), seed
        # The robot can turn in place where it starts and where it stops, 0.1 m to spare:
        # the disc it sweeps (radius: its reach) keeps that from everything (half a cell of
        # grid tolerance), and so does the footprint itself at every heading.
        for x, y in (start, goal):
            assert clearance[w.cell_of(x, y)] >= fp.reach_m + 0.1 - 0.5 * w.resolution_m, seed
        if seed < 2:
            checker = FootprintChecker(w, fp)
            turning = min(checker.clearance(*start, a) for a in np.linspace(-3.1, 3.1, 32))
            assert turning >= 0.1, (seed, turning)
        sx, sy, yaw = w.start_pose
        assert yaw == pytest.approx(math.atan2(goal[1] - sy, goal[0] - sx))


def test_clutter_worlds_are_seeded_and_mix_both_kinds():
    a, b, c = clutter_world(5), clutter_world(5), clutter_world(6)
    assert np.array_equal(a.occupancy, b.occupancy) and a.start_pose == b.start_pose
    assert a.goal == b.goal and a.name == "clutter:5"
    assert not np.array_equal(a.occupancy, c.occupancy)
    assert load_world("clutter", seed=5).name == "clutter:5"
    assert np.array_equal(load_world("clutter", seed=5).occupancy, a.occupancy)
    kinds = {KINDS[int(np.random.default_rng(s).integers(len(KINDS)))] for s in range(30)}
    assert kinds == set(KINDS)
    # Dense: much of the space between start and goal is taken.
    filled = [clutter_world(s).occupancy[4:-4, 60:-60].mean() for s in range(10)]
    assert min(filled) > 0.05


def test_clutter_worlds_scale_with_the_robot():
    """The gaps follow the width, the room the reach: a Husky's world is larger, its gaps
    wider; a TurtleBot's gaps narrower than a Jackal's in a room of the Jackal's size."""
    jackal, husky, tb4 = (get_profile(n).footprint for n in ("jackal", "husky", "turtlebot4"))
    pj = ClutterParams.for_robot(jackal.width_m, jackal.reach_m)
    ph = ClutterParams.for_robot(husky.width_m, husky.reach_m)
    pt = ClutterParams.for_robot(tb4.width_m, tb4.reach_m)
    assert pj.gap_min_m == pytest.approx(1.2 * 0.43) and pj.gap_max_m == pytest.approx(1.5 * 0.43)
    assert ph.width_m > pj.width_m and ph.gap_min_m > pj.gap_max_m
    assert pt.width_m == pj.width_m and pt.gap_max_m < pj.gap_min_m
    wj = load_world("clutter:3", footprint=jackal)
    wh = load_world("clutter:3", footprint=husky)
    assert wh.occupancy.shape[1] > wj.occupancy.shape[1]
    # Without a footprint a disc of the given reach stands in for the robot.
    assert np.array_equal(
        load_world("clutter:3", reach_m=0.3).occupancy,
        clutter_world(3, ClutterParams.for_robot(0.6, 0.3)).occupancy,
    )


def test_bad_clutter_specs_and_params_say_what_is_wrong():
    assert "clutter" in builtin_names()
    with pytest.raises(WorldError, match="clutter world seed must be an integer, got 'x'"):
        load_world("clutter:x")
    with pytest.raises(WorldError, match="seed must be an integer"):
        load_world("clutter:")
    with pytest.raises(WorldError, match="positive robot width"):
        ClutterParams.for_robot(0.0, 0.3)
    with pytest.raises(WorldError, match="less than half its width"):
        ClutterParams.for_robot(0.6, 0.2)
    with pytest.raises(WorldError, match="leave no passage"):
        clutter_world(0, ClutterParams(gap_min_ratio=1.0))
    with pytest.raises(WorldError, match="too small"):
        clutter_world(0, ClutterParams(width_m=3.0))


def test_an_episode_sizes_the_clutter_world_from_its_profile():
    """``egc-teleop episode --map clutter:S --profile P`` passes the profile's footprint to
    ``load_world``: a Husky's episode runs in the Husky's world, not the Jackal's."""
    from egc_experiments.episode import EpisodeSettings, run_settings

    husky = get_profile("husky").footprint
    _, summary = run_settings(EpisodeSettings(map="clutter:4", profile="husky", max_time_s=0.5))
    world = load_world("clutter:4", footprint=husky)
    assert summary["start"] == pytest.approx(list(world.start_pose))
    assert summary["goal"] == pytest.approx(list(world.goal))
    assert world.goal != load_world("clutter:4", footprint=get_profile("jackal").footprint).goal
