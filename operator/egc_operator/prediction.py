"""Predictive display (DESIGN 9): where the robot will be when the command now being sent acts.

The operator sees the robot as it was ``view age`` ago (the newest telemetry's stamp, on the
robot's clock), and the command it sends now reaches the robot an uplink delay later. Between the
two, the robot keeps executing the commands the operator has already sent. ``predict`` replays
them open loop from the newest measured pose:

- The command in effect at robot time t is the newest sent command with ``stamp + uplink <= t``
  (zero-order hold); before the first of them takes effect, the reference the telemetry reports
  (``v_ref``, ``w_ref``) is in effect.
- A command becomes a velocity by eq. 4 (v = x v_max, w = y w_max; the deadzone was applied
  before the command was sent), scaled as a whole by the latency governor's cap
  ``v_lim_latency`` and on the turn rate ``w_lim_latency`` when the robot reports them (DESIGN 9).
- The velocity ramps toward it at the profile's acceleration limits (braking at the
  deceleration limit), starting from the telemetry's ``v_cmd``, ``w_cmd``, and the unicycle is
  integrated on exact arcs over steps of at most ``step_s``, split where a command takes effect.
- A robot that is not DRIVING (HOLD, ESTOP, IDLE) is predicted to stop, decelerating at the
  profile's limits; so is one reached by a command with the deadman released (until a centred
  command with the deadman takes effect) or with the e-stop pressed (for good).

It cannot know what the robot's own filter (shared mode) or a collision will do, so the view
draws it as a prediction, never as a measurement. Pure: times are passed in, nothing reads a
clock. ``CommandHistory`` is the operator node's bounded record of the commands it sent.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

from egc_common.kinematics import integrate_arc, ramp_toward, scale_as_whole
from egc_common.messages import Telemetry
from egc_common.profiles import RobotProfile, profile_named

NS_PER_S = 1_000_000_000
NS_PER_MS = 1_000_000
Pose = tuple[float, float, float]

DEFAULT_STEP_S = 0.02
MAX_HORIZON_S = 3.0  # a prediction further ahead than this says nothing useful
HISTORY_MAX_AGE_NS = 4 * NS_PER_S  # MAX_HORIZON_S plus room for the uplink
HISTORY_MAX_LEN = 1024
CENTRED = 0.05  # the robot's default centre tolerance (DESIGN 8)


@dataclass(frozen=True, slots=True)
class SentCommand:
    """One command as the operator sent it; ``stamp_ns`` is on the robot's clock (ClockSync)."""

    stamp_ns: int
    x: float
    y: float
    mode: str = "shared"
    deadman: bool = True
    estop: bool = False


class CommandHistory:
    """The commands sent over the last ``max_age_ns`` (at most ``max_len``), oldest first.

    Stamps must not decrease; a command stamped earlier than the newest one (the robot's clock
    estimate jumped back, e.g. after a robot restart) starts the history over.
    """

    def __init__(self, max_age_ns: int = HISTORY_MAX_AGE_NS, max_len: int = HISTORY_MAX_LEN):
        if max_age_ns <= 0 or max_len < 1:
            raise ValueError("max_age_ns must be > 0 and max_len >= 1")
        self._max_age_ns = max_age_ns
        self._commands: deque[SentCommand] = deque(maxlen=max_len)

    def __len__(self) -> int:
        return len(self._commands)

    def add(self, command: SentCommand) -> None:
        if self._commands and command.stamp_ns < self._commands[-1].stamp_ns:
            self._commands.clear()
        self._commands.append(command)
        oldest = command.stamp_ns - self._max_age_ns
        while self._commands[0].stamp_ns < oldest:
            self._commands.popleft()

    def since(self, stamp_ns: int) -> tuple[SentCommand, ...]:
        """The commands stamped after ``stamp_ns``, preceded by the newest one at or before it
        (the one still in effect at ``stamp_ns``), oldest first."""
        out: list[SentCommand] = []
        for command in reversed(self._commands):
            out.append(command)
            if command.stamp_ns <= stamp_ns:
                break
        out.reverse()
        return tuple(out)

    @property
    def newest(self) -> SentCommand | None:
        return self._commands[-1] if self._commands else None


@dataclass(frozen=True, slots=True)
class Prediction:
    """The predicted pose at ``end_ns`` and the path to it from the measured pose."""

    pose: Pose
    path: tuple[Pose, ...]  # from the measured pose (first) to ``pose`` (last)
    start_ns: int  # the measured pose's stamp (robot clock)
    end_ns: int  # when the command now being sent takes effect (robot clock)
    uplink_ns: int  # the uplink delay estimate used
    velocity: tuple[float, float]  # (v, w) predicted at ``end_ns``
    stopping: bool  # the robot is predicted to stop (not driving, deadman released, e-stop)
    clamped: bool  # the horizon was cut to MAX_HORIZON_S


def uplink_estimate_ms(cmd_age_p50_ms: float | None, rtt_ms: float | None) -> float | None:
    """The uplink delay: the robot's median command age, else half the clock-sync round trip."""
    if cmd_age_p50_ms is not None and math.isfinite(cmd_age_p50_ms):
        return max(0.0, cmd_age_p50_ms)
    if rtt_ms is not None and math.isfinite(rtt_ms):
        return max(0.0, rtt_ms / 2.0)
    return None


def command_velocity(
    command: SentCommand,
    profile: RobotProfile,
    v_lim: float | None,
    w_lim: float | None = None,
) -> tuple[float, float]:
    """Eq. 4 (v = x v_max, w = y w_max), capped as a whole at ``v_lim`` and ``w_lim`` (same
    curvature), as the robot's latency governor does."""
    v = max(-1.0, min(1.0, command.x)) * profile.v_max_mps
    w = max(-1.0, min(1.0, command.y)) * profile.w_max_radps
    return _govern(v, w, v_lim, w_lim)


