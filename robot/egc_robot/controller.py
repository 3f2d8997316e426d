"""The robot's per-cycle controller: command acceptance, control ownership, the DESIGN 8 state
machine and the command pipeline, with no IO and no clock (DESIGN 2).

Every method takes the robot's monotonic time in nanoseconds; the Zenoh node (``zenoh_node``),
the headless episode runner and the tests feed it the same way.

Acceptance rules for ``egc/<robot>/cmd`` (DESIGN 7, 8), in this order, each rejection counted by
reason and returned to the caller for logging:

1. strict decoding (``messages.decode_command``: size, msgpack, types, ranges, NaN);
2. age on the robot's clock: ``stamp_ns`` older than ``max_command_age`` or further in the
   future than that is STALE. ``stamp_ns == 0`` means "the operator is not synchronised yet":
   accepted by default (the watchdog then bounds the age from arrival), rejected when
   ``require_clock_sync`` is set;
3. ``seq`` strictly increasing per operator: equal is DUPLICATE_SEQ, lower is OUT_OF_ORDER.
   An operator that was silent for ``release_timeout`` starts a new session (its seq history
   is forgotten), so a restarted operator is not locked out;
4. control: the first operator to send a valid command with the deadman held takes control;
   any other operator's command is NOT_IN_CONTROL. Control is released when the operator's
   liveliness token goes away (explicit release or a lost/hung process) or after
   ``release_timeout`` without a valid command from it.

An e-stop request is honoured from every decodable command, whoever sent it and however old:
stopping is always allowed (DESIGN 1: nothing from the network can do more than stop the robot).

``step`` runs one control cycle: state machine, then ``pipeline.step_command`` while DRIVING,
``safety.decelerate`` in HOLD and IDLE, zero in ESTOP; it returns the base command and the
telemetry of the cycle.

The filter of shared mode is the robot's configured one unless the operator in control picked
another of the family (OperatorCommand ``filter``, DESIGN 6); a filter that keeps memory
(``assist``) starts afresh whenever the filter changes or the robot stops driving. Via points
(``egc/<robot>/goal``, DESIGN 7) are accepted from the operator in control only, and the active
one goes to the filter in {R}.
"""

from __future__ import annotations

import math
from collections import Counter, OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
from egc_common.messages import (
    MAX_CBF_POINTS,
    BaseCommand,
    GoalMessage,
    Odometry,
    OperatorCommand,
    Rejection,
    RejectReason,
    StateMessage,
    Telemetry,
    decode_command,
    decode_goal,
)
from egc_common.scan import ObstaclePoints, Scan
from egc_common.scan_compact import PolarScan, compact

from egc_robot.filters.cbf import CbfResult
from egc_robot.latency_governor import govern, latency_speed_limit, latency_turn_limit
from egc_robot.link_stats import LinkStats
from egc_robot.pipeline import FILTERS, MODES, Limiter, PipelineConfig, PipelineResult, step_command
from egc_robot.safety import decelerate
from egc_robot.state_machine import (
    COMMAND_TIMEOUT,
    LINK_REASONS,
    STALE_COMMANDS,
    Inputs,
    State,
    Transition,
    next_state,
)
from egc_robot.via_points import (
    DEFAULT_TOLERANCE_M,
    NO_ROUTE,
    ViaPoints,
    advance,
    to_robot_frame,
)

NS_PER_S = 1_000_000_000
_NO_POINTS = np.zeros((0, 2), np.float32)
_MAX_TRACKED_OPERATORS = 64
_MAX_SETTING = 3600.0
_STOPPED_EPS = 1e-6
_MAX_DT_S = 0.5


