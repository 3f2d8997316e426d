"""Differential drive (exact arcs, limits, odometry) and collisions (exact clearance, contact)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from egc_common.footprint import Footprint
from egc_common.kinematics import wheel_speeds
from egc_common.profiles import JACKAL, PIONEER3DX
from egc_sim.collision import FootprintChecker
from egc_sim.drive import OdometryNoise, achievable_twist
from egc_sim.simulator import Simulator
from egc_sim.worlds import WorldError, load_world

from tests.sim.helpers import boxed_room, grid_world

# A base that reaches any commanded twist within one step, to test the kinematics alone.
INSTANT = PIONEER3DX.with_overrides(
    accel_max_mps2=1e9, decel_max_mps2=1e9, angular_accel_max_radps2=1e9
)


def open_room(size_m: float = 20.0):
    return grid_world(boxed_room(size_m, size_m), 0.05, (-size_m / 2, -size_m / 2))


@pytest.mark.parametrize(
    ("v", "w"), [(0.14, 0.5), (0.1, -0.3), (-0.12, 0.2), (0.13, 0.0), (0.0, 0.4)]
)
def test_constant_twist_follows_the_closed_form_arc(v, w):
    start = (0.3, -0.2, 0.7)
    sim = Simulator(open_room(), INSTANT, start)
    for _ in range(300):
        sim.step(v, w, 0.05)
    t = 15.0
    x0, y0, th0 = start
    if w == 0.0:
        expected = (x0 + v * t * math.cos(th0), y0 + v * t * math.sin(th0))
    else:
        r = v / w
        expected = (
            x0 + r * (math.sin(th0 + w * t) - math.sin(th0)),
            y0 - r * (math.cos(th0 + w * t) - math.cos(th0)),
        )
    x, y, th = sim.pose
    assert (x, y) == pytest.approx(expected, abs=1e-9)
    assert math.remainder(th - (th0 + w * t), 2 * math.pi) == pytest.approx(0.0, abs=1e-9)
    assert sim.path_m == pytest.approx(abs(v) * t, abs=1e-9)
    assert sim.time_s == pytest.approx(t)
    assert sim.odometry == sim.pose and sim.twist == pytest.approx((v, w))


def test_acceleration_and_velocity_limits_of_the_profile():
    p = PIONEER3DX
    v, w = achievable_twist(1.0, 2.0, (0.0, 0.0), 0.05, p)
    assert v == pytest.approx(p.accel_max_mps2 * 0.05)
    assert w == pytest.approx(p.angular_accel_max_radps2 * 0.05)
    v, w = achievable_twist(0.0, 0.0, (0.14, 0.5), 0.05, p)  # braking uses the deceleration
    assert v == pytest.approx(0.14 - p.decel_max_mps2 * 0.05)
    assert w == pytest.approx(0.5 - p.angular_accel_max_radps2 * 0.05)
    v, w = achievable_twist(5.0, -5.0, (0.14, -0.5), 0.05, p)  # clamped to v_max, w_max
    assert (v, w) == (p.v_max_mps, -p.w_max_radps)
    for profile in (PIONEER3DX, JACKAL):  # the body limits keep every wheel within its limit
        for vv, ww in ((9.0, 9.0), (-9.0, 9.0), (9.0, -9.0)):
            v, w = achievable_twist(vv, ww, (vv, ww), 1.0, profile)
            left, right = wheel_speeds(v, w, profile.wheel_base_m)
            assert max(abs(left), abs(right)) <= profile.wheel_speed_max_mps + 1e-12
    sim = Simulator(open_room(), p, (0.0, 0.0, 0.0))
    speeds = []
    for _ in range(20):
        sim.step(1.0, 0.0, 0.05)
        speeds.append(sim.twist[0])
    assert speeds[0] == pytest.approx(0.015) and speeds[-1] == pytest.approx(p.v_max_mps)
    assert np.all(np.diff(speeds) <= p.accel_max_mps2 * 0.05 + 1e-12)


def test_odometry_noise_is_seeded_and_drifts():
    noise = OdometryNoise(linear_rel_std=0.05, angular_rel_std=0.05)
    runs = []
    for seed in (1, 1, 2):
        sim = Simulator(open_room(), INSTANT, (0.0, 0.0, 0.0), seed=seed, odometry_noise=noise)
        for _ in range(100):
            sim.step(0.1, 0.2, 0.05)
        runs.append((sim.pose, sim.odometry))
    assert runs[0] == runs[1] and runs[0][1] != runs[2][1]
    assert runs[0][0] == runs[2][0]  # the true pose does not depend on the odometry noise
    assert runs[0][1] != pytest.approx(runs[0][0], abs=1e-6)
    with pytest.raises(ValueError):
        OdometryNoise(linear_rel_std=-1.0)


def _separating_axis_distance(rect: np.ndarray, square: np.ndarray) -> float:
    """Reference distance between two convex polygons (0 when they overlap)."""

    def overlap(a, b):
        for poly in (a, b):
            for i in range(len(poly)):
                edge = poly[(i + 1) % len(poly)] - poly[i]
                axis = np.array([-edge[1], edge[0]])
                pa, pb = a @ axis, b @ axis
                if pa.max() < pb.min() or pb.max() < pa.min():
                    return False
        return True

    if overlap(rect, square):
        return 0.0

    def point_segment(p, a, b):  # plain floats: this runs ~10^5 times
        (px, py), (ax, ay), (bx, by) = p, a, b
        ex, ey = bx - ax, by - ay
        t = min(1.0, max(0.0, ((px - ax) * ex + (py - ay) * ey) / (ex * ex + ey * ey)))
        return math.hypot(px - ax - t * ex, py - ay - t * ey)

    best = math.inf
    for poly, other in ((rect.tolist(), square.tolist()), (square.tolist(), rect.tolist())):
        for p in poly:
            for i in range(len(other)):
                best = min(best, point_segment(p, other[i], other[(i + 1) % len(other)]))
    return best


# Footprints as a union of convex parts in {R} (the reference below is for convex polygons).
_PENTAGON = [[0.35, 0.0], [0.15, 0.25], [-0.25, 0.25], [-0.25, -0.25], [0.15, -0.25]]
_L_PARTS = [
    [[0.3, 0.3], [-0.3, 0.3], [-0.3, 0.0], [0.3, 0.0]],
    [[0.0, 0.0], [-0.3, 0.0], [-0.3, -0.3], [0.0, -0.3]],
]
_L = [[0.3, 0.3], [-0.3, 0.3], [-0.3, -0.3], [0.0, -0.3], [0.0, 0.0], [0.3, 0.0]]
_SHAPES = {
    "pioneer3dx": (PIONEER3DX.footprint, [list(PIONEER3DX.footprint.vertices_m)]),
    "pentagon": (Footprint.polygon(_PENTAGON), [_PENTAGON]),
    "l-shape": (Footprint.polygon(_L), _L_PARTS),
    "disc": (Footprint.disc(0.2), None),
}


@pytest.mark.parametrize("shape", sorted(_SHAPES))
def test_clearance_is_exact_against_a_polygon_reference(shape):
    footprint, parts = _SHAPES[shape]
    world = load_world("random:5")
    checker = FootprintChecker(world, footprint)
    rng = np.random.default_rng(0)
    blocked = np.argwhere(world.occupancy)
    res = world.resolution_m
    checked = contacts = 0
    while checked < 25:
        x, y = rng.uniform(0.3, world.width_m - 0.3), rng.uniform(0.3, world.height_m - 0.3)
        yaw = rng.uniform(-math.pi, math.pi)
        got = checker.clearance(x, y, yaw)
        c, s = math.cos(yaw), math.sin(yaw)
        # The nearest square to the footprint is at most 2 reach + a cell farther from the
        # robot's centre than the square nearest the centre: only those need the reference.
        centre_d = np.hypot((blocked[:, 1] + 0.5) * res - x, (blocked[:, 0] + 0.5) * res - y)
        if centre_d.min() - footprint.reach_m - res > 1.0:
            assert got == 1.0  # nothing within the cap
            continue
        near = blocked[centre_d <= centre_d.min() + 2 * footprint.reach_m + res]
        squares = [
            np.array([[cc, rr], [cc + 1, rr], [cc + 1, rr + 1], [cc, rr + 1]], float) * res
            for rr, cc in near
        ]
        if parts is None:  # a disc: centre to square, minus the radius
            ref = min(
                (
                    math.hypot(
                        max(sq[0, 0] - x, 0.0, x - sq[1, 0]), max(sq[0, 1] - y, 0.0, y - sq[2, 1])
                    )
                    - footprint.radius_m
                    for sq in squares
                ),
                default=math.inf,
            )
        else:
            placed = [
                np.array([[x + c * u - s * v, y + s * u + c * v] for u, v in part])
                for part in parts
            ]
            ref = min(
                (_separating_axis_distance(p, sq) for p in placed for sq in squares),
                default=math.inf,
            )
        if ref >= 1.0:
            assert got == 1.0
            continue
        if ref <= 0.0:
            assert got <= 0.0
            contacts += 1
        else:
            assert got == pytest.approx(ref, abs=1e-9)
        checked += 1
    assert contacts < checked  # the draw measured clearances, not contacts only


def test_a_thin_part_across_a_cell_is_contact():
    """An edge of the footprint through a blocked cell with no vertex of either inside the
    other: the corner tests alone would miss it."""
    occupancy = np.zeros((20, 20), dtype=bool)
    occupancy[10, 10] = True  # the cell [1.0, 1.1] x [1.0, 1.1] at 0.1 m
    world = grid_world(occupancy, 0.1, (0.0, 0.0))
    # A body with a long arm 2 cm thick (a T on its side), its vertices far from the cell.
    arm = [[0.5, 0.01], [-0.4, 0.01], [-0.4, 0.1], [-0.5, 0.1], [-0.5, -0.1], [-0.4, -0.1]]
    bar = Footprint.polygon([*arm, [-0.4, -0.01], [0.5, -0.01]])
    checker = FootprintChecker(world, bar)
    assert checker.clearance(1.05, 1.05, 0.0) <= 0.0
    assert checker.clearance(1.05, 1.05, math.pi / 2) <= 0.0
    assert checker.clearance(1.05, 0.97, 0.0) == pytest.approx(0.02, abs=1e-9)


def test_driving_into_a_wall_stops_at_contact():
    world = grid_world(boxed_room(4.0, 2.0), 0.05, (0.0, 0.0))
    sim = Simulator(world, INSTANT, (1.0, 1.0, 0.0))
    assert sim.min_clearance_m == pytest.approx(1.0 - INSTANT.length_m / 2 - 0.05)  # the back wall
    for _ in range(400):
        sim.step(0.14, 0.0, 0.05)
    x, _, _ = sim.pose
    front_gap = (4.0 - 0.05) - (x + INSTANT.length_m / 2)  # to the wall's inner face
    assert sim.collided and sim.in_contact and sim.twist == (0.0, 0.0)
    assert 0.0 < front_gap < 1e-3  # stopped at the wall, never into it
    assert sim.min_clearance_m == 0.0
    sim.step(-0.1, 0.0, 0.05)  # backing away is free again
    assert not sim.in_contact and sim.collided and sim.pose[0] < x


def test_turning_in_place_next_to_a_wall_is_stopped_by_the_corner():
    world = grid_world(boxed_room(4.0, 2.0), 0.05, (0.0, 0.0))
    # Parallel to the bottom wall with 5 cm to spare: the front-right corner hits it on a turn.
    y = 0.05 + PIONEER3DX.width_m / 2 + 0.05
    sim = Simulator(world, INSTANT, (2.0, y, 0.0))
    for _ in range(100):
        sim.step(0.0, 0.5, 0.05)
    assert sim.collided and 0.0 < sim.pose[2] < 0.5


def test_bad_starts_and_steps():
    world = grid_world(boxed_room(4.0, 2.0), 0.05, (0.0, 0.0))
    with pytest.raises(WorldError, match="into an obstacle"):
        Simulator(world, PIONEER3DX, (0.1, 1.0, 0.0))
    with pytest.raises(WorldError, match="no start pose"):
        Simulator(world, PIONEER3DX)
    sim = Simulator(load_world("hallway"), PIONEER3DX)  # the world's own start
    assert sim.pose == (0.6, 0.6, 0.0)
    with pytest.raises(ValueError):
        sim.step(math.nan, 0.0, 0.05)
    with pytest.raises(ValueError):
        sim.step(0.1, 0.0, 0.0)
    with pytest.raises(TypeError, match="Footprint"):
        FootprintChecker(grid_world(boxed_room(40.0, 40.0), 1.0), 1.0)  # type: ignore[arg-type]


@pytest.mark.parametrize("profile_name", ["jackal", "husky"])
def test_skipped_collision_checks_change_nothing(profile_name, monkeypatch):
    """The clearance floor (module docstring) skips exact checks only where they could change
    nothing: the same drive with every sub-step checked exactly gives the same poses, the same
    running minimum after every step and the same contact, with far fewer exact checks."""
    from egc_common.profiles import get_profile
    from egc_sim import simulator as simulator_module

    profile = get_profile(profile_name)
    world = load_world("hallway")
    calls = {"n": 0}
    exact = FootprintChecker.clearance

    def counted(self, *args, **kwargs):
        calls["n"] += 1
        return exact(self, *args, **kwargs)

    monkeypatch.setattr(FootprintChecker, "clearance", counted)

    def drive() -> tuple[list, int]:
        """Wander (arcs; turning in place before walls, grazing them), then into a wall."""
        calls["n"] = 0
        rng = np.random.default_rng(1)
        sim = Simulator(world, profile, seed=3)
        trace = []
        for i in range(600):
            if i % 20 == 0:
                turn = rng.uniform(-0.5, 0.5) * profile.w_max_radps
            scan = sim.scan()
            front = float(scan.ranges_m[np.abs(scan.angles_rad) < 0.6].min())
            if i >= 500:
                v, w = profile.v_max_mps, 0.0
            elif front < 0.5 + profile.footprint.reach_m:
                v, w = 0.0, 0.7 * profile.w_max_radps
            else:
                v, w = 0.7 * profile.v_max_mps, turn
            sim.step(v, w, 0.05)
            trace.append((sim.pose, sim.min_clearance_m, sim.in_contact, sim.twist))
        return trace, calls["n"]

    with_floor, n_floor = drive()
    monkeypatch.setattr(simulator_module, "_FLOOR_LOOKAHEAD_M", 0.0)  # no sub-step skipped
    every_step, n_exact = drive()
    assert with_floor == every_step
    first_contact = next(i for i, row in enumerate(every_step) if row[2])
    assert every_step[first_contact - 1][1] < 0.05  # it grazed a wall before it hit one
    assert n_floor < 0.7 * n_exact
