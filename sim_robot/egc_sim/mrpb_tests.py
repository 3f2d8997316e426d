"""The start/goal tests that MRPB ships beside its maps (``tests.txt``).

Each test is a block of roslaunch ``<arg>`` lines::

    # Test 1
    <arg name="initial_pose_x" default="-12.547"/>
    ...
    <arg name="goal_pose_a" default="0.000"/>

A test is complete when all six values (initial and goal x, y, a) have been given; it ends at
its ``goal_pose_a``. Incomplete blocks are skipped. Poses are in the map frame (m, rad).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

TESTS_FILE = "tests.txt"

_ARG_RE = re.compile(r'name="(initial|goal)_pose_([xya])"\s+default="([-+0-9.eE]+)"')


@dataclass(frozen=True, slots=True)
class MrpbTest:
    start_pose: tuple[float, float, float]  # x_m, y_m, yaw_rad
    goal_pose: tuple[float, float, float]

    @property
    def goal_xy_m(self) -> tuple[float, float]:
        return self.goal_pose[0], self.goal_pose[1]


def parse_tests(text: str) -> list[MrpbTest]:
    """Every complete test in ``text``, in file order (finite values only)."""
    tests = []
    values: dict[tuple[str, str], float] = {}
    for kind, axis, raw in _ARG_RE.findall(text):
        try:
            value = float(raw)
        except ValueError:  # e.g. "1.2.3": that test is incomplete
            value = math.nan
        if math.isfinite(value):
            values[(kind, axis)] = value
        if (kind, axis) != ("goal", "a"):
            continue
        block, values = values, {}
        if len(block) == 6:
            tests.append(MrpbTest(_pose(block, "initial"), _pose(block, "goal")))
    return tests


def _pose(values: dict[tuple[str, str], float], kind: str) -> tuple[float, float, float]:
    return values[(kind, "x")], values[(kind, "y")], values[(kind, "a")]


def read_tests_beside(map_yaml: Path) -> list[MrpbTest]:
    """The tests in ``tests.txt`` next to a map's YAML; none when there is no readable file."""
    path = Path(map_yaml).parent / TESTS_FILE
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError:
        return []
    return parse_tests(text)
