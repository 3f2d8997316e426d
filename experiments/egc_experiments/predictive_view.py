"""The predictive display (DESIGN 9) as an operator model sees it: the ghost, not the past.

The operator view draws, besides the newest telemetry (the robot as it was a view age ago), a
ghost footprint where the robot will be when the command now being sent takes effect
(``egc_operator.prediction``). An operator model that drives by the predictive display
(``sighted:predictive=1``) acts on what the ghost shows: the ghost's pose, and the scan of the
newest telemetry drawn around it (the obstacles stay where they were measured in the world; the
ghost moves among them). ``ghost_observation`` builds that frame from the same telemetry, the
same command history and the same ``predict_from_history`` as the operator process's view.

The frame's ``stamp_s`` is the ghost's time (when the command takes effect), on the clock of the
telemetry's own ``stamp_s``: a newer ghost of the same telemetry is a newer frame. Pure: the time
is passed in.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from egc_common.messages import Telemetry
from egc_operator.prediction import CommandHistory, predict_from_history
from egc_sim.observation import Observation

NS_PER_S = 1_000_000_000


def ghost_observation(
    observation: Observation,
    telemetry: Telemetry,
    history: CommandHistory,
    now_ns: int,
    rtt_ms: float | None = None,
) -> Observation:
    """``observation`` (made from ``telemetry``) as the predictive display shows it at ``now_ns``.

    ``now_ns`` is on the robot's clock, like the history's stamps and ``telemetry.stamp_ns``.
    Without a prediction (no pose, unknown profile) the observation is returned unchanged: the
    view then shows only the measured robot.
    """
    prediction = predict_from_history(telemetry, history, now_ns, rtt_ms)
    if prediction is None or observation.pose is None:
        return observation
    return replace(
        observation,
        stamp_s=observation.stamp_s + (prediction.end_ns - telemetry.stamp_ns) / NS_PER_S,
        pose=prediction.pose,
        scan_xy=reframe(observation.scan_xy, observation.pose, prediction.pose),
    )


def reframe(
    points_xy: np.ndarray, measured: tuple[float, float, float], ghost: tuple[float, float, float]
) -> np.ndarray:
    """Points in the frame of the robot at ``measured``, in the frame of the robot at ``ghost``."""
    p = np.asarray(points_xy, dtype=np.float64).reshape(-1, 2)
    x0, y0, a0 = measured
    x1, y1, a1 = ghost
    c0, s0 = math.cos(a0), math.sin(a0)
    wx = x0 + c0 * p[:, 0] - s0 * p[:, 1] - x1
    wy = y0 + s0 * p[:, 0] + c0 * p[:, 1] - y1
    c1, s1 = math.cos(a1), math.sin(a1)
    return np.column_stack((c1 * wx + s1 * wy, -s1 * wx + c1 * wy))
