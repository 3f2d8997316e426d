"""Control barrier function safety filter, ``cbf`` (DESIGN 13).

A minimal-intervention filter: the command closest to the operator's that keeps every obstacle
point's barrier, and the operator's command itself, unchanged to the bit, whenever it keeps them.
``cbf_filter`` is a pure function: command (v, w) after eq. 4, scan points in {R}, the current
velocity, the loop delay tau (DESIGN 9), the profile and ``CbfParams`` in; a frozen ``CbfResult``
with its intermediates out.

**Barriers.** For each obstacle point p_i (the scan's points, plus the edges of what the laser saw
along {R}'s x axis: DESIGN 5.10, ``ObstaclePoints.seen_ahead_m`` / ``seen_behind_m``, a point
beyond which nothing is known to be free):

- sd_i: the signed distance from the footprint (the profile's L x W rectangle centred on {R}) to
  p_i, and n_i its unit gradient: from the footprint's nearest point q_i towards p_i (for a point
  inside the footprint, the outward normal of the nearest edge, and q_i on that edge).
- A rigid motion (v, w) moves a fixed point of the world at (-v + w y, -w x) in {R}, so
  d sd_i / dt = -(n_x v - b_i w) with b_i = n_x q_y - n_y q_x: exactly linear in (v, w) (no
  linearisation: the gradient of the distance to a convex set is n). The footprint *approaches*
  p_i at u_i(v, w) = n_x v - b_i w (m/s).
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
the ``points_per_sector`` most violated points of each of ``sectors`` directions; the answer on
the working set is checked against every point in reach and the violated ones are added, until
none is (a few rounds; the answer is then optimal for the whole set, being optimal for a subset
and feasible for all). Should that not settle within ``_MAX_ROUNDS`` rounds, or the polygon
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
    - ``sectors``, ``points_per_sector``: the points considered first, the most violated ones
      per direction (the solver checks every point in reach afterwards; these only make it
      settle in fewer rounds).
    """

    alpha_per_s: float = 8.0
    margin_m: float = 0.1
    weight_v: float = 1.0
    weight_w: float = 1.0
    tau_s: float = 0.25
    period_s: float = SweepParams().period_s
    sectors: int = 16
    points_per_sector: int = 2
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
        for name, top in (("sectors", 360), ("points_per_sector", 64)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= top:
                raise ValueError(f"cbf {name} must be an integer within [1, {top}], got {value!r}")
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
            if key in ("sectors", "points_per_sector"):
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
    active: tuple[CbfConstraint, ...] = ()  # constraints the answer meets with equality
    nearest_m: float = math.inf  # smallest sd_i among the points considered
    # Margin straight ahead in the direction of travel at the current speed (m), for the view.
    margin_ahead_m: float = 0.0


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
    numbers = (v_ref_mps, w_ref_radps, v_now_mps, w_now_radps)
    if not all(abs(x) <= MAX_ABS_COORD_M for x in numbers) or not 0.0 <= tau <= MAX_ABS_COORD_M:
        return _stop(CbfCase.INVALID_INPUT, v_ref_mps, w_ref_radps, params, 0.0, 0.0)

    a_dec, alpha_dec = profile.decel_max_mps2, profile.angular_accel_max_radps2
    t_now = max(abs(v_now_mps) / a_dec, abs(w_now_radps) / alpha_dec)
    k_now = tau + params.period_s + 0.5 * t_now  # (S)
    t_hi = max(t_now, abs(v_ref_mps) / a_dec, abs(w_ref_radps) / alpha_dec)
    k_cmd = tau + params.period_s + 0.5 * t_hi  # (C)
    ahead = params.margin_m + abs(v_now_mps) * k_now

    pts = obstacle_points(obstacles)
    if pts.count == 0 and not params.no_return_is_free:
        return _stop(CbfCase.NO_POINTS_UNKNOWN, v_ref_mps, w_ref_radps, params, tau, k_now)

    half_l, half_w = profile.half_size_m
    q_max = profile.half_diagonal_m  # |b_i| <= |q_i| <= q_max
    alpha = params.alpha_per_s
    sv = math.sqrt(params.weight_v) / profile.v_max_mps  # z = (sv v, sw w): Euclidean QP
    sw = math.sqrt(params.weight_w) / profile.w_max_radps
    norm0 = math.hypot(sv * v_ref_mps, sw * w_ref_radps)
    # Any command the filter can return: within the box and within norm0 of the command.
    v_bound = max(abs(v_ref_mps), min(profile.v_max_mps, abs(v_ref_mps) + norm0 / sv))
    w_bound = max(abs(w_ref_radps), min(profile.w_max_radps, abs(w_ref_radps) + norm0 / sw))
    u_bound = v_bound + q_max * w_bound
    u_now_bound = abs(v_now_mps) + q_max * abs(w_now_radps)
    # A point farther than this from the footprint has slack in (S) and (C) for every command
    # the filter can return: (S) alpha (sd - margin - K u_now) >= u_bound and (C)
    # alpha (sd - margin) >= u_bound (1 + alpha K).
    reach_sd = params.margin_m + u_bound / alpha + max(u_bound * k_cmd, k_now * u_now_bound)
    reach = q_max + reach_sd

    # Scan points in reach, then the unseen edges along the x axis.
    x = y = _EMPTY
    if pts.count:
        index = pts.prepared_index
        if index is None or index.r2_sorted[0] <= reach * reach:
            near = pts.r2 <= reach * reach
            x, y = pts.x[near], pts.y[near]
    n_scan = x.size
    geo = _geometry(x, y, half_l, half_w)
    unseen = [
        (sign, seen)
        for sign, seen in ((1.0, pts.seen_ahead_m), (-1.0, pts.seen_behind_m))
        if seen - half_l < reach_sd
    ]
    if unseen:
        # A wall across the axis where the laser stopped seeing: n = (+-1, 0), q = (+-L/2, 0).
        extra = np.array(
            [(s * seen, 0.0, seen - half_l, s, 0.0, 0.0, s * half_l, 0.0) for s, seen in unseen]
        ).T
        x, y = np.concatenate((x, extra[0])), np.concatenate((y, extra[1]))
        sd0, nx0, b0, ny0, qx0, qy0 = (
            np.concatenate((g, e)) for g, e in zip(geo, extra[2:], strict=True)
        )
        geo = (sd0, nx0, b0, ny0, qx0, qy0)
    if x.size == 0:
        case = CbfCase.NO_POINTS_FREE if pts.count == 0 else CbfCase.CLEAR
        return CbfResult(
            v_ref_mps, w_ref_radps, False, case, params.margin_m, tau, k_now, 0, 0, (), math.inf,
            ahead,
        )  # fmt: skip

    sd, nx, b = geo[0], geo[1], geo[2]
    # Approach speeds of (v, w) = nx v - b w; omega from the velocity of the nearest footprint
    # point under the current motion (S) and under the command (C).
    u_now = nx * v_now_mps - b * w_now_radps if (v_now_mps or w_now_radps) else None
    omega_now = _omega(u_now, geo, v_now_mps, w_now_radps)
    u_ref = nx * v_ref_mps - b * w_ref_radps
    omega_cmd = _omega(u_ref, geo, v_ref_mps, w_ref_radps)

    room = sd - params.margin_m
    if u_now is None:
        c_state = -alpha * np.maximum(room, 0.0)
        m_state: FloatArray | float = params.margin_m
    else:
        m_extra = omega_now * k_now * np.maximum(u_now, 0.0)
        c_state = -alpha * np.maximum(room - m_extra, 0.0)
        m_state = params.margin_m + m_extra
    gain = 1.0 + alpha * k_cmd * omega_cmd  # (C): u (1 + alpha omega K) <= alpha max(room, 0)
    c_cmd = -alpha * np.maximum(room, 0.0)
    # Rows a v + b w >= c, (S) then (C): a = -nx, b = b for (S); scaled by the gain for (C).
    slack_state = c_state + u_ref  # <= 0 where (S) holds: u_ref <= -c
    slack_cmd = c_cmd + gain * u_ref
    worst = max(float(slack_state.max()), float(slack_cmd.max()))
    nearest = float(sd.min())
    if worst <= _TOL:  # the command keeps every barrier: unchanged, to the bit
        return CbfResult(
            v_ref_mps, w_ref_radps, False, CbfCase.CLEAR, params.margin_m, tau, k_now, x.size,
            0, (), nearest, ahead,
        )  # fmt: skip

    a_all = np.concatenate((-nx, -gain * nx))
    b_all = np.concatenate((b, gain * b))
    c_all = np.concatenate((c_state, c_cmd))
    x2, y2 = np.concatenate((x, x)), np.concatenate((y, y))
    solution = _solve(a_all, b_all, c_all, x2, y2, v_ref_mps, w_ref_radps, sv, sw, profile, params)
    v_out, w_out, rounds, case = solution
    # A stop computed as the projection onto a line through the origin comes out as 1e-17.
    v_out = 0.0 if abs(v_out) <= _SAME else v_out
    w_out = 0.0 if abs(w_out) <= _SAME else w_out
    # The constraints that changed the command: violated by it, met with equality by the answer.
    r_ref = a_all * v_ref_mps + b_all * w_ref_radps - c_all
    r_out = a_all * v_out + b_all * w_out - c_all
    tight = np.flatnonzero((r_ref < -_TOL) & (np.abs(r_out) <= 1e-7 * (1.0 + np.abs(c_all))))
    n = x.size
    m_state_arr = np.broadcast_to(np.asarray(m_state, dtype=np.float64), (n,))
    m_cmd_arr = params.margin_m + omega_cmd * k_cmd * np.maximum(u_ref, 0.0)
    margins = np.concatenate((m_state_arr, m_cmd_arr))
    active = tuple(
        CbfConstraint(
            float(x2[i]),
            float(y2[i]),
            float(a_all[i]),
            float(b_all[i]),
            float(c_all[i]),
            float(sd[i % n]),
            float(margins[i]),
            "state" if i < n else "command",
            bool(i % n >= n_scan),
        )
        for i in tight[:_MAX_REPORTED]
    )
    modified = bool(v_out != v_ref_mps or w_out != w_ref_radps)
    return CbfResult(
        v_out, w_out, modified, case, params.margin_m, tau, k_now, n, rounds, active, nearest,
        ahead,
    )  # fmt: skip


def _geometry(
    x: FloatArray, y: FloatArray, half_l: float, half_w: float
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Signed distance sd, normal (nx, ny), lever b = nx qy - ny qx and the nearest footprint
    point (qx, qy) of each point; returns (sd, nx, b, ny, qx, qy)."""
    qx = np.minimum(np.maximum(x, -half_l), half_l)
    qy = np.minimum(np.maximum(y, -half_w), half_w)
    dx = x - qx
    dy = y - qy
    sd = np.sqrt(dx * dx + dy * dy)
    inside = sd <= 0.0
    if inside.any():  # contact: the nearest edge's normal, the depth as a negative distance
        dx, dy, qx, qy = dx.copy(), dy.copy(), qx.copy(), qy.copy()
        xi, yi = x[inside], y[inside]
        to_front, to_back = half_l - xi, xi + half_l
        to_left, to_right = half_w - yi, yi + half_w
        depth = np.minimum(np.minimum(to_front, to_back), np.minimum(to_left, to_right))
        ex = np.where(to_front == depth, 1.0, np.where(to_back == depth, -1.0, 0.0))
        ey = np.where(ex != 0.0, 0.0, np.where(to_left == depth, 1.0, -1.0))
        dx[inside], dy[inside] = ex, ey
        qx[inside] = np.where(ex != 0.0, ex * half_l, xi)
        qy[inside] = np.where(ey != 0.0, ey * half_w, yi)
        sd = sd.copy()
        sd[inside] = -depth
        norm = np.where(inside, 1.0, sd)
    else:
        norm = sd
    inv = 1.0 / norm
    nx = dx * inv
    ny = dy * inv
    b = nx * qy - ny * qx
    return sd, nx, b, ny, qx, qy


def _omega(u: FloatArray | None, geo: tuple[FloatArray, ...], v: float, w: float) -> FloatArray:
    """(cos of the angle between n_i and the velocity of q_i under (v, w))^PATH_POWER, 0 for
    points the footprint does not approach."""
    if u is None:
        return np.zeros(geo[0].size)
    if w == 0.0:
        speed: FloatArray | float = abs(v)
    else:
        _, _, _, _, qx, qy = geo
        gx = v - w * qy
        gy = w * qx
        speed = np.sqrt(gx * gx + gy * gy)
    with np.errstate(divide="ignore", invalid="ignore"):
        cos = np.where(u > 0.0, u / np.maximum(speed, _SAME), 0.0)
    cos = np.minimum(cos, 1.0)
    c2 = cos * cos
    out: FloatArray = c2 * c2
    return out


def _solve(
    a: FloatArray,
    b: FloatArray,
    c: FloatArray,
    x: FloatArray,
    y: FloatArray,
    v0: float,
    w0: float,
    sv: float,
    sw: float,
    profile: RobotProfile,
    params: CbfParams,
) -> tuple[float, float, int, CbfCase]:
    """Cutting planes over the rows a v + b w >= c; see the module docstring."""
    r0 = a * v0 + b * w0 - c
    norms = np.sqrt((a / sv) ** 2 + (b / sw) ** 2)
    working = _pick(np.flatnonzero(r0 < -_TOL), r0, norms, x, y, params)
    v, w = v0, w0
    for rounds in range(1, _MAX_ROUNDS + 1):
        found = _project(a[working], b[working], c[working], v0, w0, sv, sw, profile)
        if found is None:
            break
        v, w = found
        r = a * v + b * w - c
        bad = np.flatnonzero(r < -_TOL)
        if bad.size == 0:
            return v, w, rounds, CbfCase.SOLVED
        add = _pick(bad, r, norms, x, y, params)
        working = np.union1d(working, add)
    v, w = _stop_and_turn(b, c, w0, profile)
    return v, w, _MAX_ROUNDS, CbfCase.STOP_TURN


def _pick(
    rows: IntArray,
    r: FloatArray,
    norms: FloatArray,
    x: FloatArray,
    y: FloatArray,
    params: CbfParams,
) -> IntArray:
    """The ``points_per_sector`` most violated rows of each direction sector."""
    k = params.points_per_sector
    if rows.size <= k:
        return rows
    depth = r[rows] / np.maximum(norms[rows], _SAME)  # negative: violated, in the QP's metric
    sector = np.floor(
        (np.arctan2(y[rows], x[rows]) + math.pi) * (params.sectors / (2.0 * math.pi))
    ).astype(np.intp)
    order = np.lexsort((depth, sector))
    s_sorted = sector[order]
    first = np.flatnonzero(np.concatenate(([True], s_sorted[1:] != s_sorted[:-1])))
    start = np.repeat(first, np.diff(np.concatenate((first, [s_sorted.size]))))
    keep = order[np.arange(s_sorted.size) - start < k]
    out: IntArray = rows[keep]
    return out


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
    when none of the candidates is feasible (empty polygon, through rounding)."""
    vm, wm = profile.v_max_mps, profile.w_max_radps
    # Scaled rows g . z >= e, z = (sv v, sw w); the box as four more rows.
    gx = np.concatenate((a / sv, [1.0 / sv, -1.0 / sv, 0.0, 0.0]))
    gy = np.concatenate((b / sw, [0.0, 0.0, 1.0 / sw, -1.0 / sw]))
    e = np.concatenate((c, [-vm, -vm, -wm, -wm]))
    z0x, z0y = sv * v0, sw * w0
    n2 = gx * gx + gy * gy
    ok_rows = n2 > _SAME
    gx, gy, e, n2 = gx[ok_rows], gy[ok_rows], e[ok_rows], n2[ok_rows]
    r0 = gx * z0x + gy * z0y - e
    tol = _TOL * (1.0 + np.abs(e))

    # One line: the projection onto a violated row, optimal whenever feasible (KKT).
    bad = np.flatnonzero(r0 < 0.0)
    if bad.size:
        step = -r0[bad] / n2[bad]
        zx = z0x + step * gx[bad]
        zy = z0y + step * gy[bad]
        feasible = ((np.outer(zx, gx) + np.outer(zy, gy) - e) >= -tol).all(axis=1)
        if feasible.any():
            i = int(
                np.flatnonzero(feasible)[np.argmin(step[feasible] * np.sqrt(n2[bad][feasible]))]
            )
            return float(zx[i] / sv), float(zy[i] / sw)
    else:
        return v0, w0
    # Two lines: every vertex, the feasible one nearest the command.
    p, q = np.triu_indices(gx.size, 1)
    det = gx[p] * gy[q] - gy[p] * gx[q]
    ok = np.abs(det) > _SAME * np.sqrt(n2[p] * n2[q])
    p, q, det = p[ok], q[ok], det[ok]
    if p.size == 0:
        return None
    zx = (e[p] * gy[q] - e[q] * gy[p]) / det
    zy = (gx[p] * e[q] - gx[q] * e[p]) / det
    feasible = ((np.outer(zx, gx) + np.outer(zy, gy) - e) >= -tol).all(axis=1)
    if not feasible.any():
        return None
    d2 = (zx - z0x) ** 2 + (zy - z0y) ** 2
    k = int(np.argmin(np.where(feasible, d2, np.inf)))
    return float(zx[k] / sv), float(zy[k] / sw)


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
