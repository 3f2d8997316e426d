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

Operators among themselves (DESIGN 14, ``[[operator]]`` tables): an operator of higher priority
than the one in control takes control with its first deadman-held command (a supervisor);
equal priorities keep first come. Unlisted operators have priority 0.

Command sources (DESIGN 14, ``ControllerConfig.sources``; None without ``[[source]]`` tables,
and then nothing below applies): besides the operators (the ``operator`` source, which asks to
drive with each deadman-held command of the operator in control), ``zenoh`` sources
(``on_source``: ``egc/<robot>/source/<name>``) and ``ros2`` sources (``on_source_velocity``,
from the ROS 2 driver) give (v, w) directly, with no eq. 4 mapping; locks arrive through
``on_lock`` / ``on_lock_value``. Each cycle ``source_mux.arbitrate`` says which source drives.
A source's velocity goes through the same pipeline after the mapping (``filter_velocity``: the
robot's filter of shared mode, limits, footprint sweep), the latency governor (its tau from that
source's own command ages; unknown ages count as ``command_timeout``, with no human reaction
time and no view) and the state machine (``state_machine``: no deadman or stick for a source;
the scan must be fresh; e-stop latches everything). When no source may drive, the base gets zero
at once. Switching sources ramps at the profile's limits (the pipeline's acceleration limits
start from what the base had). A ``zenoh`` source's ``seq`` must increase (a source silent past
its ``timeout_s`` starts a new session) and a ``stamp_ns`` older than ``max_command_age`` of a
filtered mode is stale, as an operator's; rejections are counted as ``source_<reason>``.
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
    MAX_SPEED_MPS,
    MAX_TURN_RADPS,
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
from egc_common.source_msg import decode_lock, decode_source_command

from egc_robot.filters.cbf import CbfResult
from egc_robot.latency_governor import govern, latency_speed_limit, latency_turn_limit
from egc_robot.link_stats import LinkStats
from egc_robot.pipeline import (
    FILTERS,
    MODES,
    Limiter,
    PipelineConfig,
    PipelineResult,
    filter_velocity,
    step_command,
)
from egc_robot.safety import decelerate
from egc_robot.source_mux import LockFeed, MuxConfig, SourceSpec, Verdict, arbitrate, lock_state
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
    # DESIGN 14: command sources and locks (None: one operator source, as without [[source]]
    # tables) and the operators' priorities ([[operator]]; an unlisted operator has 0).
    sources: MuxConfig | None = None
    operator_priorities: tuple[tuple[str, int], ...] = ()

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
    took_from: str | None = None  # the operator of lower priority it took control from

    @property
    def accepted(self) -> bool:
        return self.rejection is None


@dataclass(frozen=True, slots=True)
class InputVerdict:
    """What happened to one source command or lock value (DESIGN 14). ``urgent``: it may change
    what drives or it comes from the source that drives, so run a cycle on it now."""

    rejection: Rejection | None
    urgent: bool = False

    @property
    def accepted(self) -> bool:
        return self.rejection is None


@dataclass(frozen=True, slots=True)
class CycleFacts:
    """What a cycle's statistics need (``RunStats.on_cycle``), without its whole telemetry: the
    same values the telemetry carries under the same names."""

    stamp_ns: int
    state: str
    limiter: str
    loop_delay_ms: float
    view_age_ms: float | None


