"""Issue 11 must-show: an operator who steers hard into an obstacle and holds the stick steady
gets the assistant's override (the paper's "the operator knows better"), and the pipeline's
footprint sweep still keeps the robot off the obstacle. Real pipeline, real simulator."""

from __future__ import annotations

from egc_common.profiles import get_profile
from egc_experiments.episode import PipelineController
from egc_robot.pipeline import PipelineConfig
from egc_sim.episodes import run_episode
from egc_sim.operators import ForwardOperator
from egc_sim.simulator import Simulator

from tests.sim.helpers import boxed_room, grid_world


def test_steady_stick_into_a_wall_gets_the_override_and_never_touches() -> None:
    profile = get_profile("pioneer3dx")
    occ = boxed_room(6.0, 4.0)
    occ[:, 80] = True  # a wall across the room 4.0 m from its left side
    world = grid_world(occ)
    sim = Simulator(world, profile, (1.0, 2.0, 0.0), seed=0)
    config = PipelineConfig(profile, filter="assist", no_return_is_free=True)
    controller = PipelineController(config, lambda: sim.pose)  # no via point: stick + avoidance
    rules: list[str] = []
    limiters: list[str] = []
    xs: list[float] = []

    def observe(row: object, scan: object) -> None:
        r = controller.last_result
        xs.append(sim.pose[0])
        if r is not None and r.family is not None:
            rules.append(r.family.reason)
            limiters.append(r.limiter.value)

    result = run_episode(
        sim,
        ForwardOperator("shared", 1.0),  # full stick straight at the wall, never moving
        controller,
        goal=(50.0, 2.0),  # unreachable: the run ends on time
        goal_tolerance_m=0.1,
        max_time_s=40.0,
        observer=observe,  # type: ignore[arg-type]
    )
    assert result.outcome == "timeout"
    assert "avoid-front" in rules  # the rules acted first ...
    assert "override" in rules  # ... then the steady stick won
    assert not sim.collided
    # It got close, the operator's way, and the sweep (not the rules) stopped it there.
    assert max(xs) > 4.0 - 0.5 * profile.length_m - 0.6
    assert "sweep" in limiters
    # Held still by the sweep, the override yields: the rules drive again (the stick has not
    # moved, so the override does not come back), and the robot is not left at the wall.
    last_override = len(rules) - 1 - rules[::-1].index("override")
    assert last_override < len(rules) - 100
    assert "override" not in rules[last_override + 1 :]
    assert 0.0 < result.min_clearance_m < 0.5
    assert result.min_clearance_m < 0.1  # measured 0.03 m: right up to it, not into it
