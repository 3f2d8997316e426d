"""The simulated robot: a differential-drive base with a lidar in a grid world.

``Simulator.step(v, w, dt)`` advances simulated time by ``dt``: the base follows the command
within the profile's limits (``drive``) on exact arcs, split into sub-steps short enough that no
point of the footprint moves more than half a cell between two collision checks. A sub-step
that would bring the footprint into contact with a blocked cell is cut, by bisection, at the
last pose with positive clearance; the robot stops there (``in_contact``, and ``collided`` from
then on). The robot never overlaps an obstacle, as a bumper-stopped real robot would not.

The exact collision check is skipped while it could change nothing: no point of the footprint
moves farther than (|v| + |w| reach) h in a sub-step of h seconds, so the clearance of the last
exact check, less the distance moved since, bounds the clearance from below; while that bound
stays above the running minimum there is neither contact nor a new minimum to record.

Time is passed in, never read: the same commands and seed give the same run. Poses are
(x_m, y_m, yaw_rad) in the world frame; twists (v_mps, w_radps) in {R}.
"""

from __future__ import annotations

import math

import numpy as np
from egc_common.kinematics import integrate_arc, wrap_angle
from egc_common.profiles import RobotProfile
from egc_common.scan import Scan

from egc_sim.collision import FootprintChecker
from egc_sim.drive import OdometryNoise, achievable_twist
from egc_sim.grid_world import Pose, World, WorldError
from egc_sim.lidar import Lidar, LidarConfig

_BISECTIONS = 12
# How far above the running minimum an exact check looks (m): the further, the more sub-steps
# its bound covers, and the more cells it examines.
_FLOOR_LOOKAHEAD_M = 0.25


