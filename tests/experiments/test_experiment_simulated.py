"""Simulated mode (DESIGN 10): the real controller, the operator model and the link model."""

from __future__ import annotations

import dataclasses

import pytest
from egc_experiments.run_point import RESULT_KEYS, RunPoint
from egc_experiments.simulated import run_simulated

WORLD = "random:2"


def point(**kw) -> RunPoint:
    base = {"world": WORLD, "operator": "sighted", "filter": "none", "mode": "direct"}
    return RunPoint(**{**base, **kw})


def without_wall(result: dict) -> dict:
    return {k: v for k, v in result.items() if k != "wall_s"}


def test_a_run_has_every_pinned_key_and_reaches_the_goal():
    r = run_simulated(point())
    assert set(RESULT_KEYS) <= set(r)
    assert r["outcome"] == "reached" and r["reached"] and not r["collided"]
    assert r["hold_s"] == 0 and r["stale_rejected"] == 0 and r["interventions"] == 0
    assert r["cmd_age_p50_ms"] == 0 and r["mean_speed_mps"] == pytest.approx(
        r["path_m"] / r["time_s"], abs=1e-3
    )


def test_a_seed_gives_the_same_run():
    p = point(transport="udp", delay_ms=80, jitter_ms=25, loss=5, burst=3, seed=3, max_time_s=20)
    first, second = run_simulated(p), run_simulated(p)
    assert without_wall(first) == without_wall(second)
    assert first["commands_lost"] > 0
    other = run_simulated(dataclasses.replace(p, seed=4))
    assert without_wall(other) != without_wall(first)


def test_commands_older_than_direct_mode_allows_never_drive():
    r = run_simulated(point(delay_ms=500, max_time_s=10, stall_time_s=5))
    assert r["outcome"] == "stalled" and r["path_m"] == 0
    assert r["stale_rejected"] > 100 and r["hold_s"] > 4


def test_link_aware_driving_resumes_after_an_outage_and_caps_the_speed():
    # One second without a link, 3 s into the run; in shared mode.
    kw = {"filter": "egc", "mode": "shared", "delay_ms": 100, "max_time_s": 8}
    on = run_simulated(point(outages=((3.0, 1.0),), link_aware=True, **kw))
    off = run_simulated(point(outages=((3.0, 1.0),), link_aware=False, **kw))
    assert 0 < on["hold_s"] < off["hold_s"]  # no re-centring round trip when link-aware
    assert on["stale_rejected"] > 0  # TCP held the commands back; late, they are too old
    udp = run_simulated(point(outages=((3.0, 1.0),), transport="udp", link_aware=True, **kw))
    assert udp["commands_lost"] > 0 and udp["stale_rejected"] == 0
    # In direct mode a 100 ms link puts tau near 0.5 s: the governor caps the speed.
    direct = run_simulated(point(delay_ms=100, max_time_s=8))
    assert direct["latency_limited_s"] > 0 and direct["max_speed_mps"] < 0.13
    unaware = run_simulated(point(delay_ms=100, max_time_s=8, link_aware=False))
    assert unaware["latency_limited_s"] == 0 and unaware["max_speed_mps"] == pytest.approx(0.14)


@pytest.mark.parametrize("operator", ["goal", "forward", "route"])
def test_other_operators_run(operator):
    r = run_simulated(point(operator=operator, max_time_s=5))
    assert r["outcome"] in ("timeout", "collided", "reached") and r["path_m"] > 0.1


def test_a_collision_records_the_speed_at_contact():
    # The blind `goal` operator steers the Jackal straight at the goal, into a wall.
    r = run_simulated(point(world="hallway", operator="goal", profile="jackal", max_time_s=30))
    assert r["outcome"] == "collided"
    assert r["contact_speed_mps"] > 0.5 and r["contact_turn_radps"] is not None
    clean = run_simulated(point())
    assert clean["outcome"] == "reached" and clean["contact_speed_mps"] is None
