"""The footprint geometry (DESIGN 14): polygons of any shape and discs, checked against brute
force on random shapes (hypothesis)."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from egc_common.footprint import (
    DISC_SIDES,
    Footprint,
    FootprintError,
    arc_samples,
    closest_boundary_points,
    contains,
    disc_cover,
    mitre_factor,
    mitred_outline,
    polygon_signed_distance,
    segments_cross_boxes,
    signed_distance,
    swept_min_distance,
    transform,
)
from egc_common.kinematics import signed_distance_to_rectangle
from hypothesis import given, settings
from hypothesis import strategies as st

# A pentagon with its nose forward and an L-shaped base (a robot with an arm bay cut out).
PENTAGON = Footprint.polygon([[0.4, 0.0], [0.1, 0.3], [-0.3, 0.3], [-0.3, -0.3], [0.1, -0.3]])
L_SHAPE = Footprint.polygon(
    [[0.3, 0.3], [-0.3, 0.3], [-0.3, -0.3], [0.0, -0.3], [0.0, 0.0], [0.3, 0.0]]
)


def boundary_samples(fp: Footprint, step_m: float) -> np.ndarray:
    """Points along the footprint's edge, ``step_m`` apart."""
    if fp.is_disc:
        a = np.linspace(0, 2 * math.pi, int(2 * math.pi * fp.radius_m / step_m), endpoint=False)
        return fp.radius_m * np.stack([np.cos(a), np.sin(a)], axis=1)
    xy = fp.vertices
    out = []
    for p, q in zip(xy, np.roll(xy, -1, axis=0), strict=True):
        n = max(2, int(np.hypot(*(q - p)) / step_m))
        t = np.linspace(0.0, 1.0, n, endpoint=False)[:, None]
        out.append(p + t * (q - p))
    return np.concatenate(out)


def star_polygon(radii: list[float], turn: float) -> Footprint:
    """A star-shaped (so simple) polygon: vertex k at angle 2 pi k / n + turn, radius r_k."""
    n = len(radii)
    a = turn + 2 * math.pi * np.arange(n) / n
    return Footprint.polygon(np.stack([radii * np.cos(a), radii * np.sin(a)], axis=1).tolist())


stars = st.builds(
    star_polygon,
    st.lists(st.floats(0.1, 0.8), min_size=3, max_size=12),
    st.floats(0.0, 2 * math.pi),
)
shapes = st.one_of(
    stars,
    st.builds(Footprint.disc, st.floats(0.05, 0.6)),
    st.builds(Footprint.rectangle, st.floats(0.1, 1.2), st.floats(0.1, 1.2)),
    st.sampled_from([PENTAGON, L_SHAPE]),
)


def test_pinned_rectangles_take_the_closed_form():
    fp = Footprint.rectangle(0.455, 0.381)
    assert fp.centred_box == (0.2275, 0.1905)
    assert (fp.length_m, fp.width_m, fp.half_size_m) == (0.455, 0.381, (0.2275, 0.1905))
    assert fp.reach_m == 0.5 * math.hypot(0.455, 0.381)
    rng = np.random.default_rng(0)
    x, y = rng.uniform(-1, 1, 500), rng.uniform(-1, 1, 500)
    np.testing.assert_array_equal(
        signed_distance(fp, x, y), signed_distance_to_rectangle(x, y, 0.2275, 0.1905)
    )
    # The general polygon code gives the same distances for it.
    np.testing.assert_allclose(
        polygon_signed_distance(fp.vertices, x, y),
        signed_distance_to_rectangle(x, y, 0.2275, 0.1905),
        atol=1e-12,
    )


def test_l_shape_notch_is_outside_and_pentagon_nose():
    # The notch of the L (x > 0, y < 0) is free space: 0.1 m from both inner edges.
    assert signed_distance(L_SHAPE, 0.1, -0.1) == pytest.approx(0.1)
    assert signed_distance(L_SHAPE, -0.1, -0.1) == pytest.approx(-0.1)
    assert not contains(L_SHAPE, 0.29, -0.29)  # inside its bounding box, outside the robot
    assert L_SHAPE.half_size_m == (0.3, 0.3)
    # The pentagon's nose reaches 0.4 m ahead; at y = 0.25 its front edge is far back.
    assert signed_distance(PENTAGON, 0.45, 0.0) == pytest.approx(0.05)
    assert contains(PENTAGON, 0.39, 0.0)
    assert not contains(PENTAGON, 0.3, 0.25)
    assert PENTAGON.length_m == pytest.approx(0.7)


def test_clockwise_vertices_are_stored_counter_clockwise():
    cw = Footprint.polygon(list(reversed(PENTAGON.vertices_m)))
    assert cw.area_m2 > 0
    assert set(cw.vertices_m) == set(PENTAGON.vertices_m)