@dataclass(frozen=True, slots=True)
class CycleOutput:
    """One cycle's base command, with its telemetry built on first use.

    The telemetry is a snapshot of the cycle (every value is the one when ``step`` returns) but
    is only assembled when asked for, so that the robot can send the base command first: the
    controller assembles it itself before anything that could change those values (its next
    input or cycle), if nobody asked for it by then, unless told that nobody will
    (``RobotController.skip_telemetry``: the robot sends telemetry at ``telemetry_hz``, not
    every cycle, and a telemetry costs about half of what the cycle itself does).
    """

    base: BaseCommand
    state_changed: StateMessage | None
    result: PipelineResult | None
    facts: CycleFacts
    _build: Callable[..., Telemetry] = field(repr=False, compare=False)
    _args: tuple[Any, ...] = field(repr=False, compare=False)
    _telemetry: Telemetry | None = field(default=None, init=False, repr=False, compare=False)
    _skipped: bool = field(default=False, init=False, repr=False, compare=False)

    @property
    def telemetry(self) -> Telemetry:
        telemetry = self._telemetry
        if telemetry is None:
            if self._skipped:
                raise RuntimeError("this cycle's telemetry was skipped: it is no longer known")
            telemetry = self._build(*self._args)
            object.__setattr__(self, "_telemetry", telemetry)
        return telemetry


@dataclass(slots=True)
class _OperatorTrack:
    last_seq: int
    last_rx_ns: int


@dataclass(slots=True)
class _SourceFeed:
    """A ``zenoh`` or ``ros2`` source's newest accepted command and its link statistics."""

    v_mps: float
    w_radps: float
    rx_ns: int
    stamp_ns: int  # 0: not stamped (ros2) or not synchronised
    seq: int | None  # None: the kind has none (ros2)
    link: LinkStats


