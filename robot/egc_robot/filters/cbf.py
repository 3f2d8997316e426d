"""Control barrier function safety filter, ``cbf`` (DESIGN 13).

A minimal-intervention filter: the command closest to the operator's that keeps every obstacle
point's barrier, and the operator's command itself, unchanged to the bit, whenever it keeps them.
``cbf_filter`` is a pure function: command (v, w) after eq. 4, scan points in {R}, the current
velocity, the loop delay tau (DESIGN 9), the profile and ``CbfParams`` in; a frozen ``CbfResult``
with its intermediates out.

**Barriers.** For each obstacle point p_i (the scan's points, plus the edges of what the laser saw
along {R}'s x axis: DESIGN 5.10, ``ObstaclePoints.seen_ahead_m`` / ``seen_behind_m``, a point
beyond which nothing is known to be free):

- sd_i: the signed distance from the footprint as given (DESIGN 14: the profile's polygon or
  disc; an axis-aligned rectangle centred on {R}, the Pioneer's and the Jackal's, in closed form)
  to p_i, and n_i its unit gradient: from the footprint's nearest boundary point q_i towards p_i
  (for a point inside the footprint, from p_i towards q_i: outwards). The exact shape, no disc
  cover: its distances are exact, so no margin is lost to a cover's bulges.
- A rigid motion (v, w) moves a fixed point of the world at (-v + w y, -w x) in {R}, so
  d sd_i / dt = -(n_x v - b_i w) with b_i = n_x q_y - n_y q_x: exactly linear in (v, w) (no
  linearisation: the gradient of the distance to a set is n wherever q_i is unique). The
  footprint *approaches* p_i at u_i(v, w) = n_x v - b_i w (m/s); |b_i| <= |q_i| <= the
  footprint's reach.
- The barrier is h_i = sd_i - m_i with the margin m_i = ``margin_m`` + omega_i K u_i: a fixed
  margin, plus the distance the footprint closes on p_i during the loop delay, the control
  period and the stop, K = tau + P + T / 2 with P = ``period_s`` (a command holds until the
  next cycle) and T = max(|v| / a_dec, |w| / alpha_dec) the braking time at the profile's
  limits (``safety.stopping_time_s``' model: straight towards a wall
  K u = v (tau + P) + v^2 / (2 a_dec), the delay's and the period's distance plus the braking
  distance). omega_i in [0, 1] says how squarely p_i lies in
  the footprint's path: (cos of the angle between n_i and the velocity of q_i)^4, 1 straight
  ahead, falling off quickly for points the robot passes. A point the robot passes is never
  reached by the motion (its distance shrinks only to the lateral gap), so the stopping distance
  is not owed to it: with omega = 1 for every point a Jackal at 0.8 m/s could not pass a wall at
  0.2 m (the careful drives of DESIGN 13) whatever alpha; with the 4th power it passes at the
  default alpha and margin.
- Condition, per point: dh_i/dt >= -alpha h_i with the margin held for the cycle, i.e.
  u_i(v, w) <= alpha max(h_i, 0). Inside the margin (h_i <= 0) this asks for no further approach
  instead of the recovery a textbook barrier demands: a filter that drove the robot away from a
  wall on its own, with the operator's stick centred, would break DESIGN 1 (nothing from the
  operator's side can make the robot move more than asked; here: the filter never adds motion
  the QP's closeness does not justify). So the zero command is always feasible: the filter can
  always stop, and any motion that approaches no point (moving away) is never refused.

The margin's speed is taken twice, which makes two half-planes per point:

- (S) at the robot's current velocity (the spec's "braking distance at the current speed"):
  u_i(v, w) <= alpha max(sd_i - margin - omega_i K u_i(v_now, w_now)^+, 0). A robot that is fast
  now needs room to stop from this speed, whatever it is asked next.
- (C) at the commanded velocity: u_i (1 + alpha omega_i K) <= alpha max(sd_i - margin, 0),
  linear because u_i is. Without it the filter chases its own output: a slower command shrinks
  next cycle's margin, which allows a faster one (loop gain alpha K > 1 for every useful alpha:
  the command chatters). With both, the command settles on their common fixed point.
  K here uses the larger of the current and the commanded speeds (an upper bound of the braking
  time, so the linear margin is never shorter than the quadratic braking distance).

In a replay (the current speed is the recorded command) (S) and (C) agree on the recorded
command. Box limits |v| <= v_max, |w| <= w_max from the profile close the feasible set.

**Solving** min wv (v - v0)^2 + ww (w - w0)^2 over the half-planes and the box, exactly, in
closed form, vectorised (no iterative solver): in coordinates scaled by the weights this is the
Euclidean projection onto a convex polygon. A strictly convex QP has one minimiser and the KKT
conditions are sufficient, so the projection onto a single violated line, when feasible, is the
answer; otherwise the answer is a vertex of two lines (the feasible one nearest the command).
Which points enter: only those within reach (a point whose barrier no command within the box and
within ``||u0||`` of u0 in the weighted norm can violate is dropped; the answer never lies
farther, since the zero command is feasible), then cutting planes: the working set starts with
the ``points_considered`` rows the command violates most; the answer on the working set is
checked against every point in reach and the most violated are added, until none is (a few
rounds; the answer is then optimal for the whole set, being optimal for a subset and feasible
for all). Should that not settle within ``_MAX_ROUNDS`` rounds, or the polygon
come out empty through rounding, the filter stops translation and keeps the rotation every
barrier allows (the interval of w at v = 0 always holds 0).

Cases, each never less safe than stopping (as EGC's DESIGN 5.9 rules):

- ``INVALID_INPUT``: a non-finite or > 1e6 command, velocity or tau -> stop.
- ``NO_POINTS_UNKNOWN``: no valid scan point and no-return not declared free -> stop.
  ``NO_POINTS_FREE``: declared free -> only the edges of what the laser saw constrain.
- ``CLEAR``: the command keeps every barrier -> returned as it came (the same float objects).
- ``SOLVED``: the closest command that keeps every barrier.
- ``STOP_TURN``: the fallback above.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace

import numpy as np
import numpy.typing as npt
from egc_common.footprint import Footprint, closest_boundary_points, signed_distance
from egc_common.profiles import RobotProfile
from egc_common.scan import MAX_ABS_COORD_M, ObstaclePoints, obstacle_points

from egc_robot.safety import SweepParams

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]

# omega_i = cos^PATH_POWER: how much of the stopping distance a point off the path is owed
# (module docstring: with 4 a Jackal at 0.8 m/s passes a wall 0.2 m away).
PATH_POWER = 4
_MAX_ROUNDS = 16  # cutting-plane rounds before the stop-and-turn fallback (a handful is usual)
_TOL = 1e-9  # a constraint is met when short of it by no more than this (m/s)
_SAME = 1e-12
_EMPTY = np.empty(0)
_MAX_REPORTED = 64  # active constraints kept in a result (the view and the tool show them)


class CbfCase(enum.Enum):
    """Which branch produced the result."""

    CLEAR = "clear"  # the command keeps every barrier: unchanged
    SOLVED = "solved"  # the closest command that keeps every barrier
    STOP_TURN = "stop_turn"  # no translation; the rotation the barriers allow
    NO_POINTS_UNKNOWN = "no_points_unknown"
    NO_POINTS_FREE = "no_points_free"
    INVALID_INPUT = "invalid_input"


@dataclass(frozen=True, slots=True)
class CbfParams:
    """``cbf`` settings, each with a unit (DESIGN 3, 13); ``from_profile`` gives the defaults.

    - ``alpha_per_s``: how fast a barrier may shrink (1/s): the footprint may approach a point at
      alpha x its barrier. Larger is quieter (the filter acts later) and still stops in time,
      because the margin holds the stopping distance. 8/s: alpha T = 0.4 at the 20 Hz loop
      (T = 0.05 s), so a barrier shrinks by at most 40 % per period and the sampled loop does not
      overshoot (alpha T < 1); and a careful driver passes walls 0.2 m away at 0.8 m/s (module
      docstring; at 5/s the Jackal's 0.12 m margin slowed such a pass).
    - ``margin_m``: kept from every point when standing (m). ``from_profile``: the footprint
      sweep's 3 cm (so the sweep after the filter does not have to cut in first) plus the
      distance covered at v_max in 45 ms, about the age of a 20 Hz scan when a command meets
      it: Jackal 0.12 m, Pioneer 3-DX 0.036 m.
    - ``weight_v``, ``weight_w``: weights of (dv / v_max)^2 and (dw / w_max)^2 in the distance the
      filter minimises. Equal: a cut of 10 % of v_max costs the same as 10 % of w_max, the
      ``mean_cut`` metric's own scale.
    - ``tau_s``: the loop delay (s) when the caller knows none (a replay, ``egc-teleop
      filter``): DESIGN 9's tau on a perfect link, the operator's reaction time alone. The
      robot's controller passes its measured tau instead.
    - ``period_s``: the control period (s), which the robot sets from its rate as for the
      footprint sweep (``SweepParams.period_s``).
    - ``points_considered``: how many constraints the solver takes at a time, the most violated
      ones (first by the command, then each round by the last answer). It checks every point in
      reach after each round, so this sets the cost of a round, not the answer: 8 is a wall
      ahead and one beside, each with its (S) and (C) rows and neighbours, settled in one or
      two rounds.
    """

    alpha_per_s: float = 8.0
    margin_m: float = 0.1
    weight_v: float = 1.0
    weight_w: float = 1.0
    tau_s: float = 0.25
    period_s: float = SweepParams().period_s
    points_considered: int = 8
    no_return_is_free: bool = False  # the driver's declaration (DESIGN 5.9)

    def __post_init__(self) -> None:
        for name in ("alpha_per_s", "weight_v", "weight_w"):
            value = getattr(self, name)
            if not _is_number(value) or not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"cbf {name} must be a positive number, got {value!r}")
        for name in ("margin_m", "tau_s", "period_s"):
            value = getattr(self, name)
            if not _is_number(value) or not (math.isfinite(value) and 0.0 <= value <= 60.0):
                raise ValueError(f"cbf {name} must be a number within [0, 60], got {value!r}")
        value = self.points_considered
        if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= 256:
            raise ValueError(
                f"cbf points_considered must be an integer within [1, 256], got {value!r}"
            )
        if not isinstance(self.no_return_is_free, bool):
            raise ValueError("cbf no_return_is_free must be true or false")

    @staticmethod
    def from_profile(profile: RobotProfile, **overrides: object) -> CbfParams:
        """Defaults for a profile: ``margin_m`` = 0.03 m + v_max x 45 ms (see the class)."""
        margin = round(SweepParams().margin_m + 0.045 * profile.v_max_mps, 4)
        return replace(CbfParams(margin_m=margin), **overrides)  # type: ignore[arg-type]

    @staticmethod
    def keys() -> tuple[str, ...]:
        """The keys a ``[cbf]`` config table may hold."""
        return tuple(f.name for f in fields(CbfParams))

    @staticmethod
    def from_mapping(table: Mapping[str, object], profile: RobotProfile | None = None) -> CbfParams:
        """Parameters from a config table (the robot TOML's ``[cbf]``), over the defaults of
        ``profile`` (or the plain defaults). Unknown keys and bad values raise ValueError."""
        known = CbfParams.keys()
        unknown = sorted(set(table) - set(known))
        if unknown:
            raise ValueError(
                f"[cbf] has unknown keys: {', '.join(unknown)} (known: {', '.join(known)})"
            )
        values: dict[str, object] = {}
        for key, value in table.items():
            if key == "points_considered":
                if isinstance(value, float) and value.is_integer():
                    value = int(value)
            elif key == "no_return_is_free":
                pass
            elif isinstance(value, int) and not isinstance(value, bool):
                value = float(value)
            elif not isinstance(value, float):
                raise ValueError(f"cbf {key} must be a number, got {value!r}")
            values[key] = value
        base = CbfParams.from_profile(profile) if profile is not None else CbfParams()
        return replace(base, **values)  # type: ignore[arg-type]


@dataclass(frozen=True, slots=True)
class CbfConstraint:
    """One half-plane a v + b w >= c of the answer, and the point it comes from ({R}, m)."""

    x_m: float
    y_m: float
    a: float
    b: float
    c: float
    distance_m: float  # sd_i: footprint to point (negative: inside)
    margin_m: float  # m_i at the speed it was taken at (state or command)
    kind: str  # "state" (S) or "command" (C)
    unseen: bool  # an edge of what the laser saw, not a scan point


@dataclass(frozen=True, slots=True, eq=False)
class TightRows:
    """The constraints that changed the command, as arrays (``CbfResult.active`` unpacks them
    when asked: the control loop does not)."""

    x_m: FloatArray
    y_m: FloatArray
    a: FloatArray
    b: FloatArray
    c: FloatArray
    distance_m: FloatArray
    margin_m: FloatArray
    state: npt.NDArray[np.bool_]  # (S) rows; the others are (C)
    unseen: npt.NDArray[np.bool_]


@dataclass(frozen=True, slots=True)
class CbfResult:
    """The filtered command and the intermediates the view, the tool and the tests show."""

    v_mps: float
    w_radps: float
    modified: bool
    case: CbfCase
    margin_m: float  # the fixed margin
    tau_s: float  # the loop delay the margins used
    braking_s: float  # K = tau + P + T / 2 of (S): metres of margin per m/s of approach
    considered: int = 0  # points within reach (scan points and unseen edges)
    rounds: int = 0  # cutting-plane rounds
    tight: TightRows | None = None
    nearest_m: float = math.inf  # smallest sd_i among the points considered
    # Margin straight ahead in the direction of travel at the current speed (m), for the view.
    margin_ahead_m: float = 0.0

    @property
    def active(self) -> tuple[CbfConstraint, ...]:
        """The constraints the command violated and the answer meets with equality (at most
        ``_MAX_REPORTED``)."""
        t = self.tight
        if t is None:
            return ()
        columns = (t.x_m, t.y_m, t.a, t.b, t.c, t.distance_m, t.margin_m)
        rows = zip(
            *(col.tolist() for col in columns), t.state.tolist(), t.unseen.tolist(), strict=True
        )
        return tuple(
            CbfConstraint(x, y, a, b, c, d, m, "state" if st else "command", un)
            for x, y, a, b, c, d, m, st, un in rows
        )


def cbf_filter(
    v_ref_mps: float,
    w_ref_radps: float,
    obstacles: npt.ArrayLike | ObstaclePoints,
    v_now_mps: float,
    w_now_radps: float,
    tau_s: float | None,
    profile: RobotProfile,
    params: CbfParams,
) -> CbfResult:
    """Filter one command; see the module docstring."""
    tau = params.tau_s if tau_s is None else tau_s
    v0, w0, v_now, w_now = v_ref_mps, w_ref_radps, v_now_mps, w_now_radps
    if not all(abs(x) <= MAX_ABS_COORD_M for x in (v0, w0, v_now, w_now)) or not (
        0.0 <= tau <= MAX_ABS_COORD_M
    ):
        return _stop(CbfCase.INVALID_INPUT, v0, w0, params, 0.0, 0.0)

    a_dec, alpha_dec = profile.decel_max_mps2, profile.angular_accel_max_radps2
    t_now = max(abs(v_now) / a_dec, abs(w_now) / alpha_dec)
    k_now = tau + params.period_s + 0.5 * t_now  # (S)
    t_hi = max(t_now, abs(v0) / a_dec, abs(w0) / alpha_dec)
    k_cmd = tau + params.period_s + 0.5 * t_hi  # (C)
    ahead = params.margin_m + abs(v_now) * k_now

    pts = obstacle_points(obstacles)
    if pts.count == 0 and not params.no_return_is_free:
        return _stop(CbfCase.NO_POINTS_UNKNOWN, v0, w0, params, tau, k_now)

    sv = math.sqrt(params.weight_v) / profile.v_max_mps  # z = (sv v, sw w): Euclidean QP
    sw = math.sqrt(params.weight_w) / profile.w_max_radps
    scene = _Scene(profile, params, v0, w0, v_now, w_now, k_now, k_cmd)
    # Only points the command itself could approach too fast can make it change.
    if scene.points_in_reach(pts, (v0, v0), abs(w0)) is None:
        case = CbfCase.NO_POINTS_FREE if pts.count == 0 else CbfCase.CLEAR
        return CbfResult(
            v0, w0, False, case, params.margin_m, tau, k_now, 0, 0, None, math.inf, ahead
        )
    # The rows of every point that any command the filter can return could approach too fast:
    # it returns one within the box and within norm0 of the command (the zero command is
    # feasible). The command is checked on them too (they include its own points).
    norm0 = math.hypot(sv * v0, sw * w0)
    v_hi = max(v0, min(profile.v_max_mps, v0 + norm0 / sv))
    v_lo = min(v0, max(-profile.v_max_mps, v0 - norm0 / sv))
    w_bound = max(abs(w0), min(profile.w_max_radps, abs(w0) + norm0 / sw))
    reach = scene.points_in_reach(pts, (v_lo, v_hi), w_bound)
    assert reach is not None  # it holds the command's
    rows = scene.rows(*reach)
    if rows.worst_for_command <= _TOL:  # the command keeps every barrier: unchanged, to the bit
        return CbfResult(
            v0, w0, False, CbfCase.CLEAR, params.margin_m, tau, k_now, rows.n, 0, None,
            rows.nearest, ahead,
        )  # fmt: skip

    a_all = np.concatenate((rows.a, rows.gain * rows.a))  # (S) then (C)
    b_all = np.concatenate((rows.b, rows.gain * rows.b))
    c_all = np.concatenate((rows.c_state, rows.c_cmd))
    v_out, w_out, rounds, case, working = _solve(
        a_all, b_all, c_all, v0, w0, sv, sw, profile, params.points_considered
    )
    # A stop computed as the projection onto a line through the origin comes out as 1e-17.
    v_out = 0.0 if abs(v_out) <= _SAME else v_out
    w_out = 0.0 if abs(w_out) <= _SAME else w_out
    # The constraints that changed the command: in the working set (violated by the command),
    # met with equality by the answer.
    wc = c_all[working]
    gap = a_all[working] * v_out + b_all[working] * w_out - wc
    tight = working[np.abs(gap) <= 1e-7 * (1.0 + np.abs(wc))][:_MAX_REPORTED]
    n = rows.n
    point = tight % n
    state = tight < n
    margins = rows.margins(point, state)
    found = TightRows(
        rows.x[point], rows.y[point], a_all[tight], b_all[tight], c_all[tight],
        rows.sd[point], margins, state, point >= rows.n_scan,
    )  # fmt: skip
    modified = bool(v_out != v0 or w_out != w0)
    return CbfResult(
        v_out, w_out, modified, case, params.margin_m, tau, k_now, n, rounds, found, rows.nearest,
        ahead,
    )  # fmt: skip


@dataclass(frozen=True, slots=True, eq=False)
class _Rows:
    """Every point's two half-planes, per point: a = -n_x, b, and c for (S) and (C)."""

    x: FloatArray
    y: FloatArray
    n_scan: int  # the first n_scan points are scan points, the rest unseen edges
    sd: FloatArray
    a: FloatArray
    b: FloatArray
    gain: FloatArray  # (C)'s rows are (S)'s times this
    c_state: FloatArray
    c_cmd: FloatArray
    m_state_extra: FloatArray | None  # omega K u^+ at the current speed (None: standing)
    m_cmd_extra: FloatArray  # ... at the commanded speed
    margin_m: float
    worst_for_command: float  # the command's largest shortfall over every row
    nearest: float

    @property
    def n(self) -> int:
        return self.x.size

    def margins(self, point: IntArray, state: npt.NDArray[np.bool_]) -> FloatArray:
        """The margins m_i of (S) rows (``state``) and (C) rows of the given points (m)."""
        extra = self.m_cmd_extra[point]
        if self.m_state_extra is not None:
            extra = np.where(state, self.m_state_extra[point], extra)
        else:
            extra = np.where(state, 0.0, extra)
        out: FloatArray = self.margin_m + extra
        return out


@dataclass(frozen=True, slots=True)
class _Scene:
    """One cycle's settings, shared by the command's check and the solve."""

    profile: RobotProfile
    params: CbfParams
    v0: float
    w0: float
    v_now: float
    w_now: float
    k_now: float
    k_cmd: float

    def points_in_reach(
        self, pts: ObstaclePoints, v_range: tuple[float, float], w_bound: float
    ) -> tuple[FloatArray, FloatArray, int, list[tuple[float, float, float]]] | None:
        """The points (x, y), how many are scan points, and the unseen edges, that a command
        with v in ``v_range`` and |w| <= ``w_bound`` could approach faster than their barriers
        allow; None when there is none.

        A point farther from the footprint than reach_sd has slack in (S) and (C):
        (S) alpha (sd - margin - K u_now) >= u and (C) alpha (sd - margin) >= u (1 + alpha K)
        with u the largest approach. Points ahead (x > 0: n_x >= 0) are approached by forward
        motion and turning only, points behind by reversing and turning only.
        """
        p, alpha, q_max = self.params, self.params.alpha_per_s, self.profile.half_diagonal_m
        x_back, x_front, _, _ = self.profile.footprint.bounds
        reach_sd = []
        for v_away, v_state in (
            (max(v_range[1], 0.0), max(self.v_now, 0.0)),
            (max(-v_range[0], 0.0), max(-self.v_now, 0.0)),
        ):
            u = v_away + q_max * w_bound
            u_state = v_state + q_max * abs(self.w_now)
            reach_sd.append(p.margin_m + u / alpha + max(u * self.k_cmd, self.k_now * u_state))
        reach_f, reach_b = q_max + reach_sd[0], q_max + reach_sd[1]
        x = y = _EMPTY
        if pts.count:
            index = pts.prepared_index
            far = max(reach_f, reach_b)
            if index is None or index.r2_sorted[0] <= far * far:
                if reach_f == reach_b:
                    near = pts.r2 <= reach_f * reach_f
                else:
                    near = pts.r2 <= np.where(pts.x > 0.0, reach_f * reach_f, reach_b * reach_b)
                if near.any():
                    x, y = pts.x[near], pts.y[near]
        unseen = [  # (direction, how far it saw, the footprint's extent that way)
            (sign, seen, extent)
            for sign, seen, extent, room in (
                (1.0, pts.seen_ahead_m, x_front, reach_sd[0]),
                (-1.0, pts.seen_behind_m, -x_back, reach_sd[1]),
            )
            if seen - extent < room
        ]
        if x.size == 0 and not unseen:
            return None
        return x, y, x.size, unseen

    def rows(
        self, x: FloatArray, y: FloatArray, n_scan: int, unseen: list[tuple[float, float, float]]
    ) -> _Rows:
        """The half-planes of the points (module docstring)."""
        p, alpha = self.params, self.params.alpha_per_s
        v0, w0, v_now, w_now = self.v0, self.w0, self.v_now, self.w_now
        sd, nx, ny, qx, qy = _geometry(x, y, self.profile.footprint)
        if unseen:
            # A wall across the axis where the laser stopped seeing, met first by the
            # footprint's front (back) extent: n = (+-1, 0), q = (front or back, 0).
            extra = np.array(
                [(s * seen, 0.0, seen - ext, s, 0.0, s * ext, 0.0) for s, seen, ext in unseen]
            ).T
            x, y = np.concatenate((x, extra[0])), np.concatenate((y, extra[1]))
            sd, nx, ny, qx, qy = (
                np.concatenate((g, e)) for g, e in zip((sd, nx, ny, qx, qy), extra[2:], strict=True)
            )
        b = nx * qy - ny * qx
        # Approach speeds u = nx v - b w under the command and under the current motion, and
        # how squarely each point lies in that motion's path (omega).
        u_ref = nx * v0 - b * w0
        omega_cmd = _omega(u_ref, v0, w0, qx, qy)
        room = sd - p.margin_m
        c_cmd = -alpha * np.maximum(room, 0.0)
        m_extra: FloatArray | None = None
        c_state = c_cmd
        if v_now or w_now:
            if v_now == v0 and w_now == w0:  # a replay, a steady cycle: the same speeds twice
                u_now, omega_now = u_ref, omega_cmd
            else:
                u_now = nx * v_now - b * w_now
                omega_now = _omega(u_now, v_now, w_now, qx, qy)
            m_extra = (omega_now * self.k_now) * np.maximum(u_now, 0.0)
            c_state = -alpha * np.maximum(room - m_extra, 0.0)
        gain = 1.0 + (alpha * self.k_cmd) * omega_cmd  # (C): u gain <= alpha max(room, 0)
        # The command meets row i when u_ref <= -c (S), gain u_ref <= -c (C).
        worst = max(float((c_state + u_ref).max()), float((c_cmd + gain * u_ref).max()))
        m_extra_cmd = (omega_cmd * self.k_cmd) * np.maximum(u_ref, 0.0)
        return _Rows(
            x, y, n_scan, sd, -nx, b, gain, c_state, c_cmd, m_extra, m_extra_cmd, p.margin_m,
            worst, float(sd.min()),
        )  # fmt: skip


def _geometry(
    x: FloatArray, y: FloatArray, fp: Footprint
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Signed distance sd, unit normal (nx, ny) and the footprint's nearest point (qx, qy) of
    each point. The normal is the gradient of sd: from q towards the point outside, from the
    point towards q inside (the outward normal of the nearest edge)."""
    box = fp.centred_box
    if box is not None:
        return _box_geometry(x, y, *box)
    if fp.is_disc:
        r = np.sqrt(x * x + y * y)
        centre = r <= 0.0
        safe = np.where(centre, 1.0, r)
        nx, ny = np.where(centre, 1.0, x / safe), np.where(centre, 0.0, y / safe)
        radius = fp.radius_m
        return r - radius, nx, ny, radius * nx, radius * ny
    qx, qy = closest_boundary_points(fp, x, y)
    dx, dy = x - qx, y - qy
    dist = np.sqrt(dx * dx + dy * dy)
    sd = np.where(signed_distance(fp, x, y) < 0.0, -dist, dist)
    on_edge = dist <= 0.0
    safe = np.where(on_edge, 1.0, dist)
    sign = np.where(sd < 0.0, -1.0, 1.0)  # inside: towards the edge, i.e. outwards
    nx, ny = sign * dx / safe, sign * dy / safe
    if on_edge.any():  # on the edge itself: away from the origin, as outwards as any
        r = np.maximum(np.sqrt(x * x + y * y), _SAME)
        nx, ny = np.where(on_edge, x / r, nx), np.where(on_edge, y / r, ny)
    return sd, nx, ny, qx, qy


def _box_geometry(
    x: FloatArray, y: FloatArray, half_l: float, half_w: float
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """``_geometry`` of the rectangle |x| <= half_l, |y| <= half_w in closed form."""
    qx = np.minimum(np.maximum(x, -half_l), half_l)
    qy = np.minimum(np.maximum(y, -half_w), half_w)
    dx = x - qx
    dy = y - qy
    sd = np.sqrt(dx * dx + dy * dy)
    inside = sd <= 0.0
    if not inside.any():
        inv = 1.0 / sd
        return sd, dx * inv, dy * inv, qx, qy
    xi, yi = x[inside], y[inside]
    to_front, to_back = half_l - xi, xi + half_l
    to_left, to_right = half_w - yi, yi + half_w
    depth = np.minimum(np.minimum(to_front, to_back), np.minimum(to_left, to_right))
    ex = np.where(to_front == depth, 1.0, np.where(to_back == depth, -1.0, 0.0))
    ey = np.where(ex != 0.0, 0.0, np.where(to_left == depth, 1.0, -1.0))
    dx[inside], dy[inside] = ex, ey
    qx[inside] = np.where(ex != 0.0, ex * half_l, xi)
    qy[inside] = np.where(ey != 0.0, ey * half_w, yi)
    sd[inside] = -depth
    norm = np.where(inside, 1.0, sd)
    return sd, dx / norm, dy / norm, qx, qy


def _omega(u: FloatArray, v: float, w: float, qx: FloatArray, qy: FloatArray) -> FloatArray:
    """(cos of the angle between n_i and the velocity of q_i under (v, w))^PATH_POWER, 0 for
    points the footprint does not approach (u_i <= 0)."""
    if w == 0.0:
        if v == 0.0:
            return np.zeros(u.size)
        cos = np.maximum(u, 0.0) / abs(v)  # u = nx v <= |v|: no overflow, even for subnormal v
    else:
        gx = v - w * qy
        gy = w * qx
        speed = np.sqrt(gx * gx + gy * gy)
        cos = np.maximum(u, 0.0) / np.maximum(speed, _SAME)
    cos = np.minimum(cos, 1.0)
    c2 = cos * cos
    out: FloatArray = c2 * c2
    return out


def _solve(
    a: FloatArray,
    b: FloatArray,
    c: FloatArray,
    v0: float,
    w0: float,
    sv: float,
    sw: float,
    profile: RobotProfile,
    k: int,
) -> tuple[float, float, int, CbfCase, IntArray]:
    """Cutting planes over the rows a v + b w >= c (module docstring): the ``k`` most violated
    rows first, then each round the ``k`` most violated by the last answer. Returns the
    answer, the rounds, the case and the working set."""
    # By how much each row is violated (m/s): the order in which rows join, not the answer.
    short = a * v0 + b * w0 - c
    working = _most_violated(short, k)
    for rounds in range(1, _MAX_ROUNDS + 1):
        found = _project(a[working], b[working], c[working], v0, w0, sv, sw, profile)
        if found is None:
            break
        v, w = found
        short = a * v + b * w - c
        add = _most_violated(short, k)
        if add.size == 0:
            return v, w, rounds, CbfCase.SOLVED, working
        working = np.concatenate((working, add))
    v, w = _stop_and_turn(b, c, w0, profile)
    return v, w, _MAX_ROUNDS, CbfCase.STOP_TURN, working


def _most_violated(short: FloatArray, k: int) -> IntArray:
    """Indices of the (at most) ``k`` rows with the most negative ``short`` below -tolerance."""
    bad = np.flatnonzero(short < -_TOL)
    if bad.size > k:
        bad = bad[np.argpartition(short[bad], k)[:k]]
    return bad


def _project(
    a: FloatArray,
    b: FloatArray,
    c: FloatArray,
    v0: float,
    w0: float,
    sv: float,
    sw: float,
    profile: RobotProfile,
) -> tuple[float, float] | None:
    """The closest point to (v0, w0) (weighted) in the polygon of the rows and the box, or None
    when none of the candidates is feasible (empty polygon, through rounding). The box's rows
    join only when the answer without them leaves it."""
    vm, wm = profile.v_max_mps, profile.w_max_radps
    found = _nearest_in(a * (1.0 / sv), b * (1.0 / sw), c, sv * v0, sw * w0)
    if found is not None and abs(found[0]) <= sv * vm and abs(found[1]) <= sw * wm:
        return found[0] / sv, found[1] / sw
    m = a.size
    gx = np.empty(m + 4)
    gy = np.empty(m + 4)
    e = np.empty(m + 4)
    gx[:m], gy[:m], e[:m] = a * (1.0 / sv), b * (1.0 / sw), c
    gx[m:], gy[m:] = (1.0 / sv, -1.0 / sv, 0.0, 0.0), (0.0, 0.0, 1.0 / sw, -1.0 / sw)
    e[m:] = (-vm, -vm, -wm, -wm)
    found = _nearest_in(gx, gy, e, sv * v0, sw * w0)
    return None if found is None else (found[0] / sv, found[1] / sw)


def _nearest_in(
    gx: FloatArray, gy: FloatArray, e: FloatArray, z0x: float, z0y: float
) -> tuple[float, float] | None:
    """The point of {z : gx zx + gy zy >= e} nearest to z0 (Euclidean), or None when no
    candidate is feasible."""
    n2 = gx * gx + gy * gy
    keep = n2 > _SAME
    if not keep.all():
        gx, gy, e, n2 = gx[keep], gy[keep], e[keep], n2[keep]
    r0 = gx * z0x + gy * z0y - e
    bad = np.flatnonzero(r0 < 0.0)
    if bad.size == 0:
        return z0x, z0y
    tol = _TOL * (1.0 + np.abs(e))
    # One line: the projection onto a violated row, optimal whenever feasible (KKT).
    step = -r0[bad] / n2[bad]
    zx = z0x + step * gx[bad]
    zy = z0y + step * gy[bad]
    feasible = (np.outer(zx, gx) + np.outer(zy, gy) - e >= -tol).all(axis=1)
    if feasible.any():
        i = int(np.argmax(feasible))  # all feasible ones are the one optimum
        return float(zx[i]), float(zy[i])
    # Two lines: every vertex, the feasible one nearest the command.
    p, q = np.triu_indices(gx.size, 1)
    det = gx[p] * gy[q] - gy[p] * gx[q]
    ok = np.abs(det) > _SAME * np.sqrt(n2[p] * n2[q])
    p, q, det = p[ok], q[ok], det[ok]
    if p.size == 0:
        return None
    zx = (e[p] * gy[q] - e[q] * gy[p]) / det
    zy = (gx[p] * e[q] - gx[q] * e[p]) / det
    feasible = (np.outer(zx, gx) + np.outer(zy, gy) - e >= -tol).all(axis=1)
    if not feasible.any():
        return None
    d2 = (zx - z0x) ** 2 + (zy - z0y) ** 2
    i = int(np.argmin(np.where(feasible, d2, np.inf)))
    return float(zx[i]), float(zy[i])


def _stop_and_turn(
    b: FloatArray, c: FloatArray, w0: float, profile: RobotProfile
) -> tuple[float, float]:
    """v = 0 and the w nearest w0 that every row allows at v = 0 (b w >= c); 0 is always in."""
    lo, hi = -profile.w_max_radps, profile.w_max_radps
    pos, neg = b > _SAME, b < -_SAME
    if pos.any():
        lo = max(lo, float((c[pos] / b[pos]).max()))
    if neg.any():
        hi = min(hi, float((c[neg] / b[neg]).min()))
    if lo > hi:
        return 0.0, 0.0
    return 0.0, min(max(w0, lo), hi)


def _stop(
    case: CbfCase, v_ref: float, w_ref: float, params: CbfParams, tau: float, k: float
) -> CbfResult:
    modified = not (v_ref == 0.0 and w_ref == 0.0)
    return CbfResult(0.0, 0.0, modified, case, params.margin_m, tau, k)


def _is_number(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)