@pytest.mark.parametrize(
    ("vertices", "problem"),
    [
        ([[0.3, 0.3], [-0.3, -0.3], [0.3, -0.3], [-0.3, 0.3]], "self-intersecting"),  # bow tie
        ([[0.3, 0.3], [0.3, 0.3], [-0.3, 0.3], [0, -0.3]], "repeats"),
        ([[0.0, 0.0], [0.5, 0.0], [1.0, 0.0]], "self-intersecting"),  # collinear: folds back
        ([[0.0, 0.0], [0.02, 0.0], [0.0, 0.02]], "too small"),
        ([[0.0, 0.0], [1.0, 0.05], [1.0, 0.0505]], "too small"),  # a sliver
        ([[0.0, 0.0], [1.0, 0.0]], "at least 3"),
        ([[0.0, 0.0], [1.0, 0.0], [1.0, math.nan]], "finite"),
        ([[0.0, 0.0], [1.0, 0.0], [1.0, "a"]], "numbers"),
        # An edge folding back along its neighbour (a spike).
        ([[0.0, 0.0], [0.5, 0.0], [0.2, 0.0], [0.0, 0.4]], "self-intersecting"),
    ],
)
def test_bad_polygons_say_why(vertices, problem):
    with pytest.raises(FootprintError, match=problem):
        Footprint.polygon(vertices)


@pytest.mark.parametrize("radius", [0.0, -0.2, 0.01, math.inf, 1e9])
def test_bad_discs(radius):
    with pytest.raises(FootprintError):
        Footprint.disc(radius)


@settings(max_examples=60, deadline=None)
@given(shapes, st.integers(0, 2**31 - 1))
def test_signed_distance_matches_brute_force(fp, seed):
    rng = np.random.default_rng(seed)
    reach = fp.reach_m
    pts = rng.uniform(-1.5 * reach, 1.5 * reach, (200, 2))
    got = signed_distance(fp, pts[:, 0], pts[:, 1])
    edge = boundary_samples(fp, 0.001)
    brute = np.sqrt(((pts[:, None, :] - edge[None, :, :]) ** 2).sum(axis=2)).min(axis=1)
    # The edge is sampled every millimetre: the true distance is at most that far below.
    assert np.all(np.abs(np.abs(got) - brute) <= 0.001)
    # The sign agrees with an independent inside test (winding angle).
    verts = fp.vertices
    rel = verts[None, :, :] - pts[:, None, :]
    ang = np.arctan2(rel[..., 1], rel[..., 0])
    winding = np.round(
        (np.mod(np.roll(ang, -1, axis=1) - ang + math.pi, 2 * math.pi) - math.pi).sum(axis=1)
        / (2 * math.pi)
    )
    inside = (winding != 0) if not fp.is_disc else (np.hypot(pts[:, 0], pts[:, 1]) < fp.radius_m)
    clear = brute > 1e-3  # away from the edge, where the sign is unambiguous
    assert np.array_equal((got < 0)[clear], inside[clear])


@settings(max_examples=60, deadline=None)
@given(shapes, st.integers(0, 2**31 - 1))
def test_closest_boundary_points_are_on_the_edge_at_the_distance(fp, seed):
    """The nearest boundary point lies on the edge, exactly |signed distance| away, and no
    sampled edge point is nearer (the cbf filter's q_i: its normals and b_i come from it)."""
    rng = np.random.default_rng(seed)
    reach = fp.reach_m
    pts = rng.uniform(-1.5 * reach, 1.5 * reach, (200, 2))
    qx, qy = closest_boundary_points(fp, pts[:, 0], pts[:, 1])
    assert np.all(np.abs(signed_distance(fp, qx, qy)) <= 1e-12)
    gap = np.hypot(pts[:, 0] - qx, pts[:, 1] - qy)
    assert np.allclose(gap, np.abs(signed_distance(fp, pts[:, 0], pts[:, 1])), atol=1e-12)
    edge = boundary_samples(fp, 0.001)
    brute = np.sqrt(((pts[:, None, :] - edge[None, :, :]) ** 2).sum(axis=2)).min(axis=1)
    assert np.all(gap <= brute + 1e-12)


@settings(max_examples=60, deadline=None)
@given(shapes, st.integers(1, 6), st.integers(0, 2**31 - 1))
def test_disc_cover_holds_the_footprint(fp, n, seed):
    centres, radii = disc_cover(fp, n)
    assert 1 <= len(radii) <= n
    corners = np.empty((0, 2)) if fp.is_disc else fp.vertices  # a disc's are circumscribed
    pts = np.concatenate([boundary_samples(fp, 0.005), corners])
    rng = np.random.default_rng(seed)
    box = rng.uniform(-fp.reach_m, fp.reach_m, (2000, 2))
    pts = np.concatenate([pts, box[contains(fp, box[:, 0], box[:, 1])]])
    d = np.hypot(pts[:, None, 0] - centres[None, :, 0], pts[:, None, 1] - centres[None, :, 1])
    assert np.all((d <= radii[None, :] + 1e-9).any(axis=1))