class Simulator:
    """One robot (``profile``) in one ``world``; see the module docstring.

    ``start_pose`` defaults to the world's suggested start. ``seed`` seeds the lidar and
    odometry noise. Raises ``WorldError`` if the footprint does not fit at the start.
    """

    def __init__(
        self,
        world: World,
        profile: RobotProfile,
        start_pose: Pose | None = None,
        lidar: LidarConfig | None = None,
        seed: int = 0,
        odometry_noise: OdometryNoise | None = None,
        clearance_cap_m: float = 1.0,
    ) -> None:
        if start_pose is None:
            if world.start_pose is None:
                raise WorldError(f"world {world.name!r} suggests no start pose: give one")
            start_pose = world.start_pose
        x, y, yaw = (float(v) for v in start_pose)
        if not all(math.isfinite(v) for v in (x, y, yaw)):
            raise WorldError(f"start pose must be finite, got {start_pose}")
        self.world = world
        self.profile = profile
        self.lidar_config = lidar or LidarConfig()
        self.odometry_noise = odometry_noise or OdometryNoise()
        self._lidar = Lidar(world, self.lidar_config)
        self._footprint = FootprintChecker(world, profile.footprint, clearance_cap_m)
        self._rng = np.random.default_rng(seed)
        self._pose: Pose = (x, y, wrap_angle(yaw))
        clearance = self._footprint.clearance(*self._pose)
        if clearance <= 0.0:
            raise WorldError(
                f"start pose ({x:.3f}, {y:.3f}, {yaw:.3f}) puts the {profile.name} footprint "
                f"into an obstacle or outside the map"
            )
        self._odometry: Pose = self._pose
        self._twist = (0.0, 0.0)
        self._time_s = 0.0
        self._path_m = 0.0
        self._min_clearance_m = clearance
        self._clearance_floor_m = clearance  # a lower bound on the current pose's clearance
        self._collided = False
        self._in_contact = False
        self._max_substep_m = 0.5 * world.resolution_m

    # -- state ------------------------------------------------------------------------------

    @property
    def pose(self) -> Pose:
        """Ground-truth pose (x_m, y_m, yaw_rad)."""
        return self._pose

    @property
    def odometry(self) -> Pose:
        """Pose integrated from the (optionally noisy) wheel odometry, from the start pose."""
        return self._odometry

    @property
    def twist(self) -> tuple[float, float]:
        """Actual body velocity (v_mps, w_radps) after the base's limits and contacts."""
        return self._twist

    @property
    def time_s(self) -> float:
        return self._time_s

    @property
    def path_m(self) -> float:
        """Distance travelled by the robot's centre (arc length)."""
        return self._path_m

    @property
    def min_clearance_m(self) -> float:
        """Smallest footprint clearance so far; 0 once the robot has touched an obstacle."""
        return self._min_clearance_m

    @property
    def collided(self) -> bool:
        """Any contact so far."""
        return self._collided

    @property
    def in_contact(self) -> bool:
        """The last step was stopped by an obstacle."""
        return self._in_contact

    # -- simulation -------------------------------------------------------------------------

    def scan(self, stamp_ns: int = 0) -> Scan:
        """The lidar's scan from the current pose, in {R}."""
        return self._lidar.scan(self._pose, self._rng, stamp_ns)

    def step(self, v_cmd_mps: float, w_cmd_radps: float, dt_s: float) -> None:
        """Drive the command for ``dt_s`` seconds (module docstring)."""
        if not (math.isfinite(dt_s) and dt_s > 0.0):
            raise ValueError(f"dt must be a positive number of seconds, got {dt_s}")
        if not (math.isfinite(v_cmd_mps) and math.isfinite(w_cmd_radps)):
            raise ValueError(f"velocity command must be finite, got ({v_cmd_mps}, {w_cmd_radps})")
        p = self.profile
        v_bound = min(max(abs(v_cmd_mps), abs(self._twist[0])), p.v_max_mps)
        w_bound = min(max(abs(w_cmd_radps), abs(self._twist[1])), p.w_max_radps)
        reach = self._footprint.half_diagonal_m
        travel = (v_bound + w_bound * reach) * dt_s
        n = max(1, math.ceil(travel / self._max_substep_m))
        h = dt_s / n
        self._in_contact = False
        for _ in range(n):
            v, w = achievable_twist(v_cmd_mps, w_cmd_radps, self._twist, h, p)
            if v == 0.0 and w == 0.0:  # standing still: nothing moves, nothing to check
                self._twist = (0.0, 0.0)
                continue
            after = integrate_arc(self._pose, v, w, h)
            self._clearance_floor_m -= (abs(v) + abs(w) * reach) * h
            if self._clearance_floor_m > self._min_clearance_m:  # module docstring
                self._advance(after, v, w, h, self._clearance_floor_m)
                continue
            # Exact below ``below``, which is all that contact and the minimum need.
            below = self._min_clearance_m + _FLOOR_LOOKAHEAD_M
            clearance = self._footprint.clearance(*after, below=below)
            if clearance <= 0.0:
                self._stop_at_contact(v, w, h)
                break
            self._clearance_floor_m = min(clearance, below)
            self._advance(after, v, w, h, clearance)
        self._time_s += dt_s

    def _advance(self, pose: Pose, v: float, w: float, h: float, clearance: float) -> None:
        self._pose = pose
        self._twist = (v, w)
        self._path_m += abs(v) * h
        self._min_clearance_m = min(self._min_clearance_m, clearance)
        noise = self.odometry_noise
        if noise.enabled:
            v *= 1.0 + self._rng.normal(0.0, noise.linear_rel_std)
            w *= 1.0 + self._rng.normal(0.0, noise.angular_rel_std)
        self._odometry = integrate_arc(self._odometry, v, w, h)

    def _stop_at_contact(self, v: float, w: float, h: float) -> None:
        """Move to the last clear pose of this sub-step, then stand still in contact."""
        lo, hi = 0.0, 1.0
        clear_pose, clear_value = self._pose, self._min_clearance_m
        for _ in range(_BISECTIONS):
            mid = 0.5 * (lo + hi)
            pose = integrate_arc(self._pose, v, w, mid * h)
            value = self._footprint.clearance(*pose)
            if value > 0.0:
                lo, clear_pose, clear_value = mid, pose, value
            else:
                hi = mid
        if lo > 0.0:
            self._advance(clear_pose, v, w, lo * h, clear_value)
        self._twist = (0.0, 0.0)
        self._clearance_floor_m = -math.inf  # the next sub-step checks exactly
        self._in_contact = True
        self._collided = True
        self._min_clearance_m = 0.0
