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
  u_i(v, w) <= max(alpha h_i, kappa_i sd_i^+). Inside the margin (h_i <= 0) this asks for no
  further approach (kappa_i = 0, below) instead of the recovery a textbook barrier demands:
  that one would drive the robot away from a wall on its own, the operator's stick centred,
  and a teleoperated robot must not move when nobody asks it to. So the zero command is always
  feasible: the filter can always stop, and any motion that approaches no point (moving away)
  is never refused.
- kappa_i, the creep: "no further approach" is a row a v + b w >= 0 through the origin, and
  for a point beside the middle of the footprint's flank its normal (a, b) = (-n_x, b_i)
  shrinks to zero and flips as the point passes: the allowed turn jumped between none and
  full (the continuity property test found it). So rows that no command in the box can make
  approach faster than ``CREEP_BELOW`` x v_max (U_i = |n_x| v_max + |b_i| w_max small) get a
  creep kappa_i = ``CREEP_PER_S`` x (1 - U_i / (``CREEP_BELOW`` v_max))^+: their turn limit
  kappa_i sd_i / |b_i| then grows without bound as b_i goes to zero and follows the point
  continuously. Such a point is approached at a few mm/s at most, and its distance decays
  at most exponentially (never to contact); every other row keeps kappa_i = 0, so a wall
  ahead or beside is still kept at the margin.

The margin's speed is taken twice, which makes two conditions per point:

- (S) at the robot's current velocity (the spec's "braking distance at the current speed"):
  u_i(v, w) <= max(alpha (sd_i - margin - omega_i K u_i(v_now, w_now)^+), kappa_i sd_i^+). A
  robot that is fast now needs room to stop from this speed, whatever it is asked next.
- (C) at the commanded velocity:
  u_i (1 + alpha omega_i K) <= max(alpha (sd_i - margin), kappa_i sd_i^+), linear because u_i
  is. Without it the filter chases its own output: a slower command shrinks next cycle's
  margin, which allows a faster one (loop gain alpha K > 1 for every useful alpha: the command
  chatters). With both, the command settles on their common fixed point.
  K here uses the larger of the current and the commanded speeds (an upper bound of the braking
  time, so the linear margin is never shorter than the quadratic braking distance).

Both bound the same u_i(v, w), so they make one half-plane per point, the tighter:
u_i(v, w) <= min(c_S, c_C / (1 + alpha omega_i K)) with c_S, c_C their right-hand sides (the
result's ``tight`` still says which binds). In a replay (the current speed is the recorded
command) (S) and (C) agree on the recorded command. Box limits |v| <= v_max, |w| <= w_max
from the profile close the feasible set.

**Solving** min wv (v - v0)^2 + ww (w - w0)^2 over the half-planes and the box, exactly, in
closed form (no iterative solver): in coordinates scaled by the weights this is the Euclidean
projection onto a convex polygon. A strictly convex QP has one minimiser and the KKT conditions
are sufficient, so the projection onto a single violated line, when feasible, is the answer;
otherwise the answer is a vertex of two lines, one of which the command violates (else KKT puts
the optimum at the command), the feasible one nearest the command. The rows are built for all
points at once (numpy); the few the solver works on are projected in plain Python, cheaper than
numpy's per-call cost at that size. That cost, and Python's own, not the arithmetic, is the
filter's time on the few dozen points in reach (``bench/bench_filter.py``), so:

- each quantity is one numpy call written where the solver reads it (lengths as the modulus of
  x + i y, products of several rows as one dot product, a polygon's edges repeated per point so
  that no call broadcasts), and a polygon's inside test runs only for points near its edge: the
  numbers are the formulas', to rounding;
- work that provably changes nothing is skipped, each shortcut giving the general form's answer
  to the bit (``test_cbf`` checks each against it): a CLEAR test from bounds (omega <= 1,
  creep >= 0) before omega and the creep are computed (``_Scene.rows``); the creep's calls
  when no row can creep or every point is beyond ``_Scene._creep_bound``; and the small QP's
  rows when the projection onto the first violated one is the answer (``_first_projection``).

Which points enter: a point whose barrier no command of a "cover" (a range of v and |w|) can
violate is left out, by its distance from the footprint alone. The first cover runs from a
standstill to the command (plus a little reversing and turning), so it holds every point the
command violates; then cutting planes: the working set starts with the ``points_considered``
rows the command violates most, the answer on it is checked against every row built and the
most violated are added, until none is (a round or two; the answer is then optimal for every
point built, being optimal for a subset and feasible for all). If the answer leaves the cover,
the rows are built again for a cover holding it too, and after ``_MAX_COVERS`` such covers for
the cover of every answer the filter can give (the box, within ``||u0||`` of the command in the
weighted norm: the zero command is feasible). The answer is then optimal for every point: no
point outside the cover that holds it can be approached too fast by it. Should the rounds not
settle within ``_MAX_ROUNDS``, or the polygon come out empty through rounding, the filter stops
translation and keeps the rotation every barrier allows (the interval of w at v = 0 always
holds 0).

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
from typing import Literal, NamedTuple, overload

import numpy as np
import numpy.typing as npt
from egc_common.footprint import Footprint, signed_distance
from egc_common.profiles import RobotProfile
from egc_common.scan import MAX_ABS_COORD_M, ObstaclePoints, obstacle_points

from egc_robot.safety import SweepParams

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]
ComplexArray = npt.NDArray[np.complex128]

# omega_i = cos^PATH_POWER: how much of the stopping distance a point off the path is owed
# (module docstring: with 4 a Jackal at 0.8 m/s passes a wall 0.2 m away).
PATH_POWER = 4
# The creep of rows no command can make approach faster than CREEP_BELOW x v_max (module
# docstring): kappa up to 1/s, so the turn limit beside a flank's middle is continuous on the
# scale of millimetres, while an approach at 5 % of v_max or more is never let into a margin.
CREEP_PER_S = 1.0
CREEP_BELOW = 0.05
_MAX_ROUNDS = 16  # cutting-plane rounds before the stop-and-turn fallback (a handful is usual)
_MAX_COVERS = 3  # covers grown to hold the answer before the one that holds every answer
# The first cover reaches this much (of v_max, w_max) beyond the command: answers that back off
# a little or turn away usually stay inside it, with no second build of the rows.
_COVER_V = 0.05
_COVER_W = 0.25
_TOL = 1e-9  # a constraint is met when short of it by no more than this (m/s)
_SAME = 1e-12
_SAME_SPEED = 1e-6  # sqrt(_SAME): a point's speed below this counts as this (m/s)
_EMPTY = np.empty(0)
_EMPTY_C = np.empty(0, dtype=np.complex128)
_NO_POINTS = np.empty((0, 2))