@dataclass(frozen=True, slots=True)
class ControllerConfig:
    """DESIGN 8 parameters (seconds) around the command pipeline's configuration."""

    pipeline: PipelineConfig
    # The pipeline for scans whose sensor declares "no return is free" (REP 117's +inf), when
    # the robot's configuration leaves that to the sensor; None: ``pipeline`` for every scan.
    pipeline_if_free: PipelineConfig | None = None
    max_command_age_s: float = 0.3  # direct mode (DESIGN 8)
    max_command_age_filtered_s: float = 1.0  # shared mode: the filter judges every cycle
    command_timeout_s: float = 0.25
    resume_window_s: float = 2.0  # short-gap resume after a HOLD from the link alone
    link_aware: bool = True  # off: one max age (max_command_age_s), no resume, no governor
    reaction_time_s: float = 0.25  # DESIGN 9: part of the loop delay tau
    blind_time_direct_s: float = 0.5  # DESIGN 9: D = v_max * blind_time
    blind_time_filtered_s: float = 1.0
    latency_turn_cap: bool = True  # the governor caps the turn rate too (latency_governor)
    scan_timeout_s: float = 0.2
    release_timeout_s: float = 2.0
    centre_tolerance: float = 0.05
    require_clock_sync: bool = False
    telemetry_scan_decimation: int = 2
    nominal_period_s: float = 0.05
    via_tolerance_m: float = DEFAULT_TOLERANCE_M  # a via point within this is reached
    # HOLD and IDLE decelerate at the profile's limit (DESIGN 8); False: zero at once, for a
    # base that brakes at its own limits (DESIGN 11: a zero twist in HOLD on ROS 2).
    hold_ramp: bool = True

    def __post_init__(self) -> None:
        for name in (
            "max_command_age_s",
            "max_command_age_filtered_s",
            "resume_window_s",
            "reaction_time_s",
            "blind_time_direct_s",
            "blind_time_filtered_s",
            "command_timeout_s",
            "scan_timeout_s",
            "release_timeout_s",
            "nominal_period_s",
            "via_tolerance_m",
        ):
            value = getattr(self, name)
            unit = "metres" if name.endswith("_m") else "seconds"
            # At most an hour (or 3.6 km): 1e300 overflowed the ns conversion with a traceback.
            if not (isinstance(value, (int, float)) and 0 < value <= _MAX_SETTING):
                raise ValueError(f"{name} must be a positive number of {unit}, at most 3600")
        if not 0.0 <= self.centre_tolerance < 1.0:
            raise ValueError("centre_tolerance must be in [0, 1)")
        if self.telemetry_scan_decimation < 1:
            raise ValueError("telemetry_scan_decimation must be >= 1")

    def filtered(self, mode: str) -> bool:
        """Whether a command in ``mode`` goes through a filter (shared mode, a real filter)."""
        return mode == "shared" and self.pipeline.filter != "none"

    def max_age_s(self, mode: str) -> float:
        """``max_command_age`` for a command in ``mode`` (DESIGN 8: by mode when link-aware)."""
        if self.link_aware and self.filtered(mode):
            return self.max_command_age_filtered_s
        return self.max_command_age_s

    def blind_time_s(self, mode: str) -> float:
        """DESIGN 9: how far ahead the operator may be blind, as time at v_max, by mode."""
        return self.blind_time_filtered_s if self.filtered(mode) else self.blind_time_direct_s


@dataclass(frozen=True, slots=True)
class CommandVerdict:
    """What happened to one received command payload."""

    command: OperatorCommand | None
    rejection: Rejection | None
    took_control: bool = False
    latency_ns: int | None = None  # arrival minus stamp, when the operator is synchronised

    @property
    def accepted(self) -> bool:
        return self.rejection is None


@dataclass(frozen=True, slots=True)
class CycleOutput:
    """One cycle's base command, with its telemetry built on first use.

    The telemetry is a snapshot of the cycle (every value is the one when ``step`` returns) but
    is only assembled when asked for, so that the robot can send the base command first: the
    controller assembles it itself before anything that could change those values (its next
    input or cycle), if nobody asked for it by then.
    """

    base: BaseCommand
    state_changed: StateMessage | None
    result: PipelineResult | None
    _build: Callable[..., Telemetry] = field(repr=False, compare=False)
    _args: tuple[Any, ...] = field(repr=False, compare=False)
    _telemetry: Telemetry | None = field(default=None, init=False, repr=False, compare=False)

    @property
    def telemetry(self) -> Telemetry:
        telemetry = self._telemetry
        if telemetry is None:
            telemetry = self._build(*self._args)
            object.__setattr__(self, "_telemetry", telemetry)
        return telemetry


