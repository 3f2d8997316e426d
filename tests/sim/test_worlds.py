"""Geometric TOML worlds, .npy grids, built-in names and seeded random worlds."""

from __future__ import annotations

import math

import numpy as np
import pytest
from egc_sim.random_field import RandomFieldParams, random_world
from egc_sim.shapes import Circle, Polygon, Segment, rasterise
from egc_sim.worlds import WorldError, builtin_names, load_world
from scipy import ndimage

TOML = """
name = "two shapes"
resolution_m = 0.1
bounds_m = [-1.0, 0.0, 3.0, 2.0]
start = { x_m = -0.5, y_m = 1.0, yaw_rad = 0.25 }
goal = { x_m = 2.5, y_m = 1.0 }
goal_tolerance_m = 0.4

[[segments]]
from_m = [-1.0, 0.05]
to_m = [3.0, 0.05]
thickness_m = 0.1

[[circles]]
center_m = [1.0, 1.0]
radius_m = 0.3

[[polygons]]
points_m = [[2.0, 1.2], [2.4, 1.2], [2.4, 1.8], [2.0, 1.8]]

[[areas]]
name = "box"
min_m = [2.0, 1.2]
max_m = [2.4, 1.8]
"""


def test_toml_world_is_rasterised_by_cell_centres(tmp_path):
    path = tmp_path / "w.toml"
    path.write_text(TOML)
    w = load_world(str(path))
    assert (w.name, w.resolution_m, w.origin) == ("two shapes", 0.1, (-1.0, 0.0))
    assert w.occupancy.shape == (20, 40)
    assert (w.start_pose, w.goal, w.goal_tolerance_m) == ((-0.5, 1.0, 0.25), (2.5, 1.0), 0.4)
    assert w.areas[0].name == "box" and w.areas[0].contains(2.2, 1.5)
    assert w.occupancy[0].all()  # the segment along the bottom row
    # Exactly the cells whose centre lies in a shape: the bottom row (the segment), the disc
    # of radius 0.3 m around (1, 1) and the 4 x 6 cells of the box.
    xs = -1.0 + (np.arange(40) + 0.5) * 0.1
    ys = (np.arange(20) + 0.5) * 0.1
    gx, gy = np.meshgrid(xs, ys)
    expected = np.hypot(gx - 1.0, gy - 1.0) <= 0.3
    expected[0, :] = True
    expected[12:18, 30:34] = True
    assert np.array_equal(w.occupancy, expected)
    assert not w.unknown.any()


def test_thin_diagonal_wall_has_no_gap():
    grid = rasterise([Segment((0.0, 0.0), (2.0, 2.0))], 40, 40, 0.05, (0.0, 0.0))
    # 4-connected along the diagonal: no free cell pair lets anything pass between two cells.
    _labels, n = ndimage.label(~grid)  # 4-connectivity by default
    assert n == 2


def test_polygon_even_odd_and_circle():
    square = Polygon(((0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)))
    assert rasterise([square], 10, 10, 0.2, (-0.5, -0.5)).sum() == 25
    assert rasterise([Circle((0.0, 0.0), 0.01)], 4, 4, 0.5, (-1.0, -1.0)).sum() == 0


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("bounds_m = [0, 0, 1, 1]\nsurprise = 1\n", "unknown key"),
        ("name = 'no bounds'\n", "bounds_m"),
        ("bounds_m = [0, 0, -1, 1]\n", "x_max > x_min"),
        ("bounds_m = [0, 0, 1, 1]\n[[circles]]\ncenter_m = [0, 0]\n", "lacks key"),
        ("bounds_m = [0, 0, 1, 1]\n[[circles]]\ncenter_m = [0, 0]\nradius_m = -1\n", "positive"),
        ("bounds_m = [0, 0, 1, 1]\n[[polygons]]\npoints_m = [[0, 0], [1, 1]]\n", "at least 3"),
        ("bounds_m = [0, 0, 1, 1\n", "not valid TOML"),
    ],
)
def test_bad_toml_worlds(tmp_path, text, message):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(WorldError, match=message):
        load_world(str(path))


def test_npy_grids_bool_and_occupancy_values(tmp_path):
    grid = np.zeros((3, 4), dtype=bool)
    grid[0, 1] = True
    np.save(tmp_path / "g.npy", grid)
    w = load_world(str(tmp_path / "g.npy"))
    assert w.resolution_m == 0.05 and w.origin == (0.0, 0.0)
    assert w.occupancy[0, 1] and w.occupancy.sum() == 1  # row 0 is the bottom row
    values = np.array([[0, 10, 19, 20, 65, 66, 100, -1]], dtype=np.int8)
    np.save(tmp_path / "v.npy", values)
    w = load_world(str(tmp_path / "v.npy"))
    assert w.free[0].tolist() == [True, True, True, False, False, False, False, False]
    assert w.occupied[0].tolist() == [False] * 5 + [True, True, False]
    assert w.unknown[0].tolist() == [False] * 3 + [True, True, False, False, True]