def _constant(value: float) -> FloatArray:
    """A read-only 0-d array: as an operand numpy takes it as it is, while it converts a Python
    float on every call (~0.3 us, on calls of ~0.5 us)."""
    out = np.array(value)
    out.setflags(write=False)
    return out


_ZERO, _NEG_ZERO, _ONE = _constant(0.0), _constant(-0.0), _constant(1.0)
_CREEP_PER_S = _constant(CREEP_PER_S)
_SAME_SPEED_0D, _TOL_0D = _constant(_SAME_SPEED), _constant(_TOL)
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
      ones (first by the command, then each round by the last answer). It checks every row
      built after each round, so this sets the cost of a round, not the answer: 8 holds a wall
      ahead and one beside, each with its neighbours, settled in one or two rounds.
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


class CbfResult(NamedTuple):
    """The filtered command and the intermediates the view, the tool and the tests show.

    Immutable and typed like the module's frozen dataclasses, but built on every call: a named
    tuple is built in one step (a frozen dataclass sets its twelve fields one at a time through
    ``object.__setattr__``, a few us of the filter's time)."""

    v_mps: float
    w_radps: float
    modified: bool
    case: CbfCase
    margin_m: float  # the fixed margin
    tau_s: float  # the loop delay the margins used
    braking_s: float  # K = tau + P + T / 2 of (S): metres of margin per m/s of approach
    considered: int = 0  # points within reach (scan points and unseen edges)
    rounds: int = 0  # cutting-plane rounds
    working: _Working | None = None  # the solver's rows (``tight`` reads them when asked)
    nearest_m: float = math.inf  # smallest sd_i among the points considered
    # Margin straight ahead in the direction of travel at the current speed (m), for the view.
    margin_ahead_m: float = 0.0

    @property
    def tight(self) -> TightRows | None:
        """The constraints the command violated and the answer meets with equality (at most
        ``_MAX_REPORTED``), as arrays, each the (S) or (C) that binds in its point's row (both:
        (C)); None when nothing changed. Computed when asked: the
        control loop does not."""
        return None if self.working is None else self.working.tight()

    @property
    def active(self) -> tuple[CbfConstraint, ...]:
        """``tight`` as one ``CbfConstraint`` each."""
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
    if not (
        abs(v0) <= MAX_ABS_COORD_M
        and abs(w0) <= MAX_ABS_COORD_M
        and abs(v_now) <= MAX_ABS_COORD_M
        and abs(w_now) <= MAX_ABS_COORD_M
        and 0.0 <= tau <= MAX_ABS_COORD_M
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

    shape = _shape(profile.footprint)
    q_max = shape.reach
    turn_now = q_max * (w_now if w_now >= 0.0 else -w_now)
    scene = _tuple_new(_Scene, (
        profile, params, v0, w0, v_now, w_now, k_now, k_cmd, shape.x_back, shape.x_front,
        q_max, shape, k_now * ((0.0 if v_now < 0.0 else v_now) + turn_now),
        k_now * ((0.0 if -v_now < 0.0 else -v_now) + turn_now),
    ))  # fmt: skip
    # Rows are built for the points some command within a "cover" could approach too fast:
    # first the command's own (from a standstill to it: slowing down needs no more points; a
    # little reversing and turning added), then, if the answer leaves the cover, one holding
    # the answer too, until one holds
    # it (the answer is then optimal for every point: optimal for those in the cover, and no
    # point outside it can be approached too fast by it). The last resort covers every command
    # the filter can return: within the box and within norm0 of the command (the zero command
    # is feasible). First, a test without numpy: nothing within the command's own reach,
    # nothing to change.
    cover = (
        min(v0, 0.0) - _COVER_V * profile.v_max_mps,
        max(v0, 0.0),
        min(abs(w0) + _COVER_W * profile.w_max_radps, profile.w_max_radps),
    )
    reach = scene.points_in_reach(pts, cover, quiet=True)
    if reach is None:
        case = CbfCase.NO_POINTS_FREE if pts.count == 0 else CbfCase.CLEAR
        return CbfResult(
            v0, w0, False, case, params.margin_m, tau, k_now, 0, 0, None, math.inf, ahead
        )
    first = scene.rows(*reach, clear_test=True)
    if isinstance(first, _Clear) or not first.violated.size:
        # The command keeps every barrier: unchanged, to the bit.
        return CbfResult(
            v0, w0, False, CbfCase.CLEAR, params.margin_m, tau, k_now, first.n, 0, None,
            float(first.nearest), ahead,
        )  # fmt: skip
    rows = first
    sv = math.sqrt(params.weight_v) / profile.v_max_mps  # z = (sv v, sw w): Euclidean QP
    sw = math.sqrt(params.weight_w) / profile.w_max_radps
    rounds_total = 0
    for attempt in range(_MAX_COVERS + 1):
        v_out, w_out, rounds, case, working = _solve(
            rows.abc, rows.short, rows.violated, v0, w0, sv, sw, profile, params.points_considered
        )
        rounds_total += rounds
        if case is not _SOLVED or (cover[0] <= v_out <= cover[1] and abs(w_out) <= cover[2]):
            break
        if attempt + 1 < _MAX_COVERS:
            cover = (min(cover[0], v_out), max(cover[1], v_out), max(cover[2], abs(w_out)))
        else:
            norm0 = math.hypot(sv * v0, sw * w0)
            cover = (
                min(v0, max(-profile.v_max_mps, v0 - norm0 / sv)),
                max(v0, min(profile.v_max_mps, v0 + norm0 / sv)),
                max(abs(w0), min(profile.w_max_radps, abs(w0) + norm0 / sw)),
            )
        wider = scene.points_in_reach(pts, cover)
        assert wider is not None  # it holds the command's points
        rows = scene.rows(*wider)
    # A stop computed as the projection onto a line through the origin comes out as 1e-17.
    v_out = 0.0 if abs(v_out) <= _SAME else v_out
    w_out = 0.0 if abs(w_out) <= _SAME else w_out
    found = _tuple_new(_Working, (rows, working, v_out, w_out))
    modified = bool(v_out != v0 or w_out != w0)
    return _tuple_new(CbfResult, (
        v_out, w_out, modified, case, params.margin_m, tau, k_now, rows.n, rounds_total, found,
        float(rows.nearest), ahead,
    ))  # fmt: skip


# The per-call named tuples are built with tuple.__new__: a named tuple's own __new__ is a
# Python function that binds every field by name (~2k instructions a call, of ~400k).
_tuple_new = tuple.__new__
_SOLVED = CbfCase.SOLVED  # a module name: an enum member looked up on its class costs ~1k


class _Working(NamedTuple):
    """The solver's rows and answer, kept for ``CbfResult.tight``."""

    rows: _Rows
    working: IntArray  # the rows the solver took (each violated by the command or an answer)
    v: float
    w: float

    def tight(self) -> TightRows:
        rows = self.rows
        a, b, c = rows.a, rows.b, rows.c
        wc = c[self.working]
        gap = a[self.working] * self.v + b[self.working] * self.w - wc
        violated = a[self.working] * rows.v0 + b[self.working] * rows.w0 < wc
        point = self.working[violated & (np.abs(gap) <= 1e-7 * (1.0 + np.abs(wc)))]
        point = point[:_MAX_REPORTED]
        # Which of the point's half-planes binds: (C) where its c is the row's (also when
        # both are), reported as (C) is written, -gain u >= c (the same half-plane); else (S).
        gain = rows.gain[point]
        state = rows.bounds[1][point] / gain != c[point]
        scale = np.where(state, 1.0, gain)
        x, y = rows.points[point].T.copy()
        return TightRows(
            x, y, a[point] * scale, b[point] * scale,
            np.where(state, c[point], rows.bounds[1][point]), rows.sd[point],
            rows.margins(point, state), state, point >= rows.n_scan,
        )  # fmt: skip


class _Clear(NamedTuple):
    """``_Scene.rows``' answer when the command provably keeps every row: how many points were
    in reach and the smallest sd_i, all a CLEAR result reports."""

    n: int
    nearest: float


class _Rows(NamedTuple):
    """Every point's half-plane a v + b w >= c, the tighter of its (S) and (C)."""

    points: FloatArray  # (n, 2): the scan points in reach, then the unseen edges' points
    n_scan: int
    n: int
    sd: FloatArray
    abc: FloatArray  # (3, n): a = -n_x, b, c of each point's row
    short: FloatArray  # by how much the command falls short of each row (> 0: violated)
    # (2, n): (S)'s c and (C)'s c before the division by its gain (for the report).
    bounds: FloatArray
    gain: FloatArray  # 1 + alpha K omega: (C) is -gain u >= bounds[1]
    alpha_m_state_extra: FloatArray | None  # alpha omega K u^+ at the current speed (or None)
    alpha: float
    omega_cmd: FloatArray  # omega and u at the commanded speed (its margin, for the report)
    u_ref: FloatArray
    k_cmd: float
    margin_m: float
    violated: IntArray  # the rows the command falls short of by more than _TOL, in order
    nearest: float
    v0: float  # the command the rows were checked against
    w0: float

    @property
    def a(self) -> FloatArray:
        row: FloatArray = self.abc[0]
        return row

    @property
    def b(self) -> FloatArray:
        row: FloatArray = self.abc[1]
        return row

    @property
    def c(self) -> FloatArray:
        row: FloatArray = self.abc[2]
        return row

    def margins(self, point: IntArray, state: npt.NDArray[np.bool_]) -> FloatArray:
        """The margins m_i of (S) rows (``state``) and (C) rows of the given points (m)."""
        extra = self.omega_cmd[point] * self.k_cmd * np.maximum(self.u_ref[point], 0.0)
        if self.alpha_m_state_extra is not None:
            extra = np.where(state, self.alpha_m_state_extra[point] / self.alpha, extra)
        else:
            extra = np.where(state, 0.0, extra)
        out: FloatArray = self.margin_m + extra
        return out


class _Scene(NamedTuple):
    """One cycle's settings, shared by the command's check and the solve. (Like ``_Rows`` and
    ``_Working``, a named tuple: built on every call, it costs a fraction of a frozen
    dataclass.)"""

    profile: RobotProfile
    params: CbfParams
    v0: float
    w0: float
    v_now: float
    w_now: float
    k_now: float
    k_cmd: float
    x_back: float  # the footprint's extents along x (m), its reach from {R}'s origin (m)
    x_front: float
    q_max: float
    shape: _Shape
    # K_now times the current motion's largest approach ahead and behind (m): (S)'s part of
    # ``_reach_sd``, the same for every cover.
    now_f: float
    now_b: float

    def points_in_reach(
        self,
        pts: ObstaclePoints,
        cover: tuple[float, float, float],
        quiet: bool = False,
    ) -> tuple[FloatArray, int, list[tuple[float, float, float]]] | None:
        """The points (an (m, 2) array of x, y), how many are scan points, and the unseen
        edges, that a command of the ``cover`` (v_min <= v <= v_max, |w| <= w_bound) could
        approach faster than their barriers allow; None when there is none, or, ``quiet``,
        when the command itself could approach none of them too fast (then nothing changes it).

        A point farther from the footprint than reach_sd has slack in (S) and (C):
        (S) alpha (sd - margin - K u_now) >= u and (C) alpha (sd - margin) >= u (1 + alpha K)
        with u the largest approach.
        """
        x_back, x_front, q_max = self.x_back, self.x_front, self.q_max
        seen_ahead, seen_behind = pts.seen_ahead_m, pts.seen_behind_m
        reach_f, reach_b = self._reach_sd(*cover)
        if quiet:
            v0, w0 = self.v0, self.w0
            quiet_f, quiet_b = self._reach_sd(v0, v0, w0 if w0 >= 0.0 else -w0)
            if not (seen_ahead - x_front < quiet_f or seen_behind + x_back < quiet_b):
                if pts.count == 0:
                    return None
                index = pts.prepared_index
                r2 = pts.r2
                r2_min = index.r2_sorted[0] if index is not None else r2[r2.argmin()]
                quiet_r = q_max + (quiet_b if quiet_b > quiet_f else quiet_f)
                if r2_min > quiet_r * quiet_r:
                    return None
        xy = _NO_POINTS
        n_scan = pts.count
        if n_scan:
            # One threshold for points ahead and behind: the few more rows a split by side
            # would leave out cost less than its two numpy calls over the whole scan.
            far = q_max + (reach_b if reach_b > reach_f else reach_f)
            xy = pts.xy.compress(pts.r2 <= far * far, 0)  # cheaper than xy[mask]
            n_scan = len(xy)
        # (direction, how far it saw, the footprint's extent that way)
        unseen: list[tuple[float, float, float]] = []
        if seen_ahead - x_front < reach_f:
            unseen.append((1.0, seen_ahead, x_front))
        if seen_behind + x_back < reach_b:
            unseen.append((-1.0, seen_behind, -x_back))
        if n_scan == 0 and not unseen:
            return None
        return xy, n_scan, unseen

    def _reach_sd(self, v_min: float, v_max: float, w_bound: float) -> tuple[float, float]:
        """How far from the footprint (m) a point ahead and a point behind can have its barrier
        violated by a command with v in [``v_min``, ``v_max``] and |w| <= ``w_bound``."""
        p, k, f_now, b_now = self.params, self.k_cmd, self.now_f, self.now_b
        turn, v_lo = self.q_max * w_bound, -v_min
        # max(a, b) written as b if b > a else a (the builtin's result, without its call).
        u_f = (0.0 if v_max < 0.0 else v_max) + turn
        u_b = (0.0 if v_lo < 0.0 else v_lo) + turn
        f_cmd, b_cmd, margin, alpha = u_f * k, u_b * k, p.margin_m, p.alpha_per_s
        return (
            margin + u_f / alpha + (f_now if f_now > f_cmd else f_cmd),
            margin + u_b / alpha + (b_now if b_now > b_cmd else b_cmd),
        )

    def _creep_bound(self) -> float:
        """A distance (m) beyond which no point's creep changes its row (``rows`` skips the
        creep's calls when every point is farther): the creep is kappa sd^+ <= CREEP_PER_S sd^+,
        and a point that can creep (U < CREEP_BELOW v_max) is approached by the current motion
        at u_now <= U max(|v_now| / v_max, |w_now| / w_max) = CREEP_BELOW v_max s_now, so its
        slack in (S), alpha (sd - margin) - alpha K_now omega u_now^+ (and so in (C)), is
        above its creep where (alpha - CREEP_PER_S) sd > alpha (margin + K_now CREEP_BELOW
        v_max s_now): min(bound, -creep) is then min(bound, -0.0) to the bit. Widened far
        beyond any rounding; inf when alpha <= CREEP_PER_S."""
        p, profile = self.params, self.profile
        alpha = p.alpha_per_s
        if alpha <= CREEP_PER_S:
            return math.inf
        v_max = profile.v_max_mps
        v_now, w_now = abs(self.v_now), abs(self.w_now)
        s_now = max(v_now / v_max, w_now / profile.w_max_radps)
        bound = alpha * (p.margin_m + self.k_now * CREEP_BELOW * v_max * s_now)
        return bound / (alpha - CREEP_PER_S) * (1.0 + 1e-9) + 1e-9

    @overload
    def rows(
        self,
        xy: FloatArray,
        n_scan: int,
        unseen: list[tuple[float, float, float]],
        clear_test: Literal[False] = False,
    ) -> _Rows: ...

    @overload
    def rows(
        self,
        xy: FloatArray,
        n_scan: int,
        unseen: list[tuple[float, float, float]],
        clear_test: Literal[True],
    ) -> _Rows | _Clear: ...

    def rows(
        self,
        xy: FloatArray,
        n_scan: int,
        unseen: list[tuple[float, float, float]],
        clear_test: bool = False,
    ) -> _Rows | _Clear:
        """The half-plane of each point (module docstring), the tighter of its (S) and (C).

        On the few dozen points in reach numpy's cost per call, not per element, is the time:
        each quantity is one call, written where it is read, in one pass:

        1. each point's sd_i, n_i and q_i (``_geometry``; the unseen edges as walls across the
           axis), its row's normal (a, b) = (-n_x, n_x q_y - n_y q_x), and the approach speeds
           u_i = n_x v - b_i w = -(a v + b w) under the command and the current motion;
        2. with ``clear_test``, ``_Clear`` when the command provably keeps every row, a test
           cheaper than the rows for the common case (careful driving: points in reach, none
           approached too fast): omega_i <= 1, creep >= 0 and K_now <= K_cmd make
           u_ref^+ + alpha K_cmd max(u_ref^+, u_now^+) <= alpha (sd_i - margin) sufficient for
           (S) and (C). Its rounding (~1e-15) is far inside the rows' tolerance ``_TOL``: it
           never says CLEAR where the rows would not (``test_cbf``: it agrees with them);
        3. omega_i, the creep (its calls skipped when no row can creep), (S), (C) and c."""
        p, alpha, profile = self.params, self.params.alpha_per_s, self.profile
        v0, w0, v_now, w_now = self.v0, self.w0, self.v_now, self.w_now
        box = self.shape.box
        if box is not None and len(xy):
            sd, nx, ny, q, nearest = _box_geometry(xy, box)
        else:
            sd, nx, ny, q, nearest = _geometry(xy, self.shape)
        points = xy
        if unseen:
            # A wall across the axis where the laser stopped seeing, met first by the
            # footprint's front (back) extent: n = (+-1, 0), q = (front or back, 0).
            points = np.concatenate((xy, [(s * seen, 0.0) for s, seen, _ in unseen]))
            sd = np.concatenate((sd, [seen - ext for _, seen, ext in unseen]))
            nx = np.concatenate((nx, [s for s, _, _ in unseen]))
            ny = np.concatenate((ny, [0.0] * len(unseen)))
            q = np.concatenate((q, [complex(s * ext) for s, _, ext in unseen]))
            nearest = _min(sd)
        n = sd.size
        abc = np.empty((3, n))
        ab = abc[:2]
        np.negative(nx, out=abc[0])
        np.subtract(nx * q.imag, ny * q.real, out=abc[1])
        u_ref = np.array((-v0, -w0)).dot(ab)
        up_ref = np.maximum(u_ref, _ZERO)
        up_now: FloatArray | None = None  # None at rest
        if v_now == v0 and w_now == w0:  # a replay, a steady cycle: the same speeds twice
            if v_now or w_now:
                up_now = up_ref
        elif v_now or w_now:
            up_now = np.maximum(np.array((-v_now, -w_now)).dot(ab), _ZERO)
        # bounds: (S)'s c and (C)'s before its gain; (C)'s = alpha (margin - sd) for now (the
        # clip by -creep comes below).
        bounds = np.empty((2, n))
        bound_s, room = bounds[0], bounds[1]
        np.multiply(sd, -alpha, out=room)
        room += alpha * p.margin_m
        if clear_test:
            ak = alpha * self.k_cmd
            if up_now is None or up_now is up_ref:
                need = np.multiply(up_ref, 1.0 + ak)
            else:
                need = np.maximum(up_ref, up_now)
                need *= ak
                need += up_ref
            need += room
            if need[need.argmax()] <= 0.0:
                return _Clear(n, nearest)
        # How squarely each point lies in the commanded (current) motion's path (omega).
        omega_cmd = _omega(up_ref, v0, w0, q)
        neg_creep: FloatArray | None = None  # None: -0.0 for every row
        no_creep = nearest > self._creep_bound() or (
            nearest > 0.0 and _min(np.abs(nx)) >= CREEP_BELOW
        )
        if not no_creep:
            # kappa = CREEP_PER_S (1 - U / (CREEP_BELOW v_max))^+ as one dot product of the
            # constants with (|n_x|, |b|): U = |n_x| v_max + |b| w_max. (Else the creep changes
            # no row: every point beyond ``_creep_bound``, or |n_x| >= CREEP_BELOW for every
            # row, which makes U >= CREEP_BELOW v_max, so every kappa is 0 (to rounding) and,
            # with every sd > 0, every creep +0.0: the general form's numbers without its calls.)
            scale = CREEP_PER_S / (CREEP_BELOW * profile.v_max_mps)
            weights = np.array((scale * profile.v_max_mps, scale * profile.w_max_radps))
            kappa = np.subtract(_CREEP_PER_S, weights.dot(np.abs(ab)))
            creep = np.maximum(kappa, _ZERO, out=kappa)
            creep *= np.maximum(sd, _ZERO)
            neg_creep = np.negative(creep, out=creep)
        # bounds[0] = -max(alpha (sd - margin - m_extra), creep), (S)'s c with m_extra =
        # omega K u^+ at the current speed; bounds[1] = -max(alpha (sd - margin), creep), (C)'s
        # c before its division by the gain. Written min(alpha (margin - sd) [+ alpha m_extra],
        # -creep), with alpha m_extra = (alpha K omega) u^+, whose first factor is the gain's.
        ak_omega: FloatArray | None = None
        alpha_m_extra: FloatArray | None = None
        if up_now is not None:
            if up_now is up_ref:
                omega_now = omega_cmd
            else:
                omega_now = _omega(up_now, v_now, w_now, q)
            ak_omega = (alpha * self.k_now) * omega_now
            alpha_m_extra = ak_omega * up_now
            np.add(room, alpha_m_extra, out=bound_s)
            if omega_now is not omega_cmd or self.k_now != self.k_cmd:
                ak_omega = None
        else:
            bound_s[:] = room
        if neg_creep is None:
            np.minimum(bounds, _NEG_ZERO, out=bounds)
        else:  # row by row: broadcasting (n,) against (2, n) costs about twice as much
            np.minimum(bound_s, neg_creep, out=bound_s)
            np.minimum(room, neg_creep, out=room)
        # (C): -gain u >= bounds[1], i.e. -u >= bounds[1] / gain; the point's row is the
        # tighter of (S) and (C): the same normal, the larger c.
        if ak_omega is None:
            ak_omega = (alpha * self.k_cmd) * omega_cmd
        gain = np.add(ak_omega, _ONE, out=ak_omega)
        c = abc[2]
        np.divide(room, gain, out=c)  # room: (C)'s c before its gain, clipped
        np.maximum(bound_s, c, out=c)
        # The command falls short of each row by c + u (if positive). (Finite, as every
        # input is: none violated is max(short) <= _TOL.)
        short = c + u_ref
        return _tuple_new(_Rows, (
            points, n_scan, n, sd, abc, short, bounds, gain, alpha_m_extra, alpha, omega_cmd,
            u_ref, self.k_cmd, p.margin_m, (short > _TOL_0D).nonzero()[0], nearest, v0, w0,
        ))  # fmt: skip


class _Edges:
    """A polygon's edges laid out for ``_polygon_nearest``: starts s and vectors e as x + i y,
    e's components and squared lengths, each repeated once per point (``tiled``), so that
    every step is one numpy call on two arrays of the same shape. (Broadcasting m points
    against N edges costs about three times as much per call on a few dozen points.) The
    repeats grow as needed; a mutable cache behind the frozen ``_Shape``."""

    def __init__(self, fp: Footprint) -> None:
        edges = fp._edges
        if edges is None:
            raise ValueError("a polygon footprint has edges")
        start, edge, length2 = edges
        self.count = len(start)
        self._base = (
            np.ascontiguousarray(start).view(np.complex128).ravel(),
            np.ascontiguousarray(edge).view(np.complex128).ravel(),
            np.ascontiguousarray(edge[:, 0]),
            np.ascontiguousarray(edge[:, 1]),
            np.ascontiguousarray(length2),
        )
        self._tiles = self._repeat(64)

    def _repeat(
        self, m: int
    ) -> tuple[int, ComplexArray, ComplexArray, FloatArray, FloatArray, FloatArray, IntArray]:
        start, edge, ex, ey, length2 = self._base
        s: ComplexArray = np.tile(start, m)
        e: ComplexArray = np.tile(edge, m)
        return (
            m, s, e, np.tile(ex, m), np.tile(ey, m), np.tile(length2, m),
            np.arange(0, m * self.count, self.count),
        )  # fmt: skip

    def tiled(
        self, m: int
    ) -> tuple[ComplexArray, ComplexArray, FloatArray, FloatArray, FloatArray, IntArray]:
        """s, e, e_x, e_y, |e|^2 for m points (m x N, point-major) and each point's offset."""
        tiles = self._tiles
        if tiles[0] < m:
            tiles = self._tiles = self._repeat(max(m, 2 * tiles[0]))
        k = m * self.count
        return tiles[1][:k], tiles[2][:k], tiles[3][:k], tiles[4][:k], tiles[5][:k], tiles[6][:m]


class _Box:
    """A rectangle centred on {R}: its corners (-half_l, -half_w) and (half_l, half_w), each
    repeated as an (m, 2) array for ``_box_geometry`` (``_Edges``' reason: same-shape calls)."""

    def __init__(self, half_l: float, half_w: float) -> None:
        self.half_l, self.half_w = half_l, half_w
        self._high = np.array([[half_l, half_w]])
        self.corners: tuple[int, FloatArray, FloatArray] = (0, _NO_POINTS, _NO_POINTS)
        self.repeat(64)

    def repeat(self, m: int) -> tuple[int, FloatArray, FloatArray]:
        """(rows, low, high): the corners repeated for at least m points (kept in
        ``corners``, which grows when a scan needs more)."""
        size = max(m, 2 * self.corners[0])
        high: FloatArray = np.tile(self._high, (size, 1))
        self.corners = (size, -high, high)
        return self.corners


class _Shape(NamedTuple):
    """What the filter reads of a footprint, derived once per shape (``_shape``)."""

    x_back: float  # the footprint's extents along x (m), its reach from {R}'s origin (m)
    x_front: float
    reach: float
    footprint: Footprint
    box: _Box | None  # a centred rectangle
    edges: _Edges | None  # a polygon's
    # A distance from a polygon's edge beyond which no point is inside it: half the shorter
    # side of its bounding box (a point inside is nearer the box's edge than that, and the
    # box holds the polygon), widened far beyond any rounding.
    inside_bound: float


# ``_shape``'s cache, by the footprint's identity (its hash runs over its vertices, microseconds
# on every call); each entry keeps its footprint alive, so an id is never reused while cached.
_SHAPES: dict[int, tuple[Footprint, _Shape]] = {}


def _shape(fp: Footprint) -> _Shape:
    """``_Shape`` of a footprint (numpy reductions: once per footprint, not per call)."""
    hit = _SHAPES.get(id(fp))
    if hit is not None and hit[0] is fp:
        return hit[1]
    x0, x1, y0, y1 = fp.bounds
    half = fp.centred_box
    box = None if half is None else _Box(*half)
    edges = None if fp.is_disc or box is not None else _Edges(fp)
    inside = 0.5 * min(x1 - x0, y1 - y0) * (1.0 + 1e-9) + 1e-9
    shape = _Shape(x0, x1, fp.reach_m, fp, box, edges, inside)
    if len(_SHAPES) >= 32:
        _SHAPES.clear()
    _SHAPES[id(fp)] = (fp, shape)
    return shape


def _min(a: FloatArray) -> float:
    """min of a non-empty array (the element ``argmin`` finds: a reduction costs ~3x)."""
    return float(a[a.argmin()])


def _geometry(
    xy: FloatArray, shape: _Shape
) -> tuple[FloatArray, FloatArray, FloatArray, ComplexArray, float]:
    """Signed distance sd, unit normal (n_x, n_y) and the footprint's nearest point q (as
    x + i y) of each point of the (m, 2) ``xy``, and min(sd) (inf for no point). The normal is
    the gradient of sd: from q towards the point outside, from the point towards q inside (the
    outward normal of the nearest edge)."""
    if len(xy) == 0:
        return _EMPTY, _EMPTY, _EMPTY, _EMPTY_C, math.inf
    if shape.box is not None:
        return _box_geometry(xy, shape.box)
    x, y = xy.T
    fp = shape.footprint
    if shape.edges is None:  # a disc
        r = np.sqrt(x * x + y * y)
        radius = fp.radius_m
        sd = r - radius
        nearest = _min(sd)
        if nearest > -radius:  # no point at the centre (r = 0 would give sd = -radius)
            nx, ny = x / r, y / r
        else:
            centre = r <= 0.0
            safe = np.where(centre, 1.0, r)
            nx, ny = np.where(centre, 1.0, x / safe), np.where(centre, 0.0, y / safe)
        q = np.empty(sd.size, dtype=np.complex128)
        np.multiply(nx, radius, out=q.real)
        np.multiply(ny, radius, out=q.imag)
        return sd, nx, ny, q, nearest
    p = np.ascontiguousarray(xy).view(np.complex128).ravel()
    q, pq, dist = _polygon_nearest(p, shape.edges)
    dx, dy = pq.real, pq.imag
    nearest = _min(dist)
    if nearest > shape.inside_bound:  # every point outside and off the edge: sd = dist, n = d / sd
        return dist, dx / dist, dy / dist, q, nearest
    candidates = dist <= shape.inside_bound
    inside = np.zeros(dist.size, dtype=np.bool_)
    inside[candidates] = signed_distance(fp, x[candidates], y[candidates]) < 0.0
    sd = np.where(inside, -dist, dist)
    on_edge = dist <= 0.0
    safe = np.where(on_edge, 1.0, dist)
    sign = np.where(sd < 0.0, -1.0, 1.0)  # inside: towards the edge, i.e. outwards
    nx, ny = sign * dx / safe, sign * dy / safe
    if on_edge.any():  # on the edge itself: away from the origin, as outwards as any
        r = np.maximum(np.sqrt(x * x + y * y), _SAME)
        nx, ny = np.where(on_edge, x / r, nx), np.where(on_edge, y / r, ny)
    return sd, nx, ny, q, _min(sd)


def _polygon_nearest(
    p: ComplexArray, edges: _Edges
) -> tuple[ComplexArray, ComplexArray, FloatArray]:
    """The polygon's nearest boundary point q of each point p (x + i y), p - q and |p - q|:
    ``closest_boundary_xy``'s arithmetic (the projection onto each edge, clamped to it, the
    nearest of those; a point on an edge keeps its exact zero distance), with x + i y in one
    complex number where that is exact (sums, products by a real), and |p - q| as ``np.abs``
    (hypot: one call, equal to the square root of the sum of squares to rounding). Each point
    against each edge as one (m N,) array, point-major (``_Edges.tiled``)."""
    m = p.size
    s, e, ex, ey, length2, offsets = edges.tiled(m)
    pr = p.repeat(edges.count)
    d = pr - s
    t = d.real * ex
    t += d.imag * ey
    t /= length2
    np.minimum(np.maximum(t, _ZERO, out=t), _ONE, out=t)
    c = t * e
    c += s  # the nearest point of each edge
    r = np.subtract(pr, c, out=d)  # p minus it
    dist = np.abs(r)
    k = dist.reshape(m, edges.count).argmin(axis=1)
    k += offsets
    return c.take(k), r.take(k), dist.take(k)


def _box_geometry(
    xy: FloatArray, box: _Box
) -> tuple[FloatArray, FloatArray, FloatArray, ComplexArray, float]:
    """``_geometry`` of the rectangle ``box``, in closed form, on the C-contiguous (m, 2) ``xy``:
    q is xy clamped to the corners, |p - q| the modulus of x + i y (a view; hypot on the
    columns costs ~3x), n = (p - q) / |p - q|."""
    m = len(xy)
    size, low, high = box.corners
    if size < m:
        size, low, high = box.repeat(m)
    q = np.minimum(np.maximum(xy, low[:m]), high[:m])
    d = np.subtract(xy, q)
    sd = np.abs(d.view(np.complex128)).ravel()
    dx, dy = d[:, 0], d[:, 1]
    nearest = float(sd[sd.argmin()])
    if nearest > 0.0:  # no point inside
        return sd, dx / sd, dy / sd, q.view(np.complex128).ravel(), nearest
    half_l, half_w = box.half_l, box.half_w
    x, y, qx, qy = xy[:, 0], xy[:, 1], q[:, 0], q[:, 1]
    inside = sd <= 0.0
    xi, yi = x[inside], y[inside]
    to_front, to_back = half_l - xi, xi + half_l
    to_left, to_right = half_w - yi, yi + half_w
    depth = np.minimum(np.minimum(to_front, to_back), np.minimum(to_left, to_right))
    ex = np.where(to_front == depth, 1.0, np.where(to_back == depth, -1.0, 0.0))
    ey = np.where(ex != 0.0, 0.0, np.where(to_left == depth, 1.0, -1.0))
    dx[inside], dy[inside] = ex, ey  # the outward normal of the nearest edge, of length 1
    qx[inside] = np.where(ex != 0.0, ex * half_l, xi)
    qy[inside] = np.where(ey != 0.0, ey * half_w, yi)
    sd[inside] = -depth
    norm = np.where(inside, 1.0, sd)
    return sd, dx / norm, dy / norm, q.view(np.complex128).ravel(), _min(sd)


def _omega(up: FloatArray, v: float, w: float, q: ComplexArray) -> FloatArray:
    """(cos of the angle between n_i and the velocity of q_i under (v, w))^PATH_POWER from
    u_i^+ (``up``), 0 for points the footprint does not approach: cos = u / |velocity|, the
    velocity v + i w q = (v - w q_y, w q_x) (q times i w is (-w q_y, w q_x) to the bit: each
    part one product and an exact zero), its length the modulus of x + i y (``np.abs``: within
    an ulp of hypot's, at a tenth of hypot's instructions on the real and imaginary views)."""
    if w == 0.0:
        if v == 0.0:
            return np.zeros(up.size)
        cos = up / abs(v)  # u = nx v <= |v|, no overflow, even for a subnormal v
    else:
        vel = q * complex(0.0, w)
        vel += v
        speed = np.abs(vel)
        cos = np.divide(up, np.maximum(speed, _SAME_SPEED_0D, out=speed), out=speed)
    np.minimum(cos, _ONE, out=cos)
    np.square(cos, out=cos)
    cos *= cos
    return cos


def _solve(
    abc: FloatArray,
    short: FloatArray,
    violated: IntArray,
    v0: float,
    w0: float,
    sv: float,
    sw: float,
    profile: RobotProfile,
    k: int,
) -> tuple[float, float, int, CbfCase, IntArray]:
    """Cutting planes over the rows a v + b w >= c (module docstring; ``abc``: the (3, N) rows
    a, b, c): the ``k`` most violated rows first, then each round the ``k`` most violated by
    the last answer. Returns the answer, the rounds, the case and the working set. ``short``:
    by how much the command falls short of each row (m/s, > 0: violated; ``violated``: the
    rows above the tolerance): the order in which rows join, not the answer."""
    working = _most_violated(short, k, violated)
    for rounds in range(1, _MAX_ROUNDS + 1):
        # Only the working rows become Python floats.
        a, b, c = abc.take(working, 1).tolist()
        found = _project(a, b, c, v0, w0, sv, sw, profile)
        if found is None:
            break
        v, w = found
        # c - (a v + b w): every row's shortfall (``np.dot`` of a tuple costs twice as much).
        short = np.array((-v, -w, 1.0)).dot(abc)
        if short[short.argmax()] <= _TOL:
            return v, w, rounds, _SOLVED, working
        add = _most_violated(short, k, (short > _TOL_0D).nonzero()[0])
        working = np.concatenate((working, add))
    v, w = _stop_and_turn(abc[1], abc[2], w0, profile)
    return v, w, _MAX_ROUNDS, CbfCase.STOP_TURN, working


def _most_violated(short: FloatArray, k: int, bad: IntArray) -> IntArray:
    """Indices of the (at most) ``k`` rows with the largest ``short`` above the tolerance
    (``bad``: every such row, in order)."""
    if bad.size > k:
        if bad.size == short.size:  # every row: the same partition without the indexing
            return (-short).argpartition(k)[:k]
        bad = bad.take((-short.take(bad)).argpartition(k)[:k])
    return bad


def _project(
    a: list[float],
    b: list[float],
    c: list[float],
    v0: float,
    w0: float,
    sv: float,
    sw: float,
    profile: RobotProfile,
) -> tuple[float, float] | None:
    """The closest point to (v0, w0) (weighted) in the polygon of the rows a v + b w >= c and
    the box, or None when none of the candidates is feasible (empty polygon, through rounding).
    Solved in z = (sv v, sw w), where the distance is Euclidean (rows a / sv, b / sw, c); the
    box's rows join only when the answer without them leaves it."""
    isv, isw = 1.0 / sv, 1.0 / sw
    z0x, z0y = sv * v0, sw * w0
    vm, wm = profile.v_max_mps, profile.w_max_radps
    checks: list[tuple[float, float, float, float]] | None = None
    found = _first_projection(a, b, c, isv, isw, z0x, z0y)
    if found is None:
        checks, bad = _checks(a, b, c, isv, isw, z0x, z0y)
        found = _nearest_in(checks, bad, z0x, z0y)
    if found is not None and abs(found[0]) <= sv * vm and abs(found[1]) <= sw * wm:
        return found[0] / sv, found[1] / sw
    if checks is None:
        checks, bad = _checks(a, b, c, isv, isw, z0x, z0y)
    low_v, low_w = -_TOL * (1.0 + abs(-vm)), -_TOL * (1.0 + abs(-wm))
    for gx, gy, ae, low in (
        (isv, 0.0, -vm, low_v), (-isv, 0.0, -vm, low_v),
        (0.0, isw, -wm, low_w), (0.0, -isw, -wm, low_w),
    ):  # fmt: skip
        if gx * z0x + gy * z0y - ae < 0.0:
            bad.append(len(checks))
        checks.append((gx, gy, ae, low))
    found = _nearest_in(checks, bad, z0x, z0y)
    return None if found is None else (found[0] / sv, found[1] / sw)


def _checks(
    a: list[float],
    b: list[float],
    c: list[float],
    isv: float,
    isw: float,
    z0x: float,
    z0y: float,
) -> tuple[list[tuple[float, float, float, float]], list[int]]:
    """The rows scaled to z, as (gx, gy, e, the tolerance of the feasibility test), those with a
    normal (one without cannot bind), and the places of the ones z0 violates, in order."""
    tol, same = -_TOL, _SAME
    checks: list[tuple[float, float, float, float]] = []
    bad: list[int] = []
    add_check, add_bad = checks.append, bad.append
    for ax, ay, ae in zip(a, b, c, strict=True):
        gx = ax * isv
        gy = ay * isw
        if gx * gx + gy * gy > same:
            if gx * z0x + gy * z0y < ae:
                add_bad(len(checks))
            add_check((gx, gy, ae, tol * (1.0 + (ae if ae >= 0.0 else -ae))))
    return checks, bad


def _first_projection(
    a: list[float],
    b: list[float],
    c: list[float],
    isv: float,
    isw: float,
    z0x: float,
    z0y: float,
) -> tuple[float, float] | None:
    """``_nearest_in``'s answer on the rows ``_checks`` makes of a, b, c, in its commonest case,
    without making them: when the first row with a normal is violated by z0 (every working
    row is, in the solver's first round), its projection is ``_nearest_in``'s first
    candidate, and the answer when it meets every row to the same tolerance. That candidate,
    or None when the case does not hold (``test_cbf``: the two agree)."""
    tol, same = -_TOL, _SAME
    for ax, ay, ae in zip(a, b, c, strict=True):
        gx = ax * isv
        gy = ay * isw
        if gx * gx + gy * gy > same:
            if not gx * z0x + gy * z0y < ae:
                return None
            step = (ae - gx * z0x - gy * z0y) / (gx * gx + gy * gy)
            zx, zy = z0x + step * gx, z0y + step * gy
            break
    else:
        return None
    for ax, ay, ae in zip(a, b, c, strict=True):
        gx = ax * isv
        gy = ay * isw
        if gx * gx + gy * gy > same and not (
            gx * zx + gy * zy - ae >= tol * (1.0 + (ae if ae >= 0.0 else -ae))
        ):
            return None
    return zx, zy


def _nearest_in(
    checks: list[tuple[float, float, float, float]], bad: list[int], z0x: float, z0y: float
) -> tuple[float, float] | None:
    """The point of {z : gx zx + gy zy >= e} nearest to z0 (Euclidean; ``checks``: (gx, gy, e,
    the tolerance of the feasibility test) of each row; ``bad``: those z0 violates, in
    order), or None when no candidate is feasible. A few rows (the working set): plain Python
    beats numpy's per-call cost here."""
    if not bad:
        return z0x, z0y
    # One line: the projection onto a violated row, optimal whenever feasible (KKT).
    for i in bad:
        ax, ay, ae, _ = checks[i]
        step = (ae - ax * z0x - ay * z0y) / (ax * ax + ay * ay)
        zx, zy = z0x + step * ax, z0y + step * ay
        for gx, gy, ge, low in checks:
            if not gx * zx + gy * zy - ge >= low:
                break
        else:  # feasible
            return zx, zy
    # Two lines: a vertex, one of whose rows the command violates (else KKT would put the
    # optimum at the command itself); the feasible one nearest the command.
    best: tuple[float, float] | None = None
    best_d2 = math.inf
    violated = set(bad)
    for i in bad:
        gxi, gyi, ei, _ = checks[i]
        bound_i = _SAME * math.hypot(gxi, gyi)
        for j, (gxj, gyj, ej, _) in enumerate(checks):
            if j == i or (j < i and j in violated):
                continue
            det = gxi * gyj - gyi * gxj
            if abs(det) <= bound_i * math.hypot(gxj, gyj):
                continue
            zx = (ei * gyj - ej * gyi) / det
            zy = (gxi * ej - gxj * ei) / det
            d2 = (zx - z0x) ** 2 + (zy - z0y) ** 2
            if d2 < best_d2 and _feasible(checks, zx, zy):
                best, best_d2 = (zx, zy), d2
    return best


def _feasible(checks: list[tuple[float, float, float, float]], zx: float, zy: float) -> bool:
    """z meets every row to its tolerance (a loop: all() over a generator costs more)."""
    for ax, ay, ae, low in checks:  # noqa: SIM110
        if not ax * zx + ay * zy - ae >= low:
            return False
    return True


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