def _govern(
    v: float, w: float, v_lim: float | None, w_lim: float | None = None
) -> tuple[float, float]:
    """The robot's latency governor (the same ``scale_as_whole``); an unknown cap is none."""
    v, w, _ = scale_as_whole(v, w, _cap(v_lim), _cap(w_lim))
    return v, w


def _cap(limit: float | None) -> float:
    return limit if limit is not None and math.isfinite(limit) else math.inf


def predict(
    pose: Pose,
    stamp_ns: int,
    state: str,
    velocity: tuple[float, float],
    reference: tuple[float, float],
    commands: Sequence[SentCommand],
    now_ns: int,
    uplink_ns: int,
    profile: RobotProfile,
    v_lim: float | None = None,
    step_s: float = DEFAULT_STEP_S,
    w_lim: float | None = None,
) -> Prediction:
    """Advance ``pose`` (measured at ``stamp_ns``) to ``now_ns + uplink_ns``; see the module doc.

    ``velocity`` is what the base was sent at ``stamp_ns`` (v_cmd, w_cmd), ``reference`` the
    operator's command in effect then after eq. 4 (v_ref, w_ref); ``commands`` are the sent
    commands, oldest first (earlier ones than needed are ignored).
    """
    if not step_s > 0:
        raise ValueError("step_s must be > 0")
    uplink_ns = max(0, int(uplink_ns))
    end_ns = max(stamp_ns, now_ns + uplink_ns)
    clamped = end_ns - stamp_ns > MAX_HORIZON_S * NS_PER_S
    if clamped:
        end_ns = stamp_ns + round(MAX_HORIZON_S * NS_PER_S)
    stopping = state != "DRIVING"
    latched_estop = False
    released = False
    target = (0.0, 0.0) if stopping else _govern(*reference, v_lim, w_lim)
    # The commands that take effect within (stamp_ns, end_ns], with their effect times.
    changes = [
        (c.stamp_ns + uplink_ns, c) for c in commands if stamp_ns < c.stamp_ns + uplink_ns <= end_ns
    ]
    before = [c for c in commands if c.stamp_ns + uplink_ns <= stamp_ns]
    if before and not stopping:
        changes.insert(0, (stamp_ns, before[-1]))
    v, w = velocity
    current = pose
    path = [pose]
    t = stamp_ns
    max_step_ns = max(1, round(step_s * NS_PER_S))
    index = 0
    while t < end_ns:
        while index < len(changes) and changes[index][0] <= t:
            command = changes[index][1]
            index += 1
            if stopping:
                continue
            if command.estop:
                latched_estop = True
            if not command.deadman:
                released = True
            elif released and abs(command.x) <= CENTRED and abs(command.y) <= CENTRED:
                released = False
            if latched_estop or released:
                target = (0.0, 0.0)
            else:
                target = command_velocity(command, profile, v_lim, w_lim)
        next_change = changes[index][0] if index < len(changes) else end_ns
        dt_ns = min(max_step_ns, next_change - t, end_ns - t)
        dt = dt_ns / NS_PER_S
        v = ramp_toward(target[0], v, profile.accel_max_mps2 * dt, profile.decel_max_mps2 * dt)
        dw = profile.angular_accel_max_radps2 * dt
        w = ramp_toward(target[1], w, dw, dw)
        current = integrate_arc(current, v, w, dt)
        path.append(current)
        t += dt_ns
    return Prediction(
        pose=current,
        path=tuple(path),
        start_ns=stamp_ns,
        end_ns=end_ns,
        uplink_ns=uplink_ns,
        velocity=(v, w),
        stopping=stopping or latched_estop or released,
        clamped=clamped,
    )


def predict_from_telemetry(
    t: Telemetry,
    commands: Sequence[SentCommand],
    now_ns: int,
    rtt_ms: float | None,
    step_s: float = DEFAULT_STEP_S,
) -> Prediction | None:
    """``predict`` for the newest telemetry; None without a pose or with an unknown profile.

    The uplink is ``uplink_estimate_ms`` (0 when nothing is known yet).
    """
    profile = profile_named(t.profile)
    if t.pose is None or profile is None or now_ns <= 0:
        return None
    uplink_ms = uplink_estimate_ms(t.cmd_age_p50_ms, rtt_ms) or 0.0
    return predict(
        pose=t.pose,
        stamp_ns=t.stamp_ns,
        state=t.state,
        velocity=(t.v_cmd, t.w_cmd),
        reference=(t.v_ref, t.w_ref),
        commands=commands,
        now_ns=now_ns,
        uplink_ns=round(uplink_ms * NS_PER_MS),
        profile=profile,
        v_lim=t.v_lim_latency,
        step_s=step_s,
        w_lim=t.w_lim_latency,
    )


def predict_from_history(
    t: Telemetry, history: CommandHistory, now_ns: int, rtt_ms: float | None
) -> Prediction | None:
    """``predict_from_telemetry`` with the commands of ``history`` that can still act after
    ``t``'s stamp (sent at most one uplink before it): what the view draws as the ghost."""
    uplink_ms = uplink_estimate_ms(t.cmd_age_p50_ms, rtt_ms) or 0.0
    first_ns = t.stamp_ns - round(uplink_ms * NS_PER_MS)
    return predict_from_telemetry(t, history.since(first_ns), now_ns, rtt_ms)