@dataclass(slots=True)
class _OperatorTrack:
    last_seq: int
    last_rx_ns: int


@dataclass(slots=True)
class _Scan:
    points: ObstaclePoints  # checked when the scan arrives, not on every command
    rx_ns: int
    no_return_is_free: bool = False  # the sensor's declaration (Scan.no_return_is_free)


@dataclass(slots=True)
class Counters:
    accepted: int = 0
    rejected: Counter[str] = field(default_factory=Counter)
    cycles: int = 0

    @property
    def rejected_total(self) -> int:
        return sum(self.rejected.values())


class RobotController:
    """Pure per-cycle robot logic (see the module docstring)."""

    def __init__(self, config: ControllerConfig, start_ns: int) -> None:
        self.config = config
        self.counters = Counters()
        self._transition = Transition(State.IDLE, "no operator")
        self._state_since_ns = start_ns
        self._controller_op: str | None = None
        self._control_epoch = 0  # incremented whenever control is taken or released
        self._driving_epoch = -1
        self._no_operator_reason = "no operator"
        self._command: OperatorCommand | None = None
        self._command_rx_ns = 0
        self._tracks: OrderedDict[str, _OperatorTrack] = OrderedDict()
        self._alive: set[str] = set()
        # Operators whose liveliness token went away: their commands still in flight (or a hung
        # process that wakes up) must not take control again until the token is back.
        self._departed: OrderedDict[str, None] = OrderedDict()
        self._estop_pending = False
        self._scan: _Scan | None = None
        self._telemetry_xy: npt.NDArray[np.float32] | None = None  # of ``_scan``, when asked for
        self._telemetry_polar: PolarScan | None = None  # ... its compact beams (DESIGN 12)
        self._raw_scan: Scan | None = None  # the newest scan as it came, for the compact scan
        self._telemetry_beams: int | None = None  # the downlink budget's scan beams (None: all)
        self._pose: tuple[float, float, float] | None = None
        self._map_pose: tuple[float, float, float] | None = None
        self._route = NO_ROUTE
        self._goal_seq: tuple[str, int] | None = None  # (operator, last accepted goal seq)
        self._filter_memory: object | None = None
        self._memory_filter = ""  # which filter the memory belongs to
        self._previous = (0.0, 0.0)
        self._last_step_ns: int | None = None
        self._last_drive_epoch = -1  # control epoch of the last DRIVING cycle (resume)
        self._stale_rx_ns: int | None = None  # last stale command from the operator in control
        self._last_drive_ns = start_ns
        self._link = LinkStats(
            reaction_time_s=config.reaction_time_s, unknown_part_s=config.command_timeout_s
        )
        # The configuration's times in ns, computed once: as ints where commands are vetted, as
        # the floats the cycle always compared with.
        self._max_age_ns = {mode: int(config.max_age_s(mode) * NS_PER_S) for mode in MODES}
        self._release_ns = int(config.release_timeout_s * NS_PER_S)
        self._fresh_age_ns = {mode: config.max_age_s(mode) * NS_PER_S for mode in MODES}
        self._blind_time_s = {mode: config.blind_time_s(mode) for mode in MODES}
        self._release_after_ns = config.release_timeout_s * NS_PER_S
        self._timeout_ns = config.command_timeout_s * NS_PER_S
        self._scan_timeout_ns = config.scan_timeout_s * NS_PER_S
        self._resume_window_ns = config.resume_window_s * NS_PER_S
        self._unreported: CycleOutput | None = None  # the last cycle, telemetry not built yet

    # -- inputs -------------------------------------------------------------------------------

    @property
    def state(self) -> State:
        return self._transition.state

    @property
    def reason(self) -> str:
        return self._transition.reason

    @property
    def operator(self) -> str | None:
        return self._controller_op

    @property
    def link_totals(self) -> tuple[int, int]:
        """(commands that arrived from the operator in control, seq numbers missing between
        them) over the whole run: the link's loss as the robot measured it."""
        return self._link.received_total, self._link.missing_total

    def on_command(self, payload: object, now_ns: int) -> CommandVerdict:
        """Decode and vet one payload from ``egc/<robot>/cmd``; never raises."""
        if self._unreported is not None:
            self._report()
        decoded = decode_command(payload)
        if isinstance(decoded, Rejection):
            return self._reject(None, decoded, now_ns)
        cmd = decoded
        op = cmd.op
        seq = cmd.seq
        if cmd.estop:
            self._estop_pending = True
        max_age_ns = self._max_age_ns[cmd.mode]
        if op == self._controller_op:
            self._link.on_arrival(seq, now_ns)
        latency_ns: int | None = None
        if cmd.stamp_ns == 0:
            if self.config.require_clock_sync:
                return self._reject(
                    cmd, Rejection(RejectReason.STALE, "operator not synchronised"), now_ns
                )
        else:
            latency_ns = now_ns - cmd.stamp_ns
            if latency_ns > max_age_ns:
                return self._reject(
                    cmd, Rejection(RejectReason.STALE, f"{latency_ns / 1e6:.0f} ms old"), now_ns
                )
            if latency_ns < -max_age_ns:
                return self._reject(
                    cmd,
                    Rejection(RejectReason.STALE, f"stamped {-latency_ns / 1e6:.0f} ms ahead"),
                    now_ns,
                )
        track = self._tracks.get(op)
        if (
            track is not None
            and now_ns - track.last_rx_ns <= self._release_ns  # else a new session of that op
            and seq <= track.last_seq
        ):
            reason = (
                RejectReason.DUPLICATE_SEQ if seq == track.last_seq else RejectReason.OUT_OF_ORDER
            )
            return self._reject(cmd, Rejection(reason, f"seq {seq} after {track.last_seq}"), now_ns)
        if track is not None:
            track.last_seq, track.last_rx_ns = seq, now_ns
            self._tracks.move_to_end(op)
        else:
            self._track(op, seq, now_ns)
        took_control = False
        if self._controller_op is None and cmd.deadman:
            if op in self._departed:
                return self._reject(
                    cmd,
                    Rejection(
                        RejectReason.NOT_IN_CONTROL,
                        f"{op}: its liveliness token is gone (the session ended or was lost)",
                    ),
                    now_ns,
                )
            self._controller_op = op
            self._control_epoch += 1
            self._link.reset()
            self._link.on_arrival(seq, now_ns)
            took_control = True
        if self._controller_op != op:
            holder = self._controller_op or "nobody (hold the deadman to take control)"
            return self._reject(
                cmd,
                Rejection(RejectReason.NOT_IN_CONTROL, f"{op}: control held by {holder}"),
                now_ns,
            )
        self._command = cmd
        self._command_rx_ns = now_ns
        self._link.on_accepted(latency_ns, cmd.view_age_ms, now_ns)
        self.counters.accepted += 1
        return CommandVerdict(cmd, None, took_control, latency_ns)

    @property
    def route(self) -> ViaPoints:
        """The operator's via points and which one is active."""
        return self._route

    def on_goal(self, payload: object, now_ns: int) -> Rejection | None:
        """Decode and vet one payload from ``egc/<robot>/goal``; never raises.

        Only the operator in control may set via points; the seq must increase per operator;
        a frame the driver gives no pose in is refused (the robot could not follow it).
        """
        if self._unreported is not None:
            self._report()
        decoded = decode_goal(payload)
        if isinstance(decoded, Rejection):
            return self._reject_goal(decoded)
        goal: GoalMessage = decoded
        if goal.op != self._controller_op:
            holder = self._controller_op or "nobody"
            return self._reject_goal(
                Rejection(
                    RejectReason.NOT_IN_CONTROL, f"goal from {goal.op}: control held by {holder}"
                )
            )
        if (
            self._goal_seq is not None
            and self._goal_seq[0] == goal.op
            and goal.seq <= self._goal_seq[1]
        ):
            return self._reject_goal(
                Rejection(
                    RejectReason.OUT_OF_ORDER, f"goal seq {goal.seq} after {self._goal_seq[1]}"
                )
            )
        if goal.points and self._pose_in(goal.frame) is None:
            return self._reject_goal(
                Rejection(
                    RejectReason.OUT_OF_RANGE, f"no pose in frame {goal.frame!r} from the driver"
                )
            )
        self._goal_seq = (goal.op, goal.seq)
        current = self._route
        if (current.op, current.frame, current.points) == (goal.op, goal.frame, goal.points):
            return None  # the operator repeats its route (it does, at 1 Hz): keep the progress
        route = ViaPoints(goal.frame, goal.points, goal.op)
        self._route = advance(route, self._pose_in(goal.frame), self.config.via_tolerance_m)
        return None

    def _reject_goal(self, rejection: Rejection) -> Rejection:
        self.counters.rejected["goal_" + rejection.reason.value] += 1
        return rejection

    def _pose_in(self, frame: str) -> tuple[float, float, float] | None:
        return self._map_pose if frame == "map" else self._pose

    def on_scan(self, scan: Scan, now_ns: int) -> None:
        """The newest scan; its arrival time decides freshness (scan_timeout)."""
        if self._unreported is not None:
            self._report()
        self._scan = _Scan(scan.obstacles(), now_ns, scan.no_return_is_free)
        self._raw_scan = scan
        self._telemetry_xy = None  # decimated for the telemetry when it is built
        self._telemetry_polar = None

    @property
    def scan_beams_max(self) -> int | None:
        """The most beams the telemetry's scan can have (the newest scan's beams over
        ``telemetry_scan_decimation``), None before the first scan."""
        raw = self._raw_scan
        if raw is None:
            return None
        return max(1, -(-raw.ranges_m.size // self.config.telemetry_scan_decimation))

    def set_telemetry_beams(self, beams: int | None) -> None:
        """The most scan beams the telemetry may carry (the downlink budget's plan, DESIGN 12;
        None: every beam the ``telemetry_scan_decimation`` leaves)."""
        if beams is not None and beams < 1:
            raise ValueError("beams must be >= 1")
        if beams != self._telemetry_beams:
            if self._unreported is not None:
                self._report()  # the last cycle's telemetry keeps the scan it had
            self._telemetry_beams = beams
            self._telemetry_xy = None
            self._telemetry_polar = None

    def on_odometry(self, odometry: Odometry) -> None:
        if self._unreported is not None:
            self._report()
        self._pose = (odometry.x_m, odometry.y_m, odometry.theta_rad)
        self._map_pose = odometry.map_pose
        if self._route.active is not None:
            pose = self._pose_in(self._route.frame)
            self._route = advance(self._route, pose, self.config.via_tolerance_m)

    def on_operator_alive(self, operator_id: str, alive: bool) -> None:
        """A liveliness token ``alive/operator/<id>`` appeared or went away."""
        if self._unreported is not None:
            self._report()
        if alive:
            self._departed.pop(operator_id, None)
            if operator_id not in self._alive:
                self._tracks.pop(operator_id, None)  # a (re)started operator: new seq session
            if len(self._alive) < _MAX_TRACKED_OPERATORS:
                self._alive.add(operator_id)
            return
        self._alive.discard(operator_id)
        self._departed[operator_id] = None
        self._departed.move_to_end(operator_id)
        while len(self._departed) > _MAX_TRACKED_OPERATORS:
            self._departed.popitem(last=False)
        if operator_id == self._controller_op:
            self._release(f"operator {operator_id} lost")

    def on_base_stopped(self) -> None:
        """The node sent the base a zero command outside a cycle (a failed cycle): the next
        cycle ramps up from standstill instead of resuming the last command at once."""
        self._previous = (0.0, 0.0)

    # -- the control cycle --------------------------------------------------------------------

    def step(self, now_ns: int) -> CycleOutput:
        """One control cycle at ``now_ns``: decide the state, compute and return the base command.

        Only what the base command needs is computed here; the telemetry is built after it has
        been sent (``CycleOutput.telemetry``).
        """
        if self._unreported is not None:
            self._report()
        cfg = self.config
        dt_s = (
            cfg.nominal_period_s
            if self._last_step_ns is None
            else min(max((now_ns - self._last_step_ns) / NS_PER_S, 0.0), _MAX_DT_S)
        )
        self._last_step_ns = now_ns
        self.counters.cycles += 1
        cmd = self._command
        silent_ns = now_ns - self._command_rx_ns
        if self._controller_op is not None and silent_ns > self._release_after_ns:
            self._release(f"operator {self._controller_op} silent")
            cmd = None
        timeout_ns = self._timeout_ns
        timed_out = silent_ns > timeout_ns
        fresh = (
            cmd is not None
            and not timed_out
            and (cmd.stamp_ns == 0 or now_ns - cmd.stamp_ns <= self._fresh_age_ns[cmd.mode])
        )
        stale_arriving = self._stale_rx_ns is not None and now_ns - self._stale_rx_ns <= timeout_ns
        session_kept = cfg.link_aware and self._last_drive_epoch == self._control_epoch
        scan = self._scan
        scan_fresh = scan is not None and now_ns - scan.rx_ns <= self._scan_timeout_ns
        tol = cfg.centre_tolerance
        inputs = Inputs(
            operator_present=self._controller_op is not None,
            command_fresh=fresh,
            deadman=cmd is not None and cmd.deadman,
            centred=cmd is not None and abs(cmd.x) <= tol and abs(cmd.y) <= tol,
            scan_fresh=scan_fresh,
            estop=self._estop_pending,
            reset=cmd is not None and cmd.reset,
            base_stopped=max(abs(self._previous[0]), abs(self._previous[1])) < _STOPPED_EPS,
            same_control=self._driving_epoch == self._control_epoch,
            no_operator_reason=self._no_operator_reason,
            stale_reason=STALE_COMMANDS if not timed_out or stale_arriving else COMMAND_TIMEOUT,
            session_kept=session_kept,
            resume_allowed=session_kept and now_ns - self._last_drive_ns <= self._resume_window_ns,
        )
        self._estop_pending = False
        before = self._transition
        self._transition = next_state(before, inputs)
        changed = self._transition is not before
        if changed:
            self._state_since_ns = now_ns

        result: PipelineResult | None = None
        state = self._transition.state
        self._driving_epoch = self._control_epoch if state is State.DRIVING else -1
        v_lim: float | None = None
        w_lim: float | None = None
        tau_s: float | None = None  # unknown without link awareness: cbf takes its default
        if cfg.link_aware:
            profile = cfg.pipeline.profile
            tau_s = self._link.loop_delay_s(now_ns)
            blind_s = self._blind_time_s[cmd.mode if cmd is not None else "shared"]
            v_lim = latency_speed_limit(tau_s, profile.v_max_mps, profile.decel_max_mps2, blind_s)
            if cfg.latency_turn_cap:
                w_lim = latency_turn_limit(
                    tau_s, profile.w_max_radps, profile.angular_accel_max_radps2, blind_s
                )
        filter_name = self._filter_for(cmd)
        if state is State.DRIVING and cmd is not None and scan is not None:
            self._last_drive_epoch = self._control_epoch
            self._last_drive_ns = self._command_rx_ns  # the gap is timed from this command
            if filter_name != self._memory_filter:
                self._filter_memory, self._memory_filter = None, filter_name
            pipeline = cfg.pipeline
            if scan.no_return_is_free and cfg.pipeline_if_free is not None:
                pipeline = cfg.pipeline_if_free
            result = step_command(
                pipeline,
                cmd.x,
                cmd.y,
                cmd.mode,
                scan.points,
                self._previous,
                dt_s,
                filter_name=filter_name,
                goal_xy_m=None if self._route.active is None else self._goal_in_robot_frame(),
                now_ns=now_ns,
                memory=self._filter_memory,
                loop_delay_s=tau_s,
            )
            self._filter_memory = result.memory
            v, w, limiter = result.v_cmd_mps, result.w_cmd_radps, result.limiter
            if v_lim is not None:
                v, w, capped = govern(v, w, v_lim, math.inf if w_lim is None else w_lim)
                if capped:
                    limiter = Limiter.LATENCY
        elif state is State.ESTOP:
            self._filter_memory = None
            v, w, limiter = 0.0, 0.0, Limiter.ESTOP
        else:
            self._filter_memory = None
            v, w = (
                decelerate(self._previous, dt_s, cfg.pipeline.profile)
                if cfg.hold_ramp
                else (0.0, 0.0)
            )
            limiter = Limiter.WATCHDOG if self.reason in LINK_REASONS else Limiter.HOLD
        self._previous = (v, w)

        base = BaseCommand(stamp_ns=now_ns, seq=self.counters.cycles, linear_mps=v, angular_radps=w)
        shown_filter = filter_name if cmd is not None and cmd.mode == "shared" else "none"
        out = CycleOutput(
            base,
            self.state_message(now_ns) if changed else None,
            result,
            self._telemetry,
            (now_ns, cmd, fresh, v, w, limiter, result, v_lim, w_lim, shown_filter),
        )
        # Nothing the telemetry reports changes before it is built: every input and the next
        # cycle build it first (``_report``) when nobody has asked for it.
        self._unreported = out
        return out

    def state_message(self, now_ns: int) -> StateMessage:
        return StateMessage(
            stamp_ns=now_ns,
            state=self.state.value,
            reason=self.reason,
            operator=self._controller_op,
            rejected=self.counters.rejected_total,
        )

    # -- helpers ------------------------------------------------------------------------------

    def _filter_for(self, cmd: OperatorCommand | None) -> str:
        """The shared-mode filter: the operator's pick when this robot runs it, else ours."""
        default = self.config.pipeline.filter
        if cmd is None or cmd.filter is None or default == "none":
            return default  # a robot configured without a filter stays without one
        return cmd.filter if cmd.filter in FILTERS and cmd.filter != "none" else default

    def _goal_in_robot_frame(self) -> tuple[float, float] | None:
        active = self._route.active
        pose = self._pose_in(self._route.frame)
        if active is None or pose is None:
            return None
        return to_robot_frame(active, pose)

    def _report(self) -> None:
        """Build the last cycle's telemetry before the state it reports changes."""
        out = self._unreported
        self._unreported = None
        if out is not None:
            out.telemetry  # noqa: B018 (kept on the output)

    def _telemetry(
        self,
        now_ns: int,
        cmd: OperatorCommand | None,
        fresh: bool,
        v: float,
        w: float,
        limiter: Limiter,
        result: PipelineResult | None,
        v_lim: float | None,
        w_lim: float | None,
        shown_filter: str,
    ) -> Telemetry:
        """The telemetry of the cycle at ``now_ns``, from the state that cycle left (which stays
        as it is until the telemetry is built, see ``step``)."""
        self._unreported = None
        link = self._link.figures(now_ns)
        scan = self._scan
        scan_xy = self._telemetry_xy
        if scan_xy is None:
            scan_xy, self._telemetry_polar = self._telemetry_scan()
            self._telemetry_xy = scan_xy
        route = self._route
        # Guide circles for the view only from egc: ek-egc's live in the EK space, not in {R}.
        filtered = result.filtered if result is not None and result.filter_name == "egc" else None
        if cmd is None:
            cmd_age_ms = None
        else:
            since = cmd.stamp_ns if cmd.stamp_ns else self._command_rx_ns
            cmd_age_ms = (now_ns - since) / 1e6
        return Telemetry(
            seq=cmd.seq if cmd is not None else 0,
            stamp_ns=now_ns,
            state=self.state.value,
            mode=cmd.mode if cmd is not None else "shared",
            v_ref=result.v_ref_mps if result is not None else 0.0,
            w_ref=result.w_ref_radps if result is not None else 0.0,
            v_cmd=v,
            w_cmd=w,
            w_si=result.w_si if result is not None else (1.0 if fresh else 0.0),
            region=result.region.value if result is not None else "safe",
            side=result.side.value if result is not None and result.side is not None else None,
            limiter=limiter.value,
            igc=filtered.igc if filtered is not None else None,
            agc=filtered.agc if filtered is not None else None,
            egc=filtered.egc if filtered is not None else None,
            r_rc=filtered.r_rc_m if filtered is not None else 0.0,
            scan_xy=scan_xy,
            pose=self._pose,
            cmd_age_ms=cmd_age_ms,
            # A scan the driver's thread received after this cycle read its clock is 0 old,
            # not a fraction of a millisecond from the future.
            scan_age_ms=None if scan is None else max(0.0, (now_ns - scan.rx_ns) / 1e6),
            operator=self._controller_op,
            profile=self.config.pipeline.profile.name,
            rejected=self.counters.rejected_total,
            cycle=self.counters.cycles,
            reason=self.reason,
            # DESIGN 7: which filter of DESIGN 6 runs ("none" in direct mode)
            filter=shown_filter,
            loop_delay_ms=link.loop_delay_s * 1e3,
            cmd_age_p50_ms=link.cmd_age_p50_ms,
            cmd_age_p90_ms=link.cmd_age_p90_ms,
            cmd_gap_max_ms=link.cmd_gap_max_ms,
            link_loss=link.link_loss,
            view_age_ms=link.view_age_ms,
            v_lim_latency=v_lim,
            # Only a turn cap that can bind (below w_max) is reported, so the view stays quiet.
            w_lim_latency=w_lim
            if w_lim is not None and w_lim < self.config.pipeline.profile.w_max_radps
            else None,
            goal=route.active,
            goal_frame=route.frame if route.active is not None else None,
            goals_left=route.remaining_after_active,
            suggested_rad=None
            if result is None or result.family is None
            else result.family.suggested_rad,
            scan_polar=self._telemetry_polar,
            **_cbf_view(result),
        )

    def _telemetry_scan(self) -> tuple[npt.NDArray[np.float32], PolarScan | None]:
        """The newest scan for the telemetry: its beams compact (DESIGN 12) when they are evenly
        spaced, then the points no beam holds; else its points as before. At most
        ``n / telemetry_scan_decimation`` beams, fewer when the budget says so."""
        raw, scan = self._raw_scan, self._scan
        if raw is None or scan is None:
            return np.zeros((0, 2), np.float32), None
        beams = self.scan_beams_max or 1
        if self._telemetry_beams is not None:
            beams = min(beams, self._telemetry_beams)
        polar = compact(raw, beams) if raw.ranges_m.size else None
        if polar is None:
            points = scan.points.xy
            step = max(self.config.telemetry_scan_decimation, -(-len(points) // beams))
            return np.ascontiguousarray(points[::step], dtype=np.float32), None
        extra = raw.extra_xy_m
        xy = polar.points()
        if extra is not None and len(extra):
            xy = np.concatenate((xy, np.asarray(extra, np.float32).reshape(-1, 2)))
        return xy, polar

    def _reject(
        self, cmd: OperatorCommand | None, rejection: Rejection, now_ns: int
    ) -> CommandVerdict:
        self.counters.rejected[rejection.reason.value] += 1
        stale = rejection.reason is RejectReason.STALE
        if stale and cmd is not None and cmd.op == self._controller_op:
            self._stale_rx_ns = now_ns  # commands arrive, but too old (HOLD reason)
        return CommandVerdict(cmd, rejection)

    def _track(self, operator_id: str, seq: int, now_ns: int) -> None:
        self._tracks[operator_id] = _OperatorTrack(seq, now_ns)
        self._tracks.move_to_end(operator_id)
        while len(self._tracks) > _MAX_TRACKED_OPERATORS:  # bounded against hostile op ids
            oldest = next(k for k in self._tracks if k != self._controller_op)
            del self._tracks[oldest]

    def _release(self, reason: str) -> None:
        self._controller_op = None
        self._control_epoch += 1
        self._link.reset()
        self._command = None
        self._no_operator_reason = reason
        self._route = NO_ROUTE  # via points belong to the operator who set them
        self._goal_seq = None


def _cbf_view(result: PipelineResult | None) -> dict[str, Any]:
    """The telemetry keys of cbf's view (DESIGN 13): the points whose barriers changed the
    command, the margin and the margin ahead; nothing when cbf did not run this cycle."""
    detail = None if result is None or result.family is None else result.family.detail
    if not isinstance(detail, CbfResult):
        return {}
    xy = _NO_POINTS
    tight = detail.tight
    if tight is not None and tight.x_m.size:
        pairs = np.column_stack((tight.x_m, tight.y_m)).astype(np.float32)
        xy = np.unique(pairs, axis=0)[:MAX_CBF_POINTS]  # a point's (S) and (C) rows: once
    return {"cbf_xy": xy, "cbf_margin_m": detail.margin_m, "cbf_ahead_m": detail.margin_ahead_m}
