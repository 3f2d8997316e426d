"""An operator model that drives by the predictive display (DESIGN 9): ``predictive_view``."""

from __future__ import annotations

import math

import numpy as np
import pytest
from egc_common.messages import Telemetry
from egc_common.profiles import PIONEER3DX
from egc_experiments.predictive_view import ghost_observation, reframe
from egc_experiments.simulated import CLOCK0_NS, OperatorSide
from egc_operator.prediction import CommandHistory, SentCommand, predict_from_telemetry
from egc_sim.grid_world import Pose
from egc_sim.observation import Observation
from egc_sim.operators import Stick, make_operator

MS = 1_000_000


def test_reframe_moves_the_points_into_the_ghosts_frame():
    points = np.array([[1.0, 0.0], [0.0, 2.0]])
    ahead = reframe(points, (0.0, 0.0, 0.0), (0.5, 0.0, 0.0))
    np.testing.assert_allclose(ahead, [[0.5, 0.0], [-0.5, 2.0]], atol=1e-12)
    turned = reframe(points, (0.0, 0.0, 0.0), (0.0, 0.0, math.pi / 2))
    np.testing.assert_allclose(turned, [[0.0, -1.0], [2.0, 0.0]], atol=1e-12)
    # Measured from a moved, turned robot: the world point (3, 1) seen from both poses.
    measured, ghost = (1.0, 1.0, math.pi / 2), (2.0, 0.0, math.pi)
    world = np.array([[3.0, 1.0]])
    in_measured = reframe(world, (0.0, 0.0, 0.0), measured)
    np.testing.assert_allclose(
        reframe(in_measured, measured, ghost), reframe(world, (0, 0, 0), ghost)
    )
    assert reframe(np.zeros((0, 2)), measured, ghost).shape == (0, 2)


def _telemetry(stamp_ns: int, pose: Pose | None, profile: str = "pioneer3dx") -> Telemetry:
    v = PIONEER3DX.v_max_mps
    return Telemetry(
        seq=1,
        stamp_ns=stamp_ns,
        state="DRIVING",
        mode="direct",
        v_ref=v,
        w_ref=0.0,
        v_cmd=v,
        w_cmd=0.0,
        w_si=0.0,
        pose=pose,
        profile=profile,
        cmd_age_p50_ms=100.0,
    )


def test_the_ghost_is_the_views_prediction_with_the_scan_around_it():
    stamp = 5_000 * MS
    tel = _telemetry(stamp, (1.0, 2.0, 0.0))
    history = CommandHistory()
    for k in range(40):  # full forward, every 20 ms, from 300 ms before the telemetry
        history.add(SentCommand(stamp - 300 * MS + k * 20 * MS, 1.0, 0.0, "direct"))
    now = stamp + 480 * MS
    obs = Observation(5.0, tel.pose, np.array([[2.0, 0.0]]), "DRIVING", "")
    ghost = ghost_observation(obs, tel, history, now)
    expected = predict_from_telemetry(tel, history.since(stamp - 100 * MS), now, None)
    assert expected is not None
    assert ghost.pose == pytest.approx(expected.pose)
    # Straight ahead at v_max for the view age (480 ms) plus the uplink (100 ms).
    assert ghost.pose[0] == pytest.approx(1.0 + PIONEER3DX.v_max_mps * 0.58, abs=1e-6)
    assert ghost.stamp_s == pytest.approx(5.58)
    np.testing.assert_allclose(ghost.scan_xy, [[2.0 - PIONEER3DX.v_max_mps * 0.58, 0.0]])
    assert (ghost.state, ghost.goal) == (obs.state, obs.goal)


def test_without_a_prediction_the_view_shows_the_measurement():
    history = CommandHistory()
    obs = Observation(5.0, None, np.zeros((0, 2)), "DRIVING", "")
    assert ghost_observation(obs, _telemetry(5 * 10**9, None), history, 6 * 10**9) is obs
    obs = Observation(5.0, (0.0, 0.0, 0.0), np.zeros((0, 2)), "DRIVING", "")
    unknown = _telemetry(5 * 10**9, (0.0, 0.0, 0.0), profile="no-such-robot")
    assert ghost_observation(obs, unknown, history, 6 * 10**9) is obs


class _Recording:
    """A model that records what it is shown."""

    def __init__(self, predictive: bool) -> None:
        self.params = type("P", (), {"reaction_s": 0.0, "predictive": predictive})()
        self.seen: list[Observation] = []

    def observe(self, t_s: float, observation: Observation) -> None:
        self.seen.append(observation)

    def command(self, t_s: float, pose: Pose) -> Stick:
        return Stick(1.0, 0.0, True, "direct")


@pytest.mark.parametrize("predictive", [False, True])
def test_the_operator_side_shows_a_predictive_model_the_ghost(predictive):
    model = _Recording(predictive)
    side = OperatorSide(model, "direct", (0.0, 0.0, 0.0))
    side.command(0)  # nothing seen yet: no ghost either
    assert model.seen == []
    tel = _telemetry(CLOCK0_NS + 20 * MS, (0.0, 0.0, 0.0))
    obs = Observation(0.02, tel.pose, np.array([[3.0, 0.0]]), "DRIVING", "")
    side.on_telemetry(0.1, obs, tel)
    side.command(120 * MS)
    if not predictive:
        assert model.seen == [obs]
        return
    assert len(model.seen) == 1
    ghost = model.seen[0]
    assert ghost.pose is not None and ghost.pose[0] > 0.0  # ahead of the measured pose
    assert ghost.scan_xy[0, 0] == pytest.approx(3.0 - ghost.pose[0])
    assert ghost.stamp_s > obs.stamp_s


def test_the_predictive_option_of_the_sighted_operator():
    model = make_operator("sighted:predictive=1", (5.0, 0.0), "direct")
    assert model.params.predictive is True  # type: ignore[attr-defined]
    assert make_operator("sighted", (5.0, 0.0), "direct").params.predictive is False  # type: ignore[attr-defined]
    with pytest.raises(ValueError, match="predictive must be 1 or 0"):
        make_operator("sighted:predictive=maybe", (5.0, 0.0), "direct")


def test_the_emulated_operator_shows_the_ghost_after_each_command_the_node_sends():
    from egc_experiments.operator_model import ModelDriver

    model = _Recording(True)
    driver = ModelDriver(OperatorSide(model, "direct", (0.0, 0.0, 0.0)))
    stamp = 7_000 * MS
    tel = _telemetry(stamp, (0.0, 0.0, 0.0))
    driver.on_telemetry(tel)
    history = CommandHistory()
    history.add(SentCommand(stamp + 40 * MS, 1.0, 0.0, "direct"))
    driver.on_commands(history, stamp + 40 * MS)
    driver.sample(0.0)
    assert len(model.seen) == 1
    ghost = model.seen[0]
    assert ghost.pose is not None and ghost.pose[0] > 0.0
    assert ghost.stamp_s == pytest.approx(7.14)  # + 40 ms since the stamp + 100 ms uplink
