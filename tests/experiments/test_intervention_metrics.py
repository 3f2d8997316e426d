"""DESIGN 13's metrics over a run (``egc_robot.intervention``), and where they are reported: the
episode JSON, the simulated experiment's runs and the arena's tables."""

from __future__ import annotations

import math

import numpy as np
import pytest
from egc_common.profiles import JACKAL
from egc_common.scan import obstacle_points
from egc_experiments.arena import outcome_table
from egc_experiments.episode import EpisodeSettings, run_settings
from egc_experiments.run_point import RunPoint
from egc_experiments.simulated import run_simulated
from egc_robot.intervention import InterventionTally
from egc_robot.pipeline import PipelineConfig, filter_velocity

# A wall 0.1 m ahead of the Jackal's bumper, inside cbf's 0.12 m margin: it holds the robot.
WALL = obstacle_points(np.column_stack((np.full(81, 0.354), np.linspace(-2, 2, 81))))
OPEN = obstacle_points([[8.0, 8.0]])


def cycle(config: PipelineConfig, v: float, previous: tuple[float, float], pts, mode="shared"):
    return filter_velocity(config, v, 0.0, mode, pts, previous, 0.05)


def test_the_tally_counts_what_the_filter_changed_not_the_ramp():
    config = PipelineConfig(JACKAL, filter="cbf")
    tally = InterventionTally(JACKAL.v_max_mps, JACKAL.w_max_radps)
    previous = (0.0, 0.0)
    for _ in range(10):  # speeding up in the open: the base ramps, nothing is cut
        r = cycle(config, 1.0, previous, OPEN)
        assert r.plain == (r.v_cmd_mps, r.w_cmd_radps)
        tally.add(r, 0.05)
        previous = (r.v_cmd_mps, r.w_cmd_radps)
    assert tally.as_dict() == {
        "commands": 10, "changed": 0, "changed_share": 0.0, "mean_cut": 0.0, "hold_s": 0.0,
    }  # fmt: skip
    for _ in range(10):  # the wall: braking at the base's limit, then held
        r = cycle(config, 1.0, previous, WALL)
        tally.add(r, 0.05)
        previous = (r.v_cmd_mps, r.w_cmd_radps)
    d = tally.as_dict()
    assert d["commands"] == 20 and 5 <= d["changed"] <= 10
    assert d["changed_share"] == pytest.approx(d["changed"] / 20)
    assert d["hold_s"] > 0.0 and 0.0 < d["mean_cut"] <= 2.0


def test_direct_mode_changes_nothing():
    config = PipelineConfig(JACKAL, filter="cbf")
    tally = InterventionTally(JACKAL.v_max_mps, JACKAL.w_max_radps)
    previous = (0.0, 0.0)
    for _ in range(20):
        r = cycle(config, 1.0, previous, WALL, mode="direct")
        tally.add(r, 0.05)
        previous = (r.v_cmd_mps, r.w_cmd_radps)
    assert tally.changed == 0 and tally.hold_s == 0.0 and tally.commands == 20


def test_the_episode_json_carries_the_metrics():
    settings = EpisodeSettings(
        map="random:0", operator="goal", filter="cbf", profile="jackal", max_time_s=20.0
    )
    _, summary = run_settings(settings)
    for key in ("commands", "changed", "changed_share", "mean_cut", "hold_s"):
        assert key in summary, key
    assert summary["commands"] > 0
    assert summary["changed_share"] == pytest.approx(summary["changed"] / summary["commands"])
    assert summary["hold_s"] <= summary["time_s"]


def test_the_arena_table_shows_them_and_copes_with_older_records():
    base = {"operator": "goal", "filter": "cbf", "outcome": "reached", "time_s": 10.0,
            "path_m": 5.0, "interventions": 3}  # fmt: skip
    records = [
        {**base, "commands": 100, "changed": 5, "mean_cut": 0.02, "hold_s": 1.0},
        {**base, "commands": 300, "changed": 3, "mean_cut": 0.01, "hold_s": 3.0},
        base,  # from before DESIGN 13: left out of the three columns
    ]
    header, _, row = outcome_table(records, ["cbf"], ["goal"])
    assert header.endswith("| changed share | mean cut | hold s / episode |")
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[-3:] == ["0.020", f"{(0.02 * 100 + 0.01 * 300) / 400:.3f}", "2.0"]
    older = outcome_table([base], ["cbf"], ["goal"])[2]
    assert older.rstrip(" |").endswith("– | – | –")
    assert math.isfinite(float(cells[-1]))


def test_a_simulated_experiment_run_carries_the_metrics():
    """``egc-teleop experiment`` (simulated): DESIGN 13's metrics beside DESIGN 10's keys;
    DESIGN 13's hold_s is ``filter_hold_s`` there (DESIGN 10 pins ``hold_s`` for HOLD)."""
    p = RunPoint(world="random:3", operator="sighted", filter="cbf", mode="shared",
                 profile="jackal", seed=0, max_time_s=15.0)  # fmt: skip
    r = run_simulated(p)
    for key in ("filter_commands", "changed", "changed_share", "mean_cut", "filter_hold_s"):
        assert key in r, key
    assert r["filter_commands"] > 0 and 0.0 <= r["changed_share"] <= 1.0
    assert "hold_s" in r  # DESIGN 10's, unchanged