def test_toml_world_over_a_npy_grid(tmp_path):
    np.save(tmp_path / "base.npy", np.zeros((10, 10), dtype=bool))
    (tmp_path / "w.toml").write_text(
        'grid = "base.npy"\nresolution_m = 0.1\norigin_m = [5.0, 5.0]\n'
        "[[circles]]\ncenter_m = [5.5, 5.5]\nradius_m = 0.15\n"
    )
    w = load_world(str(tmp_path / "w.toml"))
    assert w.origin == (5.0, 5.0) and w.occupancy.shape == (10, 10)
    assert w.occupancy[4:6, 4:6].all() and w.occupancy.sum() == 4


def test_builtin_names_and_errors():
    names = builtin_names()
    assert {"hallway", "office02", "random"} <= set(names)
    with pytest.raises(WorldError, match="unknown world"):
        load_world("no-such-world")
    with pytest.raises(WorldError, match="seed must be an integer"):
        load_world("random:abc")
    with pytest.raises(WorldError, match="grid file not found"):
        load_world("missing.npy")


def test_hallway_after_the_papers_figure_9():
    w = load_world("hallway")
    assert [a.name for a in w.areas] == ["A", "B", "C", "D"]
    assert w.start_pose is not None and w.goal is not None
    x0, y0, _ = w.start_pose
    assert not w.blocked_at(x0, y0) and not w.blocked_at(*w.goal)
    # Obstacles on alternating sides: in each area, blocked cells off the walls lie near the
    # right wall (low y) for A and C and near the left wall for B and D.
    inside = w.occupancy[5:-5, 5:-5]  # drop the walls (0.2 m + margin)
    ys = w.origin_y_m + (np.arange(w.rows)[5:-5] + 0.5) * w.resolution_m
    xs = w.origin_x_m + (np.arange(w.cols)[5:-5] + 0.5) * w.resolution_m
    mid = 0.5 * (w.areas[0].y_min_m + w.areas[0].y_max_m)
    for area, low in zip(w.areas, (True, False, True, False), strict=True):
        cols = (xs >= area.x_min_m) & (xs <= area.x_max_m)
        rows, _ = np.nonzero(inside[:, cols])
        assert rows.size > 0, area.name
        assert bool(ys[rows].mean() < mid) is low, area.name


def test_random_worlds_are_seeded_solvable_and_block_the_straight_line():
    a, b, c = random_world(7), random_world(7), random_world(8)
    assert np.array_equal(a.occupancy, b.occupancy) and a.start_pose == b.start_pose
    assert not np.array_equal(a.occupancy, c.occupancy)
    for seed in range(20):
        w = load_world(f"random:{seed}")
        assert w.name == f"random:{seed}"
        (sx, sy, yaw), (gx, gy) = w.start_pose, w.goal
        assert yaw == pytest.approx(math.atan2(gy - sy, gx - sx))
        # A disc of radius passage_m fits at start and goal and links them.
        clearance = ndimage.distance_transform_edt(~w.occupancy) * w.resolution_m
        labels, _ = ndimage.label(clearance >= RandomFieldParams().passage_m)
        start_id = labels[w.cell_of(sx, sy)]
        assert start_id and start_id == labels[w.cell_of(gx, gy)]
        # Something stands on the straight line from start to goal.
        t = np.linspace(0.0, 1.0, 400)
        assert any(w.blocked_at(sx + u * (gx - sx), sy + u * (gy - sy)) for u in t), seed
    assert load_world("random", seed=3).name == "random:3"


def test_the_world_id_names_the_map_frame_whatever_the_file():
    """DESIGN 15 ``map`` in the robot's info: the same grid is the same frame, wherever it was
    loaded from; another grid is another frame."""
    from egc_sim.grid_world import world_id

    names = builtin_names()
    a, b = load_world(names[0]), load_world(names[0])
    assert world_id(a) == world_id(b) and world_id(a).startswith("grid:")
    assert world_id(load_world(names[1])) != world_id(a)


def test_random_worlds_are_sized_for_a_large_robot():
    """A Husky (0.60 m of reach) could not turn where the default field starts it (7 mm from
    the wall at the worst of 30 seeds): its worlds are scaled so it keeps 0.15 m turning there.
    Robots up to 0.45 m of reach get the default worlds, cell for cell."""
    from egc_common.profiles import get_profile
    from egc_sim.collision import FootprintChecker

    assert RandomFieldParams.for_reach(0.3) == RandomFieldParams()
    for name in ("pioneer3dx", "jackal", "turtlebot4"):
        reach = get_profile(name).footprint.reach_m
        assert np.array_equal(
            load_world("random:3", reach_m=reach).occupancy, random_world(3).occupancy
        )
    husky = get_profile("husky")
    params = RandomFieldParams.for_reach(husky.footprint.reach_m)
    assert params.width_m > RandomFieldParams().width_m
    for seed in range(7000, 7030):
        world = load_world(f"random:{seed}", reach_m=husky.footprint.reach_m)
        x, y, _ = world.start_pose
        checker = FootprintChecker(world, husky.footprint)
        # every heading at the start: the robot can turn in place there
        turning = min(checker.clearance(x, y, a) for a in np.linspace(-math.pi, math.pi, 73))
        assert turning >= 0.1, (seed, turning)
