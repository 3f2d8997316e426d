"""The network-delay operator models (DESIGN 10): ``sighted`` and ``route``."""

from __future__ import annotations

import math

import numpy as np
import pytest
from egc_experiments.episode import EpisodeSettings, run_settings
from egc_sim.grid_world import World
from egc_sim.observation import Observation, ViewBuffer
from egc_sim.operators import make_operator
from egc_sim.route import RouteError, RouteOperator, building_map, plan_route
from egc_sim.sighted import SightedOperator, SightedParams, free_distances
from egc_sim.worlds import load_world

OFFICE_START = (-7.0, -1.0, math.pi / 2)
OFFICE_GOAL = (-2.0, 3.6)


def test_view_buffer_acts_on_what_arrived_a_reaction_time_ago():
    view = ViewBuffer(0.25)
    assert view.seen(10.0) is None
    view.observe(1.0, Observation(0.9, (1.0, 0.0, 0.0)))
    view.observe(1.1, Observation(1.0, (2.0, 0.0, 0.0)))
    view.observe(1.2, Observation(0.95, (9.0, 0.0, 0.0)))  # overtaken: older stamp
    assert view.seen(1.2) is None
    first = view.seen(1.25)
    assert first is not None and first.pose == (1.0, 0.0, 0.0)
    latest = view.seen(2.0)
    assert latest is not None and latest.pose == (2.0, 0.0, 0.0)


def test_free_distances_see_a_wall_ahead_but_not_beside():
    wall = np.array([[1.0, y] for y in np.linspace(-0.5, 0.5, 21)])
    free = free_distances(wall, np.array([0.0, math.pi / 2, math.pi]), 0.3, 2.0)
    assert free[0] == pytest.approx(1.0)
    assert free[1] == 2.0 and free[2] == 2.0


def test_sighted_waits_for_the_view_and_steers_round_an_obstacle():
    op = SightedOperator((5.0, 0.0), "direct", params=SightedParams(noise_std=0.0))
    stick = op.command(0.0, (0.0, 0.0, 0.0))
    assert (stick.x_o, stick.y_o, stick.deadman) == (0.0, 0.0, True)
    # A box right ahead on the line to the goal: the operator turns away from it.
    box = np.array([[1.0, y] for y in np.linspace(-0.4, 0.4, 17)])
    op.observe(0.0, Observation(0.0, (0.0, 0.0, 0.0), box))
    stick = op.command(0.3, (0.0, 0.0, 0.0))
    assert abs(stick.y_o) > 0.1
    # Free way: straight at the goal.
    clear = SightedOperator((5.0, 0.0), "direct", params=SightedParams(noise_std=0.0))
    clear.observe(0.0, Observation(0.0, (0.0, 0.0, 0.0)))
    assert clear.command(0.3, (0.0, 0.0, 0.0)).y_o == pytest.approx(0.0)
    assert clear.command(0.3, (0.0, 0.0, 0.0)).x_o == pytest.approx(1.0)


def test_sighted_ignores_the_true_pose():
    op = SightedOperator((5.0, 0.0), "shared", params=SightedParams(noise_std=0.0))
    op.observe(0.0, Observation(0.0, (0.0, 0.0, 0.0)))
    assert op.command(1.0, (0.0, 0.0, 0.0)) == op.command(1.0, (3.0, 3.0, 2.0))


def test_sighted_noise_is_seeded():
    def sticks(seed: int) -> list[float]:
        op = SightedOperator((5.0, 0.0), "shared", seed=seed)
        op.observe(0.0, Observation(0.0, (0.0, 0.0, 0.0)))
        return [op.command(0.02 * i, (0.0, 0.0, 0.0)).y_o for i in range(50)]

    assert sticks(3) == sticks(3)
    assert sticks(3) != sticks(4)
    assert max(abs(v) for v in sticks(3)) < 0.3


def test_sighted_reaches_the_end_of_the_hallway_in_shared_mode():
    _, summary = run_settings(EpisodeSettings(map="hallway", operator="sighted", filter="egc"))
    assert summary["outcome"] == "reached"
    assert summary["interventions"] > 0  # the filter helped past the bins


def _outcomes(reaction_s: float) -> list[dict[str, float]]:
    out = []
    for world in ("random:1", "random:2"):
        _, s = run_settings(
            EpisodeSettings(
                map=world,
                operator=f"sighted:reaction_s={reaction_s}",
                filter="none",
                max_time_s=150,
            )
        )
        out.append(s)
    return out


def test_a_stale_view_makes_the_sighted_operator_worse():
    fresh, stale = _outcomes(0.25), _outcomes(2.0)
    assert all(s["outcome"] == "reached" for s in fresh)
    assert sum(s["time_s"] for s in stale) > 1.2 * sum(s["time_s"] for s in fresh)
    assert min(s["min_clearance_m"] for s in stale) < min(s["min_clearance_m"] for s in fresh)


