"""Lidar ranges against closed-form geometry, a brute-force march, noise and no-return."""

from __future__ import annotations

import math

import numpy as np
import pytest
from egc_sim.lidar import Lidar, LidarConfig, Raycaster
from egc_sim.worlds import load_world

from tests.sim.helpers import grid_world

RES = 0.05


def wall_ahead_world():
    """Free for x < 3 m, a wall for x in [3, 3.5) m; 2 m high strip, nothing else."""
    occ = np.zeros((80, 70), dtype=bool)  # origin (0, -2): y in [-2, 2)
    occ[:, 60:] = True
    return grid_world(occ, RES, (0.0, -2.0))


def test_wall_ahead_matches_closed_form():
    caster = Raycaster(wall_ahead_world())
    x, yaw = 1.23, 0.0
    angles = np.linspace(-0.5, 0.5, 21)  # all of these hit the wall face x = 3
    ranges = caster.cast(x, 0.1, yaw, float(angles[0]), float(angles[1] - angles[0]), 21, 10.0)
    expected = (3.0 - x) / np.cos(angles)
    assert np.max(np.abs(ranges - expected)) < 1e-9  # exact, far within one cell


def test_wall_ahead_from_a_rotated_robot_and_range_max():
    caster = Raycaster(wall_ahead_world())
    # Robot facing +y, its beam at -pi/2 looks along world +x.
    r = caster.cast(0.5, 0.0, math.pi / 2, -math.pi / 2, 0.0, 1, 10.0)
    assert r[0] == pytest.approx(2.5, abs=1e-9)
    assert math.isinf(caster.cast(0.5, 0.0, 0.0, 0.0, 0.0, 1, 2.0)[0])  # beyond range_max


def circular_room(radius_m: float):
    n = int(2 * radius_m / RES) + 8
    c = (np.arange(n) + 0.5) * RES - n * RES / 2
    gx, gy = np.meshgrid(c, c)
    return grid_world(np.hypot(gx, gy) > radius_m, RES, (-n * RES / 2, -n * RES / 2))


@pytest.mark.parametrize("pose", [(0.0, 0.0, 0.0), (0.7, -0.4, 1.0), (-1.1, 0.3, -2.5)])
def test_circular_room_within_one_cell(pose):
    radius = 2.0
    lidar = Lidar(circular_room(radius), LidarConfig(beams=360, range_max_m=10.0))
    scan = lidar.scan(pose, np.random.default_rng(0))
    x, y, yaw = pose
    theta = yaw + scan.angles_rad
    # Distance from (x, y) along theta to the circle |p| = R.
    b = x * np.cos(theta) + y * np.sin(theta)
    expected = -b + np.sqrt(b * b - (x * x + y * y - radius * radius))
    assert np.max(np.abs(scan.ranges_m - expected)) <= RES


def _march(world, x, y, theta, range_max, step=2e-4):
    """Reference: walk the ray in tiny steps until it enters a blocked cell."""
    t = np.arange(0.0, range_max, step)
    rows = np.floor((y + t * math.sin(theta) - world.origin_y_m) / world.resolution_m).astype(int)
    cols = np.floor((x + t * math.cos(theta) - world.origin_x_m) / world.resolution_m).astype(int)
    inside = (rows >= 0) & (rows < world.rows) & (cols >= 0) & (cols < world.cols)
    hit = ~inside
    hit[inside] = world.occupancy[rows[inside], cols[inside]]
    i = int(np.argmax(hit))
    return float(t[i]) if hit[i] else math.inf


@pytest.mark.parametrize("beams,fov", [(360, 2 * math.pi), (61, 2.0), (7, 0.3)])
def test_matches_a_brute_force_march_on_a_real_map(beams, fov):
    world = load_world("office02")
    config = LidarConfig(beams=beams, fov_rad=fov, range_max_m=6.0)
    caster = Raycaster(world)
    rng = np.random.default_rng(beams)
    free = np.argwhere(world.free)
    for _ in range(3):
        r, c = free[rng.integers(len(free))]
        x = world.origin_x_m + (c + rng.random()) * RES
        y = world.origin_y_m + (r + rng.random()) * RES
        yaw = rng.uniform(-math.pi, math.pi)
        got = caster.cast(x, y, yaw, config.angle_min_rad, config.angle_increment_rad, beams, 6.0)
        for i in range(0, beams, max(1, beams // 40)):
            theta = yaw + config.angle_min_rad + i * config.angle_increment_rad
            ref = _march(world, x, y, theta, 6.0)
            if math.isinf(ref):
                assert math.isinf(got[i]) or got[i] > 6.0 - 2e-4
            else:
                assert got[i] == pytest.approx(ref, abs=3e-4), (x, y, theta)


def test_scan_layout_noise_and_no_return():
    world = wall_ahead_world()
    cfg = LidarConfig(beams=4, range_max_m=5.0)
    assert (cfg.angle_min_rad, cfg.angle_increment_rad) == (-math.pi, math.pi / 2)
    half = LidarConfig(beams=5, fov_rad=math.pi)
    assert half.angle_min_rad == -math.pi / 2 and half.angle_increment_rad == math.pi / 4
    rng = np.random.default_rng(1)
    scan = Lidar(world, cfg).scan((1.0, 0.0, 0.0), rng, stamp_ns=42)
    # Beams at -pi, -pi/2, 0, pi/2: the back beam hits the grid's edge (outside blocks) at 1 m,
    # the side beams the grid's edge at 2 m, the front beam the wall at 2 m.
    assert scan.ranges_m.tolist() == pytest.approx([1.0, 2.0, 2.0, 2.0])
    assert scan.stamp_ns == 42 and scan.no_return_is_free
    far = Lidar(world, LidarConfig(beams=4, range_max_m=1.5)).scan((1.0, 0.0, 0.0), rng)
    assert far.ranges_m[1:].tolist() == [math.inf] * 3
    plus_one = LidarConfig(beams=4, range_max_m=1.5, no_return="range_max_plus_one")
    assert Lidar(world, plus_one).scan((1.0, 0.0, 0.0), rng).ranges_m[1:].tolist() == [2.5] * 3
    noisy = Lidar(world, LidarConfig(beams=360, noise_std_m=0.01, range_max_m=5.0))
    clean = Lidar(world, LidarConfig(beams=360, range_max_m=5.0)).scan((1.0, 0.0, 0.3), rng)
    errors = noisy.scan((1.0, 0.0, 0.3), np.random.default_rng(5)).ranges_m - clean.ranges_m
    assert 0.008 < float(np.std(errors)) < 0.012 and abs(float(np.mean(errors))) < 0.002


def test_sensor_inside_an_obstacle_reads_zero():
    world = wall_ahead_world()
    assert Raycaster(world).cast(3.2, 0.0, 0.0, -1.0, 0.5, 5, 5.0).tolist() == [0.0] * 5


def test_bad_configs_are_rejected():
    for kwargs in (
        {"beams": 0},
        {"fov_rad": 7.0},
        {"range_min_m": 2.0, "range_max_m": 1.0},
        {"noise_std_m": -0.1},
        {"no_return": "nan"},
    ):
        with pytest.raises(ValueError):
            LidarConfig(**kwargs)
