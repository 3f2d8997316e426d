"""MRPB's tests.txt: parsed into start/goal tests, and the first one a map's suggestion."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
from egc_common.profiles import PIONEER3DX
from egc_sim.mrpb_tests import MrpbTest, parse_tests, read_tests_beside
from egc_sim.simulator import Simulator
from egc_sim.worlds import load_world

from tests.sim.helpers import MRPB, write_map_yaml


def _block(number: int, start: tuple[str, str, str], goal: tuple[str, str, str]) -> str:
    lines = [f"# Test {number}"]
    for kind, values in (("initial", start), ("goal", goal)):
        for axis, value in zip("xya", values, strict=True):
            lines.append(f'<arg name="{kind}_pose_{axis}" default="{value}"/>')
    return "\n".join(lines) + "\n\n"


def test_parses_every_complete_test_in_order():
    text = _block(1, ("-1.5", "2", "0.0"), ("3e0", "-4.25", "3.142")) + _block(
        2, ("7", "8", "-1.571"), ("9", "10", "0")
    )
    assert parse_tests(text) == [
        MrpbTest((-1.5, 2.0, 0.0), (3.0, -4.25, 3.142)),
        MrpbTest((7.0, 8.0, -1.571), (9.0, 10.0, 0.0)),
    ]
    assert parse_tests(text)[0].goal_xy_m == (3.0, -4.25)


@pytest.mark.parametrize(
    "broken",
    [
        _block(1, ("1", "2", "0"), ("3", "4", "0")).replace('"initial_pose_y"', '"other_y"'),
        _block(1, ("1", "nan", "0"), ("3", "4", "0")),
        _block(1, ("1", "2", "0"), ("3", "1.2.3", "0")),
        _block(1, ("1", "2", "0"), ("inf", "4", "0")),
    ],
)
def test_an_incomplete_test_is_skipped_and_the_next_one_kept(broken):
    good = _block(2, ("5", "6", "0"), ("7", "8", "0"))
    assert parse_tests(broken + good) == [MrpbTest((5.0, 6.0, 0.0), (7.0, 8.0, 0.0))]


def test_no_file_or_no_tests_means_no_suggestion(tmp_path):
    yaml_path = write_map_yaml(tmp_path, np.full((20, 20), 254, dtype=np.uint8))
    assert read_tests_beside(yaml_path) == []
    world = load_world(str(yaml_path))
    assert world.start_pose is None and world.goal is None
    (tmp_path / "tests.txt").write_text("# nothing here\n")
    assert load_world(str(yaml_path)).start_pose is None


def test_a_map_with_tests_beside_it_suggests_the_first(tmp_path):
    yaml_path = write_map_yaml(tmp_path, np.full((40, 40), 254, dtype=np.uint8))
    (tmp_path / "tests.txt").write_text(
        _block(1, ("1.0", "0.5", "1.571"), ("1.5", "1.8", "0"))
        + _block(2, ("0", "0", "0"), ("1", "1", "0"))
    )
    world = load_world(str(yaml_path))
    assert world.start_pose == (1.0, 0.5, 1.571) and world.goal == (1.5, 1.8)
    assert Simulator(world, PIONEER3DX).pose == pytest.approx((1.0, 0.5, 1.571))


@pytest.mark.skipif(not MRPB.is_dir(), reason=f"MRPB maps not found at {MRPB}")
def test_every_mrpb_map_starts_where_its_first_test_does(tmp_path):
    maps = sorted(p.parent for p in MRPB.glob("*/tests.txt"))
    assert len(maps) >= 5
    for folder in maps:
        world = load_world(str(folder / "map.yaml"))
        first = parse_tests((folder / "tests.txt").read_text())[0]
        assert world.start_pose == first.start_pose and world.goal == first.goal_xy_m
        Simulator(world, PIONEER3DX)  # the footprint fits there
    shipped = load_world("office02")
    assert shipped.start_pose == (-12.547, 8.542, 0.0) and shipped.goal == (13.059, 1.702)
    # Without its tests.txt the same map suggests nothing.
    copy = tmp_path / "office02"
    shutil.copytree(MRPB / "office02", copy)
    (copy / "tests.txt").unlink()
    assert load_world(str(copy / "map.yaml")).start_pose is None
