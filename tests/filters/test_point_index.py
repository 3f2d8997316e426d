"""The scan's point index (issue 9: the command path without numpy) changes no result.

``ObstaclePoints.index`` is built per scan in the driver's receiving thread; EGC's
nearest-point queries and the footprint sweep's reach test then use it. Every result must be
the very one of the numpy path: same floats, same nearest point on ties, same branch.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from egc_common.profiles import JACKAL, PIONEER3DX
from egc_common.scan import Scan, obstacle_points
from egc_robot.filters import egc as egc_mod
from egc_robot.filters.egc import EgcParams, _nearest, _nearest_indexed, egc_filter
from egc_robot.safety import SweepParams, sweep_scale
from hypothesis import given, settings
from hypothesis import strategies as st

P3DX = EgcParams.from_profile(PIONEER3DX.r_min_m, PIONEER3DX.r_max_m, PIONEER3DX.v_max_mps)
JACKAL_P = EgcParams.from_profile(JACKAL.r_min_m, JACKAL.r_max_m, JACKAL.v_max_mps)

coords = st.floats(-3.0, 3.0, allow_nan=False)
# Coarse coordinates make ties (equal distances, repeated points) common.
grid_coords = st.integers(-12, 12).map(lambda i: i * 0.125)
point_lists = st.lists(st.tuples(coords, coords), min_size=1, max_size=120) | st.lists(
    st.tuples(grid_coords, grid_coords), min_size=1, max_size=120
)


def both(points):
    """The same points without an index (numpy path) and with one."""
    plain = obstacle_points(np.asarray(points, dtype=np.float64))
    indexed = obstacle_points(np.asarray(points, dtype=np.float64))
    indexed.index()
    assert plain.prepared_index is None and indexed.prepared_index is not None
    return plain, indexed


@settings(max_examples=400)
@given(point_lists, coords, coords, st.floats(0.01, 4.0))
def test_indexed_nearest_is_numpy_nearest(points, cx, cy, limit):
    _, obstacles = both(points)
    found = _nearest_indexed(obstacles.prepared_index, (cx, cy), limit)
    expected = _nearest(obstacles.x, obstacles.y, (cx, cy))
    if found is None:  # gave up: the caller asks numpy
        return
    if expected[0] < limit:
        assert found == expected
    else:
        assert found == (math.inf, -1)


@settings(max_examples=400)
@given(
    point_lists,
    st.floats(-0.14, 0.14, allow_nan=False),
    st.floats(-0.6, 0.6, allow_nan=False),
)
def test_egc_filter_same_result_with_the_index(points, v, w):
    plain, indexed = both(points)
    assert egc_filter(v, w, indexed, P3DX) == egc_filter(v, w, plain, P3DX)


@settings(max_examples=200)
@given(
    point_lists,
    st.floats(-2.0, 2.0, allow_nan=False),
    st.floats(-2.0, 2.0, allow_nan=False),
)
def test_egc_filter_same_result_with_the_index_jackal(points, v, w):
    plain, indexed = both(points)
    assert egc_filter(v, w, indexed, JACKAL_P) == egc_filter(v, w, plain, JACKAL_P)


@settings(max_examples=300)
@given(
    point_lists,
    st.floats(-0.14, 0.14, allow_nan=False),
    st.floats(-0.6, 0.6, allow_nan=False),
)
def test_sweep_scale_same_result_with_the_index(points, v, w):
    plain, indexed = both(points)
    params = SweepParams()
    expected = sweep_scale(v, w, plain, PIONEER3DX, params)
    assert sweep_scale(v, w, indexed, PIONEER3DX, params) == expected


def _corridor(box_m: float) -> Scan:
    a = np.linspace(-math.pi, math.pi, 720, endpoint=False)
    with np.errstate(divide="ignore"):
        r = np.where(np.sin(a) != 0, 1.2 / np.abs(np.sin(a)), np.inf)
    box = np.abs(a + 0.08) < 0.15
    r[box] = np.minimum(r[box], box_m / np.maximum(np.cos(a[box]), 1e-3))
    return Scan(a, np.minimum(r, 12.0), 0.05, 10.0)


@pytest.mark.parametrize("box_m", [0.3, 0.5, 0.75, 1.5, 5.0])
def test_corridor_scans_every_command(box_m):
    """The bench's scene and others, over the whole stick: identical results, and the index
    answers without numpy where something is near."""
    scan = _corridor(box_m)
    plain = obstacle_points(scan.obstacles().xy.copy())
    indexed = scan.obstacles()
    indexed.index()
    for x in np.linspace(-1.0, 1.0, 21):
        for y in np.linspace(-1.0, 1.0, 21):
            v, w = x * PIONEER3DX.v_max_mps, y * PIONEER3DX.w_max_radps
            assert egc_filter(v, w, indexed, P3DX) == egc_filter(v, w, plain, P3DX)
            params = SweepParams()
            assert sweep_scale(v, w, indexed, PIONEER3DX, params) == sweep_scale(
                v, w, plain, PIONEER3DX, params
            )


def test_the_bench_command_needs_no_numpy(monkeypatch):
    """The bench's command (half forward, a little left, box 0.75 m ahead): all three
    nearest-point queries come from the index."""
    scan = _corridor(0.75)
    obstacles = scan.obstacles()
    obstacles.index()

    def no_numpy(*args):
        raise AssertionError("numpy path taken")

    monkeypatch.setattr(egc_mod, "_nearest", no_numpy)
    res = egc_filter(0.5 * PIONEER3DX.v_max_mps, 0.2 * PIONEER3DX.w_max_radps, obstacles, P3DX)
    assert res.modified