def test_disc_cover_of_a_rectangle_is_a_row_of_discs():
    centres, radii = disc_cover(Footprint.rectangle(0.9, 0.3), 3)
    np.testing.assert_allclose(centres, [[-0.3, 0.0], [0.0, 0.0], [0.3, 0.0]], atol=1e-12)
    np.testing.assert_allclose(radii, [math.hypot(0.15, 0.15)] * 3)


@settings(max_examples=60, deadline=None)
@given(shapes, st.floats(0.001, 0.05), st.integers(0, 2**31 - 1))
def test_mitred_outline_holds_the_grown_footprint(fp, grow, seed):
    outer = mitred_outline(fp, grow)
    rng = np.random.default_rng(seed)
    edge = boundary_samples(fp, 0.002)
    # Points within ``grow`` of the footprint's edge (and so of the footprint).
    a = rng.uniform(0, 2 * math.pi, len(edge))
    r = grow * np.sqrt(rng.uniform(0, 1, len(edge)))
    pts = edge + np.stack([r * np.cos(a), r * np.sin(a)], axis=1)
    assert np.all(polygon_signed_distance(outer, pts[:, 0], pts[:, 1]) <= 1e-9)
    # And nothing of it farther than mitre_factor * grow from the footprint.
    far = signed_distance(fp, outer[:, 0], outer[:, 1])
    if fp.is_disc:  # the circumscribed polygon of the grown disc
        bound = (fp.radius_m + grow) / math.cos(math.pi / DISC_SIDES) - fp.radius_m
    else:
        bound = mitre_factor(fp) * grow
    assert np.all(far <= bound + 1e-9)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**31 - 1))
def test_segments_cross_boxes_matches_sampling(seed):
    rng = np.random.default_rng(seed)
    a, b = rng.uniform(-1, 1, (20, 2)), rng.uniform(-1, 1, (20, 2))
    b[:3, 0] = a[:3, 0]  # vertical and horizontal segments too
    b[3:6, 1] = a[3:6, 1]
    centres, half = rng.uniform(-1, 1, (30, 2)), 0.1
    got = segments_cross_boxes(a, b, centres, half)
    t = np.linspace(0, 1, 4001)[None, :, None]
    pts = a[:, None, :] + t * (b - a)[:, None, :]  # (E, T, 2)
    # x and y apart: the same comparisons as one (E, T, M, 2) array, 4x faster without it
    near_x = np.abs(pts[:, :, None, 0] - centres[None, None, :, 0]) <= half
    near_y = np.abs(pts[:, :, None, 1] - centres[None, None, :, 1]) <= half
    sampled = (near_x & near_y).any(axis=1)
    assert np.all(got[sampled])  # every sampled hit is found
    # A miss by sampling that the test calls a hit must be a graze thinner than the sampling.
    for e, m in zip(*np.nonzero(got & ~sampled), strict=True):
        d = np.abs(pts[e, :, :] - centres[m]).max(axis=1).min()
        assert d <= half + np.hypot(*(b[e] - a[e])) / 4000


@settings(max_examples=40, deadline=None)
@given(
    shapes,
    st.floats(-2.0, 2.0),
    st.floats(-3.0, 3.0),
    st.floats(0.05, 2.0),
    st.integers(0, 2**31 - 1),
)
def test_the_swept_footprint_is_sampled_within_two_steps(fp, v, w, t_s, seed):
    """No footprint point moves more than 2 step_m between samples (the start pose included),
    so the sampled minimum distance, with the start's, is at most step_m above the true one
    (checked against a 50x finer sampling)."""
    step_m, step_rad = 0.02, 0.05
    x, y, th = arc_samples(v, w, t_s, step_m, step_rad, fp.reach_m)
    poses = np.column_stack([np.concatenate([[0.0], x]), np.concatenate([[0.0], y])])
    angles = np.concatenate([[0.0], th])
    corners = fp.vertices if not fp.is_disc else fp.vertices * math.cos(math.pi / DISC_SIDES)
    placed = [transform(corners, (px, py, a)) for (px, py), a in zip(poses, angles, strict=True)]
    for before, after in itertools.pairwise(placed):
        assert np.hypot(*(after - before).T).max() <= 2 * step_m + 1e-9
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-3.0, 3.0, (60, 2))
    # With the start pose's own distance (which the sweep knows: the clearance now), the true
    # minimum is at most step_m below the sampled one; fine is within step_m / 50 of the true.
    now = float(signed_distance(fp, pts[:, 0], pts[:, 1]).min())
    sampled = min(now, swept_min_distance(fp, pts, v, w, t_s, step_m, step_rad))
    fine = min(now, swept_min_distance(fp, pts, v, w, t_s, step_m / 50, step_rad / 50))
    assert fine - step_m / 50 - 1e-9 <= sampled <= fine + step_m + 1e-9
