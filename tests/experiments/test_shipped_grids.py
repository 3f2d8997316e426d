"""Every grid shipped in experiments/grids/ loads and names only things that exist.

The committed reports were made from these files by the command in their headers; a grid that
no longer parses (a renamed option, world or filter) would make those commands fail for a user.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from egc_experiments.experiment_cli import check_point
from egc_experiments.grid import load_grid

GRIDS = sorted((Path(__file__).resolve().parents[2] / "experiments" / "grids").glob("*.toml"))


def test_the_grids_are_there():
    names = {p.name for p in GRIDS}
    assert {"quick.toml", "delay-sweep.toml", "predictive-jackal.toml"} <= names


@pytest.mark.parametrize("path", GRIDS, ids=[p.stem for p in GRIDS])
def test_a_shipped_grid_loads_and_checks(path):
    grid = load_grid(path, check_point)
    assert grid.points