def _toy_world() -> World:
    """6 m x 4 m room, a wall across x = 3 m with a gap near the top (y in [3, 3.6])."""
    occ = np.zeros((80, 120), dtype=bool)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = True
    occ[:60, 59:61] = True
    occ[72:, 59:61] = True
    return World("toy", occ, np.zeros_like(occ), 0.05, 0.0, 0.0)


def test_route_plans_through_the_gap_in_a_wall():
    world = _toy_world()
    route = plan_route(world.occupancy, 0.05, world.origin, (1.0, 1.0), (5.0, 1.0), 0.25)
    assert tuple(route[0]) == (1.0, 1.0) and tuple(route[-1]) == (5.0, 1.0)
    crossing = route[np.argmin(np.abs(route[:, 0] - 3.0))]
    assert 3.0 < crossing[1] < 3.6  # through the gap
    steps = np.hypot(*np.diff(route, axis=0).T)
    assert steps.max() < 0.08  # cell to neighbouring cell
    for x, y in route[1:-1]:
        assert not world.blocked_at(x, y)
    assert steps.sum() > 2 * math.hypot(2.0, 2.0)  # up to the gap and back down (straight: 4 m)


def test_route_without_a_way_raises():
    world = _toy_world()
    with pytest.raises(RouteError, match="no route"):
        plan_route(world.occupancy, 0.05, world.origin, (1.0, 1.0), (5.0, 1.0), 0.4)


def test_route_on_office02_goes_round_the_corner_and_follows_it():
    world = load_world("office02")
    op = RouteOperator.on_world(world, OFFICE_START, OFFICE_GOAL, 0.19, "direct")
    straight = math.dist(OFFICE_START[:2], OFFICE_GOAL)
    assert straight < op.length_m < 2 * straight
    # Seen at the start, pointing up the corridor: drive on, turning little.
    op.observe(0.0, Observation(0.0, OFFICE_START))
    stick = op.command(0.5, (0.0, 0.0, 0.0))
    assert stick.x_o > 0.8 and abs(stick.y_o) < 0.3
    _, summary = run_settings(
        EpisodeSettings(
            map="office02", start=OFFICE_START, goal=OFFICE_GOAL, operator="route", filter="none"
        )
    )
    assert summary["outcome"] == "reached"


def test_building_map_drops_furniture_and_keeps_walls():
    world = load_world("hallway")
    building = building_map(world.occupancy, world.resolution_m)
    assert world.blocked_at(3.5, 0.45)  # bin A
    row, col = world.cell_of(3.5, 0.45)
    assert not building[row, col]
    row, col = world.cell_of(5.0, -0.1)  # the wall
    assert building[row, col]
    # Planned on the room alone, the route runs into the obstacles: blind in direct mode.
    random_world = load_world("random:1")
    room = building_map(random_world.occupancy, random_world.resolution_m)
    assert room.sum() < random_world.occupancy.sum()
    _, summary = run_settings(
        EpisodeSettings(map="random:1", operator="route:map=building", filter="none")
    )
    assert summary["outcome"] == "collided"
    _, summary = run_settings(EpisodeSettings(map="random:1", operator="route", filter="none"))
    assert summary["outcome"] == "reached"


def test_make_operator_builds_and_rejects_the_models():
    world = _toy_world()
    op = make_operator("sighted:reaction_s=0.5,noise_std=0", (5.0, 1.0), "direct")
    assert isinstance(op, SightedOperator)
    assert op.params.reaction_s == 0.5 and op.params.noise_std == 0.0
    route = make_operator(
        "route:map=building", (5.0, 1.0), "direct", world=world, start=(1.0, 1.0, 0.0)
    )
    assert isinstance(route, RouteOperator)
    with pytest.raises(ValueError, match="needs a goal"):
        make_operator("sighted", None, "shared")
    with pytest.raises(ValueError, match="unknown option 'speed'"):
        make_operator("sighted:speed=2", (1.0, 1.0), "shared")
    with pytest.raises(ValueError, match="not a number"):
        make_operator("sighted:gain=fast", (1.0, 1.0), "shared")
    with pytest.raises(ValueError, match="map and the start"):
        make_operator("route", (1.0, 1.0), "shared")
    with pytest.raises(ValueError, match="full or building"):
        make_operator("route:map=other", (1.0, 1.0), "shared", world=world, start=(1, 1, 0))


def test_episode_cli_takes_the_models(capsys):
    from tests.cli_process import main

    assert (
        main(["episode", "--map", "random:2", "--operator", "route", "--filter", "none", "--json"])
        == 0
    )
    assert '"outcome": "reached"' in capsys.readouterr().out
    assert main(["episode", "--map", "hallway", "--operator", "sighted:bins=2", "--json"]) == 2
    assert "bins" in capsys.readouterr().err
