"""The ``sighted`` operator model (DESIGN 10): drives by the operator view, as it arrives.

A person at the joystick who sees what the operator view shows, no more: the newest telemetry
that has arrived (``observation.Observation``: the scan in the robot frame, the pose, the
state), acted on after a reaction time (``reaction_s``, default 0.25 s, through
``observation.ViewBuffer``). The goal is known (it is drawn in the view). When the robot echoes
an active via point (``Observation.goal``, DESIGN 7), the view draws that one as the place to go
next, and the operator steers at it instead of the goal (issue 11: with via points planned
round the walls, the straight line at the final goal is no one's honest intention).

Each command:

1. take the observation seen at ``t - reaction_s``; none yet, or no pose in it: centred stick,
   deadman held (waiting for the view);
2. free distances: for ``bins`` directions around the robot, how far a corridor of half-width
   ``corridor_m`` (the robot's half-width plus a margin) runs from the robot's centre before it
   meets a scan point, capped at ``look_m``. A direction is *free* when that distance reaches
   ``min(look_m, distance to the goal)``;
3. choose the free direction nearest to the goal's bearing, with a small cost
   (``switch_cost`` per radian) for moving away from the direction chosen last time (in the
   world frame), so that the choice does not flicker between two gaps. With no free direction:
   the most open one;
4. stuck: when the seen robot has been DRIVING without moving (5 cm, 0.3 rad) for
   ``stuck_s``, the way it points is given up (taboo) for ``taboo_s``: directions within
   ``taboo_rad`` of it cost a full turn more, and for ``turn_s`` the stick only turns (no
   forward): the operator tries another gap, as a person does when the robot (or its filter)
   will not go where the stick says;
5. stick: turn y_o = clamp(gain * error / pi + noise), forward x_o = max(cos(error), 0), scaled
   down when the way straight ahead is short (``slow_m``: a person slows near an obstacle).
   ``noise`` is seeded steering noise, an Ornstein-Uhlenbeck process of standard deviation
   ``noise_std`` (stick units) and correlation time ``noise_tau_s``: a hand, not white noise.

All of it uses the *observed* pose and scan, i.e. the past: with a delayed view the operator
keeps turning after the robot already points the right way, as a real one does.

``predictive=1``: the operator drives by the predictive display's ghost (DESIGN 9) instead,
where the robot will be when the command now sent takes effect, with the scan drawn around it.
This model is the same; what it is shown changes, and the experiments build that
(``egc_experiments.predictive_view``, fed through ``observe``). In a plain episode (no link)
there is nothing to predict and the option changes nothing.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass

import numpy as np
from egc_common.joystick import clamp_unit
from egc_common.kinematics import wrap_angle

from egc_sim.grid_world import Pose
from egc_sim.observation import FloatArray, Observation, ViewBuffer
from egc_sim.operators import Stick, check_mode


@dataclass(frozen=True, slots=True)
class SightedParams:
    """Tuning of the sighted operator (module docstring); lengths in m, times in s."""

    reaction_s: float = 0.25
    noise_std: float = 0.05
    noise_tau_s: float = 0.5
    gain: float = 2.0
    corridor_m: float = 0.3
    comfort_m: float = 0.0
    look_m: float = 1.5
    slow_m: float = 0.8
    min_forward: float = 0.3
    predictive: bool = False  # shown the predictive display's ghost (module docstring)
    bins: int = 72
    switch_cost: float = 1.0
    stuck_s: float = 2.0
    taboo_s: float = 6.0
    taboo_rad: float = 0.8
    turn_s: float = 1.0

    def __post_init__(self) -> None:
        for name in ("reaction_s", "noise_std", "switch_cost", "comfort_m"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"sighted operator: {name} must be >= 0, got {value}")
        for name in (
            "noise_tau_s",
            "gain",
            "corridor_m",
            "look_m",
            "slow_m",
            "stuck_s",
            "taboo_s",
            "taboo_rad",
            "turn_s",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"sighted operator: {name} must be > 0, got {value}")
        if not 0 <= self.min_forward <= 1:
            raise ValueError("sighted operator: min_forward must be in [0, 1]")
        if not 8 <= self.bins <= 3600:
            raise ValueError("sighted operator: bins must be in [8, 3600]")


def free_distances(
    points_xy: FloatArray, angles_rad: FloatArray, corridor_m: float, look_m: float
) -> FloatArray:
    """For each direction, how far a corridor of half-width ``corridor_m`` is free (<= look_m).

    ``points_xy`` (N, 2) in {R}; a point blocks a direction when it lies ahead along it
    (projection > 0) within ``corridor_m`` of its centre line.
    """
    free = np.full(angles_rad.shape, look_m, dtype=np.float64)
    if len(points_xy) == 0:
        return free
    p = np.asarray(points_xy, dtype=np.float64)
    near = np.einsum("ij,ij->i", p, p) <= (look_m + corridor_m) ** 2
    p = p[near]
    if len(p) == 0:
        return free
    c, s = np.cos(angles_rad), np.sin(angles_rad)
    along = np.outer(p[:, 0], c) + np.outer(p[:, 1], s)
    lateral = np.abs(np.outer(p[:, 1], c) - np.outer(p[:, 0], s))
    blocked = (along > 0.0) & (lateral < corridor_m)
    hit = np.where(blocked, along, np.inf).min(axis=0)
    result: FloatArray = np.minimum(free, hit)
    return result


class SightedOperator:
    """Steers towards ``goal`` through the free direction nearest to it (module docstring)."""

    def __init__(
        self,
        goal: tuple[float, float],
        mode: str = "shared",
        seed: int = 0,
        params: SightedParams | None = None,
    ) -> None:
        self.goal = (float(goal[0]), float(goal[1]))
        self.mode = check_mode(mode)
        self.params = params or SightedParams()
        self.view = ViewBuffer(self.params.reaction_s)
        self._angles = np.linspace(-math.pi, math.pi, self.params.bins, endpoint=False)
        self._rng = random.Random(seed)
        self._noise = 0.0
        self._noise_t: float | None = None
        self._chosen_world: float | None = None
        self._anchor: tuple[float, Pose] | None = None  # (stamp, pose) when it last moved
        self._taboo: tuple[float, float] | None = None  # (world direction, until stamp)
        self._turn_until = -math.inf  # after being stuck: turn in place until this stamp

    def observe(self, t_s: float, observation: Observation) -> None:
        self.view.observe(t_s, observation)

    def _steering_noise(self, t_s: float) -> float:
        p = self.params
        if p.noise_std == 0:
            return 0.0
        if self._noise_t is None:
            self._noise = self._rng.gauss(0.0, p.noise_std)
        else:
            decay = math.exp(-max(t_s - self._noise_t, 0.0) / p.noise_tau_s)
            self._noise = self._noise * decay + p.noise_std * math.sqrt(
                1.0 - decay * decay
            ) * self._rng.gauss(0.0, 1.0)
        self._noise_t = t_s
        return self._noise

    def command(self, t_s: float, pose: Pose) -> Stick:
        """The stick at ``t_s``; ``pose`` (the simulator's truth) is not used."""
        noise = self._steering_noise(t_s)
        obs = self.view.seen(t_s)
        if obs is None or obs.pose is None:
            return Stick(0.0, 0.0, True, self.mode)
        self._check_stuck(obs)
        error, ahead = self.choose(obs)
        p = self.params
        forward = max(math.cos(error), 0.0) * min(1.0, max(p.min_forward, ahead / p.slow_m))
        if obs.stamp_s < self._turn_until:
            forward = 0.0
        return Stick(
            clamp_unit(forward), clamp_unit(p.gain * error / math.pi + noise), True, self.mode
        )

    def _check_stuck(self, obs: Observation) -> None:
        """A robot that does not move while driving: give up the way it points (taboo)."""
        assert obs.pose is not None
        p = self.params
        anchor = self._anchor
        if obs.state != "DRIVING" or anchor is None:
            self._anchor = (obs.stamp_s, obs.pose)
            return
        (x0, y0, yaw0), (x, y, yaw) = anchor[1], obs.pose
        if math.hypot(x - x0, y - y0) > 0.05 or abs(wrap_angle(yaw - yaw0)) > 0.3:
            self._anchor = (obs.stamp_s, obs.pose)
        elif obs.stamp_s - anchor[0] >= p.stuck_s:
            direction = yaw if self._chosen_world is None else self._chosen_world
            self._taboo = (direction, obs.stamp_s + p.taboo_s)
            self._turn_until = obs.stamp_s + p.turn_s
            self._anchor = (obs.stamp_s, obs.pose)

    def choose(self, obs: Observation) -> tuple[float, float]:
        """(heading error of the chosen direction in rad, free distance straight ahead in m)."""
        assert obs.pose is not None
        p = self.params
        x, y, yaw = obs.pose
        target = self.goal if obs.goal is None else obs.goal
        dx, dy = target[0] - x, target[1] - y
        distance = math.hypot(dx, dy)
        bearing = wrap_angle(math.atan2(dy, dx) - yaw)
        need = min(p.look_m, distance)
        angles = self._angles
        free = free_distances(obs.scan_xy, angles, p.corridor_m + p.comfort_m, p.look_m)
        candidates = free >= need - 1e-9
        if not candidates.any():  # no comfortable way: the tight ones
            free = free_distances(obs.scan_xy, angles, p.corridor_m, p.look_m)
            candidates = free >= need - 1e-9
        if candidates.any():
            cost = np.abs(np.angle(np.exp(1j * (angles - bearing))))
            if self._chosen_world is not None:
                away = np.abs(np.angle(np.exp(1j * (angles + yaw - self._chosen_world))))
                cost = cost + p.switch_cost * away
            if self._taboo is not None and obs.stamp_s < self._taboo[1]:
                off = np.abs(np.angle(np.exp(1j * (angles + yaw - self._taboo[0]))))
                cost = cost + np.where(off < p.taboo_rad, 2 * math.pi, 0.0)
            cost = np.where(candidates, cost, np.inf)
            # A free direction within a bin of the goal's bearing: steer at the goal itself.
            best = int(np.argmin(cost))
            chosen = float(angles[best])
            if abs(wrap_angle(chosen - bearing)) <= 2 * math.pi / p.bins:
                chosen = bearing
        else:
            chosen = float(angles[int(np.argmax(free))])
        self._chosen_world = wrap_angle(chosen + yaw)
        ahead = float(free_distances(obs.scan_xy, np.zeros(1), p.corridor_m, p.look_m)[0])
        return wrap_angle(chosen), ahead
