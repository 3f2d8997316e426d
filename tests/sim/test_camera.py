"""The simulator's forward camera (DESIGN 12): closed-form wall heights, the lidar's ranges, and
what changes when the robot moves or turns."""

from __future__ import annotations

import math

import numpy as np
import pytest
from egc_sim.camera import (
    INSIDE,
    CameraModel,
    CameraRenderer,
    cast_columns,
    render_camera,
)
from egc_sim.lidar import Raycaster
from egc_sim.worlds import load_world

from tests.sim.helpers import grid_world

RES = 0.05


def wall_ahead_world():
    """Free for x < 3 m, a wall from x = 3 m on; y in [-5, 5)."""
    occ = np.zeros((200, 100), dtype=bool)  # origin (0, -5)
    occ[:, 60:] = True
    return grid_world(occ, RES, (0.0, -5.0))


MODEL = CameraModel(width_px=320, height_px=240, hfov_rad=math.radians(90.0), height_m=0.4)


def wall_rows(image: np.ndarray, column: int) -> np.ndarray:
    """Rows of ``column`` that show the wall (its colour has more red than blue; sky, haze and
    floor are grey or blue)."""
    px = image[:, column].astype(int)
    return np.flatnonzero(px[:, 0] - px[:, 2] > 20)


def test_a_wall_straight_ahead_fills_the_centre_columns_at_its_closed_form_height():
    image = render_camera(wall_ahead_world(), (1.0, 0.0, 0.0), MODEL)
    assert image.shape == (240, 320, 3) and image.dtype == np.uint8
    f = MODEL.focal_px  # 160 px for 320 px across 90 degrees
    depth = 2.0
    bottom = 120 + f * MODEL.height_m / depth  # 152: rows whose centre lies above it
    top = 120 - f * (MODEL.wall_height_m - MODEL.height_m) / depth  # -8: clipped at 0
    for column in (140, 159, 160, 180):
        rows = wall_rows(image, column)
        assert rows.min() == max(0, math.ceil(top - 0.5))
        assert rows.max() == math.ceil(bottom - 0.5) - 1
        assert np.all(np.diff(rows) == 1)
    # A flat wall is at the same depth in every column (no fisheye): the same bottom edge.
    bottoms = {int(wall_rows(image, c).max()) for c in range(0, 320, 16)}
    assert len(bottoms) == 1


def test_nearer_is_taller_and_brighter():
    near = render_camera(wall_ahead_world(), (2.0, 0.0, 0.0), MODEL)  # 1 m away
    far = render_camera(wall_ahead_world(), (0.5, 0.0, 0.0), MODEL)  # 2.5 m away
    near_rows, far_rows = wall_rows(near, 160), wall_rows(far, 160)
    assert near_rows.size > far_rows.size
    assert near[near_rows, 160].mean() > far[far_rows, 160].mean()


def test_the_sky_is_above_the_horizon_and_the_floor_below_it():
    # Facing into open space along the corridor of a wide world: sky at the top, floor at the
    # bottom of the centre column, nothing of a wall in between far away.
    occ = np.zeros((400, 2000), dtype=bool)  # 100 m x 20 m
    world = grid_world(occ, RES, (0.0, -10.0))
    image = render_camera(world, (1.0, 0.0, 0.0), MODEL)
    top, bottom = image[0, 160].astype(int), image[-1, 160].astype(int)
    assert top[2] > top[0] + 30  # blue sky
    assert abs(bottom[0] - bottom[2]) < 15  # grey floor


def test_driving_forward_moves_the_floor_and_turning_moves_the_wall():
    world = wall_ahead_world()
    a = render_camera(world, (1.0, 0.3, 0.0), MODEL)
    b = render_camera(world, (1.5, 0.3, 0.0), MODEL)  # half a floor square further
    assert not np.array_equal(a[200:], b[200:])  # the floor's squares moved
    np.testing.assert_array_equal(a[:40, :, 2] > a[:40, :, 0], b[:40, :, 2] > b[:40, :, 0])
    # Turned 30 degrees left: the wall's near edge column (the ray along world +x) is now
    # right of the centre, where the pinhole puts a ray at -30 degrees.
    turned = render_camera(world, (1.0, 0.0, math.radians(30.0)), MODEL)
    column = int(160 + MODEL.focal_px * math.tan(math.radians(30.0)))
    rows = wall_rows(turned, column)
    depth = 2.0 * math.cos(math.radians(30.0))  # along the optical axis
    assert rows.max() == math.ceil(120 + MODEL.focal_px * MODEL.height_m / depth - 0.5) - 1


@pytest.mark.parametrize("pose_index", range(4))
def test_each_column_sees_what_the_lidar_sees_on_a_real_map(pose_index):
    world = load_world("office02")
    caster = Raycaster(world)
    rng = np.random.default_rng(pose_index)
    free = np.argwhere(world.free)
    row, col = free[rng.integers(free.shape[0])]
    x = world.origin_x_m + (col + 0.5) * world.resolution_m
    y = world.origin_y_m + (row + 0.5) * world.resolution_m
    yaw = float(rng.uniform(-math.pi, math.pi))
    slopes = MODEL.column_offsets()
    hits = cast_columns(caster, (x, y, yaw), slopes, 8.0)
    angles = np.arctan(slopes)
    for c in range(0, slopes.size, 7):  # the lidar casts one beam at a time here
        expected = caster.cast(x, y, yaw, float(angles[c]), 0.0, 1, 8.0)[0]
        got = hits.depth_m[c] / math.cos(angles[c])  # depth -> range along the ray
        if math.isinf(expected):
            assert math.isinf(hits.depth_m[c])
        else:
            assert got == pytest.approx(expected, abs=1e-9)


def test_inside_an_obstacle_the_camera_sees_nothing():
    image = render_camera(wall_ahead_world(), (4.0, 0.0, 0.0), MODEL)
    assert np.all(image == INSIDE.astype(np.uint8))


def test_odd_sizes_and_a_renderer_reused_for_many_poses():
    model = CameraModel(width_px=161, height_px=121, hfov_rad=1.2)
    renderer = CameraRenderer(load_world("hallway"), model)
    first = renderer.render((0.6, 0.6, 0.0))
    for k in range(5):
        image = renderer.render((0.6 + 0.1 * k, 0.6, 0.05 * k))
        assert image.shape == (121, 161, 3)
    assert np.array_equal(first, renderer.render((0.6, 0.6, 0.0)))  # pure


@pytest.mark.parametrize(
    "changes",
    [{"width_px": 1}, {"hfov_rad": 0.0}, {"hfov_rad": math.pi}, {"height_m": 3.0}],
)
def test_bad_models_are_refused(changes):
    with pytest.raises(ValueError):
        CameraModel(**changes)