@dataclass(frozen=True, slots=True)
class _SourceReport:
    """What the telemetry says about sources (DESIGN 14), fixed at the cycle."""

    source: str | None
    lock: str | None
    source_age_ms: float | None
    # When a source other than the operator drives: its command's seq (0: none) and the time
    # its command age counts from (stamp, or arrival when not stamped); None otherwise.
    seq: int | None
    since_ns: int | None


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
        # DESIGN 14 (all unused without sources)
        self._mux = config.sources
        mux = config.sources
        self._op_source = None if mux is None else mux.operator_source
        self._source_specs = {} if mux is None else {s.name: s for s in mux.sources}
        self._lock_specs = {} if mux is None else {lk.name: lk for lk in mux.locks}
        self._op_priority = dict(config.operator_priorities)
        self._feeds: dict[str, _SourceFeed] = {}
        self._lock_feeds: dict[str, LockFeed] = {}
        self._op_claim_ns: int | None = None  # newest deadman-held command of the one in control
        self._verdict: Verdict | None = None  # the last cycle's
        self._verdict_changed = False

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
    def driving_for_operator(self) -> bool:
        """Whether losing the operator in control now loses a drive (DESIGN 8): DRIVING, or
        held by the link alone (a command timeout or stale commands) while its newest command
        still holds the deadman. An operator that released the deadman and then went quiet (a
        script that ended, a console that closed) left; it was not lost."""
        if self._transition.state is State.DRIVING:
            return True
        cmd = self._command
        return self._transition.reason in LINK_REASONS and cmd is not None and cmd.deadman

    @property
    def link_totals(self) -> tuple[int, int]:
        """(commands that arrived from the operator in control, seq numbers missing between
        them) over the whole run: the link's loss as the robot measured it."""
        return self._link.received_total, self._link.missing_total

    def on_command(self, payload: object, now_ns: int) -> CommandVerdict:
        """Decode and vet one payload from ``egc/<robot>/cmd``; never raises."""
        return self.vet_command(decode_command(payload), now_ns)

    def vet_command(self, decoded: OperatorCommand | Rejection, now_ns: int) -> CommandVerdict:
        """Vet one command already decoded (``messages.decode_command``: a Rejection is counted
        as rejected); the rules 2-4 of the module docstring. Never raises."""
        if self._unreported is not None:
            self._report()
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
        took_from: str | None = None
        holder = self._controller_op
        if cmd.deadman and op != holder and (holder is None or self._outranks(op, holder)):
            if op in self._departed:
                return self._reject(
                    cmd,
                    Rejection(
                        RejectReason.NOT_IN_CONTROL,
                        f"{op}: its liveliness token is gone (the session ended or was lost)",
                    ),
                    now_ns,
                )
            if holder is not None:  # a supervisor takes over (DESIGN 14)
                took_from = holder
                self._route = NO_ROUTE  # via points belong to the operator who set them
                self._goal_seq = None
                self._stale_rx_ns = None
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
        if cmd.deadman:
            self._op_claim_ns = now_ns  # the operator source asks to drive (DESIGN 14)
        return CommandVerdict(cmd, None, took_control, latency_ns, took_from)

    def _outranks(self, op: str, holder: str) -> bool:
        """``op`` has a higher ``[[operator]]`` priority than ``holder`` (DESIGN 14)."""
        priority = self._op_priority
        return priority.get(op, 0) > priority.get(holder, 0)

    # -- command sources and locks (DESIGN 14) --------------------------------------------------

    def on_source(self, name: str, payload: object, now_ns: int) -> InputVerdict:
        """One payload from ``egc/<robot>/source/<name>`` (a ``zenoh`` source); never raises."""
        decoded = decode_source_command(payload)
        if isinstance(decoded, Rejection):
            return self._reject_input(decoded)
        return self._on_velocity(
            name, "zenoh", decoded.v_mps, decoded.w_radps, now_ns, decoded.seq, decoded.stamp_ns
        )

    def on_source_velocity(
        self, name: str, v_mps: float, w_radps: float, now_ns: int
    ) -> InputVerdict:
        """One velocity from a ``ros2`` source's topic (checked here, as from the network)."""
        if not (
            isinstance(v_mps, float)
            and isinstance(w_radps, float)
            and abs(v_mps) <= MAX_SPEED_MPS  # also false for NaN
            and abs(w_radps) <= MAX_TURN_RADPS
        ):
            return self._reject_input(
                Rejection(RejectReason.OUT_OF_RANGE, f"velocity {v_mps!r}, {w_radps!r}")
            )
        return self._on_velocity(name, "ros2", v_mps, w_radps, now_ns, None, 0)

    def on_lock(self, name: str, payload: object, now_ns: int) -> InputVerdict:
        """One payload from ``egc/<robot>/lock/<name>`` (a msgpack bool); never raises."""
        decoded = decode_lock(payload)
        if isinstance(decoded, Rejection):
            return self._reject_input(decoded, "lock")
        return self.on_lock_value(name, decoded, now_ns, ros2=False)

    def on_lock_value(self, name: str, value: bool, now_ns: int, ros2: bool = True) -> InputVerdict:
        """A lock's value (from ``on_lock`` or a ROS 2 ``std_msgs/Bool`` topic)."""
        if self._unreported is not None:
            self._report()
        spec = self._lock_specs.get(name)
        if spec is None or (spec.topic is not None) != ros2:
            return self._reject_input(
                Rejection(RejectReason.NOT_IN_CONTROL, f"no such lock {name!r} of this feed"),
                "lock",
            )
        before = lock_state(spec, self._lock_feeds.get(name), now_ns) is not None
        feed = LockFeed(bool(value), now_ns)
        self._lock_feeds[name] = feed
        return InputVerdict(None, urgent=before != (lock_state(spec, feed, now_ns) is not None))

    def _on_velocity(
        self,
        name: str,
        kind: str,
        v_mps: float,
        w_radps: float,
        now_ns: int,
        seq: int | None,
        stamp_ns: int,
    ) -> InputVerdict:
        if self._unreported is not None:
            self._report()
        spec = self._source_specs.get(name)
        if spec is None or spec.kind != kind:
            return self._reject_input(
                Rejection(RejectReason.NOT_IN_CONTROL, f"no {kind} source named {name!r}")
            )
        age_ns: int | None = None
        if stamp_ns:
            age_ns = now_ns - stamp_ns
            max_age_ns = self._max_age_ns["shared"]
            if abs(age_ns) > max_age_ns:
                what = f"{age_ns / 1e6:.0f} ms old" if age_ns > 0 else "stamped ahead"
                return self._reject_input(Rejection(RejectReason.STALE, f"{name}: {what}"))
        feed = self._feeds.get(name)
        session = feed is not None and now_ns - feed.rx_ns <= spec.timeout_ns
        last_seq = None if feed is None or not session else feed.seq
        if seq is not None and last_seq is not None and seq <= last_seq:
            reason = RejectReason.DUPLICATE_SEQ if seq == last_seq else RejectReason.OUT_OF_ORDER
            return self._reject_input(Rejection(reason, f"{name}: seq {seq} after {last_seq}"))
        if feed is None:
            link = LinkStats(reaction_time_s=0.0, unknown_part_s=self.config.command_timeout_s)
            feed = self._feeds[name] = _SourceFeed(v_mps, w_radps, now_ns, stamp_ns, seq, link)
        else:
            if not session:
                feed.link.reset()  # a new session of that source
            feed.v_mps, feed.w_radps, feed.rx_ns = v_mps, w_radps, now_ns
            feed.stamp_ns, feed.seq = stamp_ns, seq
        feed.link.on_arrival(seq if seq is not None else feed.link.received_total + 1, now_ns)
        # An autonomy stack sees its own sensors: no view delay, no human reaction time.
        feed.link.on_accepted(age_ns, 0, now_ns)
        driving = self._verdict.source if self._verdict is not None else None
        current = None if driving is None else self._source_specs.get(driving)
        urgent = driving == name or current is None or spec.priority > current.priority
        return InputVerdict(None, urgent)

    def _reject_input(self, rejection: Rejection, what: str = "source") -> InputVerdict:
        self.counters.rejected[f"{what}_{rejection.reason.value}"] += 1
        return InputVerdict(rejection)

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

    def scan_age_ms(self, now_ns: int) -> float | None:
        """How long ago the newest scan arrived (None before the first)."""
        scan = self._scan
        return None if scan is None else max(0.0, (now_ns - scan.rx_ns) / 1e6)

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
        # DESIGN 14: which source drives, decided before the operator's snapshot, as a change
        # of source is control changing hands.
        verdict = None if self._mux is None else self._arbitrate(now_ns)
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
        feed: _SourceFeed | None = None  # the source that drives when not the operator
        if verdict is not None:
            inputs, feed = self._source_inputs(verdict, inputs, fresh)
        self._estop_pending = False
        before = self._transition
        self._transition = next_state(before, inputs)
        changed = self._transition is not before
        if changed:
            self._state_since_ns = now_ns
        if verdict is not None and self._verdict_changed:
            changed = True  # the state message says which source drives and which lock holds

        result: PipelineResult | None = None
        state = self._transition.state
        self._driving_epoch = self._control_epoch if state is State.DRIVING else -1
        v_lim: float | None = None
        w_lim: float | None = None
        tau_s: float | None = None  # unknown without link awareness: cbf takes its default
        if cfg.link_aware:
            profile = cfg.pipeline.profile
            if feed is None:
                tau_s = self._link.loop_delay_s(now_ns)
                blind_s = self._blind_time_s[cmd.mode if cmd is not None else "shared"]
            else:
                tau_s = feed.link.loop_delay_s(now_ns)
                blind_s = self._blind_time_s["shared"]
            v_lim = latency_speed_limit(tau_s, profile.v_max_mps, profile.decel_max_mps2, blind_s)
            if cfg.latency_turn_cap:
                w_lim = latency_turn_limit(
                    tau_s, profile.w_max_radps, profile.angular_accel_max_radps2, blind_s
                )
        filter_name = self._filter_for(cmd) if feed is None else cfg.pipeline.filter
        if state is State.DRIVING and feed is not None and scan is not None:
            # The source's velocity as it is (no eq. 4), through the same filter and sweep.
            result = filter_velocity(
                self._pipeline_for(filter_name, scan),
                feed.v_mps,
                feed.w_radps,
                "shared",
                scan.points,
                self._previous,
                dt_s,
                filter_name=filter_name,
                now_ns=now_ns,
                memory=self._filter_memory,
                loop_delay_s=tau_s,  # the source's own (cbf's delay-aware margin, DESIGN 13)
            )
            v, w, limiter = self._governed(result, v_lim, w_lim)
        elif state is State.DRIVING and cmd is not None and scan is not None:
            self._last_drive_epoch = self._control_epoch
            self._last_drive_ns = self._command_rx_ns  # the gap is timed from this command
            result = step_command(
                self._pipeline_for(filter_name, scan),
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
            v, w, limiter = self._governed(result, v_lim, w_lim)
        elif state is State.ESTOP:
            self._filter_memory = None
            v, w, limiter = 0.0, 0.0, Limiter.ESTOP
        else:
            self._filter_memory = None
            # DESIGN 14: when no source may drive, zero at once (a base keeps its last command).
            ramp = cfg.hold_ramp and (verdict is None or verdict.source is not None)
            v, w = decelerate(self._previous, dt_s, cfg.pipeline.profile) if ramp else (0.0, 0.0)
            limiter = Limiter.WATCHDOG if self.reason in LINK_REASONS else Limiter.HOLD
        self._previous = (v, w)

        base = BaseCommand(stamp_ns=now_ns, seq=self.counters.cycles, linear_mps=v, angular_radps=w)
        if feed is not None:
            shown_filter = filter_name
        else:
            shown_filter = filter_name if cmd is not None and cmd.mode == "shared" else "none"
        report = None if verdict is None else self._source_report(verdict, feed, now_ns)
        facts = CycleFacts(
            now_ns,
            self.state.value,
            limiter.value,
            self._link.loop_delay_s(now_ns) * 1e3,
            self._link.view_age_ms,
        )
        out = CycleOutput(
            base,
            self.state_message(now_ns) if changed else None,
            result,
            facts,
            self._telemetry,
            (now_ns, cmd, fresh, v, w, limiter, result, v_lim, w_lim, shown_filter, report),
        )
        # Nothing the telemetry reports changes before it is built: every input and the next
        # cycle build it first (``_report``) when nobody has asked for it.
        self._unreported = out
        return out

    def state_message(self, now_ns: int) -> StateMessage:
        verdict = self._verdict
        return StateMessage(
            stamp_ns=now_ns,
            state=self.state.value,
            reason=self.reason,
            operator=self._controller_op,
            rejected=self.counters.rejected_total,
            source=None if verdict is None else verdict.source,
            lock=None if verdict is None else verdict.lock,
            map_pose=self._map_pose,
        )

    @property
    def verdict(self) -> Verdict | None:
        """The last cycle's arbitration (DESIGN 14); None without sources or before a cycle."""
        return self._verdict

    # -- command sources in the cycle (DESIGN 14) -----------------------------------------------

    def _arbitrate(self, now_ns: int) -> Verdict:
        """Which source drives this cycle; a change of source is control changing hands."""
        mux = self._mux
        assert mux is not None
        claims = {name: feed.rx_ns for name, feed in self._feeds.items()}
        op_source = self._op_source
        claim = self._op_claim_ns  # None once the operator in control is released
        if op_source is not None and claim is not None:
            claims[op_source.name] = claim
        verdict = arbitrate(mux, claims, self._lock_feeds, now_ns)
        previous = self._verdict
        self._verdict = verdict
        self._verdict_changed = previous is None or (previous.source, previous.lock) != (
            verdict.source,
            verdict.lock,
        )
        if previous is None or previous.source != verdict.source:
            self._control_epoch += 1  # nothing inherits DRIVING; no short-gap resume across
            self._filter_memory = None
        return verdict

    def _source_inputs(
        self, verdict: Verdict, operator: Inputs, operator_fresh: bool
    ) -> tuple[Inputs, _SourceFeed | None]:
        """The state machine's snapshot for the source that drives (state_machine docstring),
        and that source's feed when it is not the operator."""
        spec: SourceSpec | None = (
            None if verdict.source is None else self._source_specs.get(verdict.source)
        )
        if spec is not None and spec.kind == "operator":
            return operator, None
        if spec is None:
            locked = verdict.reason if verdict.lock is not None else None
            return (
                Inputs(
                    operator_present=False,
                    command_fresh=False,
                    deadman=False,
                    centred=False,
                    scan_fresh=operator.scan_fresh,
                    estop=operator.estop,
                    reset=False,
                    base_stopped=operator.base_stopped,
                    no_operator_reason=verdict.reason,
                    lock_reason=locked,
                ),
                None,
            )
        # Only the operator in control leaves an e-stop, with a fresh, deadman-held, centred
        # reset, whatever source drives.
        reset = operator_fresh and operator.reset and operator.deadman and operator.centred
        inputs = Inputs(
            operator_present=True,
            command_fresh=True,
            deadman=True,
            centred=True,
            scan_fresh=operator.scan_fresh,
            estop=operator.estop,
            reset=reset,
            base_stopped=operator.base_stopped,
            same_control=operator.same_control,
            source=spec.name,
        )
        return inputs, self._feeds[spec.name]

    def _source_report(
        self, verdict: Verdict, feed: _SourceFeed | None, now_ns: int
    ) -> _SourceReport:
        if feed is not None:
            since = feed.stamp_ns or feed.rx_ns
            return _SourceReport(
                verdict.source, verdict.lock, (now_ns - feed.rx_ns) / 1e6, feed.seq or 0, since
            )
        age = None
        if verdict.source is not None and self._command is not None:
            age = (now_ns - self._command_rx_ns) / 1e6
        return _SourceReport(verdict.source, verdict.lock, age, None, None)

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

    def skip_telemetry(self, out: CycleOutput) -> None:
        """Nobody will ask for ``out``'s telemetry: it is not built (asking raises)."""
        object.__setattr__(out, "_skipped", True)
        if self._unreported is out:
            self._unreported = None

    def _pipeline_for(self, filter_name: str, scan: _Scan) -> PipelineConfig:
        """The pipeline for this cycle's scan (``pipeline_if_free`` when no return means free
        space); a filter other than last cycle's starts without its memory."""
        if filter_name != self._memory_filter:
            self._filter_memory, self._memory_filter = None, filter_name
        cfg = self.config
        if scan.no_return_is_free and cfg.pipeline_if_free is not None:
            return cfg.pipeline_if_free
        return cfg.pipeline

    def _governed(
        self, result: PipelineResult, v_lim: float | None, w_lim: float | None
    ) -> tuple[float, float, Limiter]:
        """Keep the filter's memory; the command within the latency governor's caps."""
        self._filter_memory = result.memory
        v, w, limiter = result.v_cmd_mps, result.w_cmd_radps, result.limiter
        if v_lim is not None:
            v, w, capped = govern(v, w, v_lim, math.inf if w_lim is None else w_lim)
            if capped:
                limiter = Limiter.LATENCY
        return v, w, limiter

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
        report: _SourceReport | None,
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
        seq = cmd.seq if cmd is not None else 0
        if report is not None and report.since_ns is not None:  # a source, not the operator
            cmd_age_ms: float | None = (now_ns - report.since_ns) / 1e6
            seq = report.seq or 0
            mode = "shared"
        elif cmd is None:
            cmd_age_ms = None
            mode = "shared"
        else:
            since = cmd.stamp_ns if cmd.stamp_ns else self._command_rx_ns
            cmd_age_ms = (now_ns - since) / 1e6
            mode = cmd.mode
        return Telemetry(
            seq=seq,
            stamp_ns=now_ns,
            state=self.state.value,
            mode=mode,
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
            source=None if report is None else report.source,
            lock=None if report is None else report.lock,
            source_age_ms=None if report is None else report.source_age_ms,
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
        self._op_claim_ns = None
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
