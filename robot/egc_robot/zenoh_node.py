"""The robot process's IO shell around ``RobotController`` (DESIGN 1, 7, 8; issue 4).

The controller is owned by whoever holds the node's lock: the command thread that vets a
command, or the loop thread at each deadline. So there are

- a fixed-rate control cycle on a monotonic deadline schedule (``rate_hz``, default 20; the
  deadline advances by whole periods, so the rate does not drift with the work done per cycle),
  which is also the watchdog's tick; a tick that comes less than half a period after another
  cycle ran (a command's, below) skips its own: with commands at 50 Hz the robot runs 50
  cycles a second, not 70 (a quarter of its CPU), and the watchdog still runs within one and a
  half periods of the last cycle,
- plus an immediate cycle in the robot's command thread whenever commands from the operator in
  control are accepted: the thread waits on the command subscriber's channel, takes every
  command queued there at once, vets each one in order (seq gaps counted, estop latched, stale
  ones dropped) and runs one cycle on the newest, plus one before any command that changes
  what the state machine acts on (``egc_robot.command_batch``: deadman, estop, reset, centred,
  mode, operator). A Python callback would not save the hand-off: zenoh-python runs it in a
  thread of its own, fed by a 256-deep FIFO, one command at a time; with a cycle per command
  and cycles slower than the command period (DWA at 19 ms p50 / 37 ms p90 on a machine at load
  6.6, commands every 20 ms), that FIFO stood ~1 s deep (commands 990 ms old, p50) and held
  the robot at the stale limit. The channel is a ring (``_COMMAND_QUEUE``): a stuck thread
  never blocks Zenoh's network thread, and the commands it would drop are seconds old (seq
  gaps, counted as loss). bench/bench_link.py measures publish-to-base latency,
- and one whenever a driver that announces its scans (``set_scan_listener``: the ROS 2 driver)
  has a new one, in the driver's thread (bench/bench_ros2.py measures scan-to-``/cmd_vel``),
- telemetry at ``telemetry_hz`` (DESIGN 12; default 20), from whichever cycle is due, never one
  per accepted command (the immediate cycle on a command still runs; only its telemetry goes),
  on the view plane (DATA, DROP); state on change and at 1 Hz on the control plane,
- the downlink budget (DESIGN 12, ``egc_common.view_budget``): every accepted command's reports
  (``view_age_ms``, ``rx_kbps``, ``camera_age_ms``) and the view plane's own byte count
  (telemetry plus the camera's ``bytes_sent``) update it; each cycle its plan sets the telemetry
  rate, the scan's beams and the camera's allotment (``CameraSink.set_allotment``), and the
  telemetry carries the plan and the estimate, so the operator can say what the link carries,
- the clock queryable ``egc/<robot>/clock`` answered straight from the callback,
- the liveliness token ``egc/<robot>/alive/robot`` and a liveliness subscriber (with history)
  on ``egc/<robot>/alive/operator/*``,
- every rejected command counted by reason (in the controller) and logged, rate-limited per
  reason so a flood cannot flood the log,
- with command sources (DESIGN 14, ``ControllerConfig.sources``): a subscriber per ``zenoh``
  source (``egc/<robot>/source/<name>``) and per Zenoh-fed lock (``egc/<robot>/lock/<name>``),
  and the driver's ROS 2 sources and locks (``set_input_listeners``); each goes to the
  controller under the lock, and a cycle runs at once when it may change what drives (a lock
  that engages stops the base within one pipeline run).

Nothing received from the network can raise out of a callback or the loop: the decoders are
non-raising, and the callbacks guard the little they do. Should a cycle fail anyway (a bug),
the node sends the base a zero command, logs it and carries on (``_fail_safe``).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import replace
from typing import Protocol

import zenoh
from egc_common import keys
from egc_common.event_log import EventLog
from egc_common.messages import (
    BaseCommand,
    OperatorCommand,
    Rejection,
    StateMessage,
    decode_command,
    encode_clock_reply,
)
from egc_common.scan import Scan
from egc_common.stop_flag import StopRequest
from egc_common.transport import (
    CONTROL_REPLY,
    control_publisher,
    payload_bytes,
    view_publisher,
)
from egc_common.view_budget import (
    BudgetConfig,
    BudgetState,
    Plan,
    RateMeter,
    Report,
    initial_state,
    on_cycle,
    on_report,
    plan,
)

from egc_robot.command_batch import ControlBits, control_bits, cycle_before, decoded_control_bits
from egc_robot.controller import CommandVerdict, CycleOutput, InputVerdict, RobotController
from egc_robot.drivers import Driver
from egc_robot.run_stats import RunStats

log = logging.getLogger("egc.robot")

_STATE_PERIOD_NS = 1_000_000_000
# Commands held between Zenoh's network thread and the command thread (module docstring): at
# 50 Hz over 5 s, so the ring only drops commands long stale, and only if the thread is stuck.
_COMMAND_QUEUE = 256
_COMMAND_THREAD_JOIN_S = 5.0


class Recorder(Protocol):
    """The black box's interface (``egc_robot.blackbox.BlackBox``)."""

    def on_command(
        self, raw_payload: bytes, accepted: bool, reason: str | None, now_ns: int
    ) -> None: ...
    def on_base_command(self, command: BaseCommand) -> None: ...
    def on_scan(self, scan: Scan, now_ns: int) -> None: ...
    def on_state(self, state: StateMessage) -> None: ...
    def close(self) -> None: ...


class CameraSink(Protocol):
    """What the budget needs of a camera streamer (``egc_robot.camera_stream``, DESIGN 12): an
    allotment it keeps to (frames/s and kbit/s; 0 fps: off), settable from any thread, and the
    bytes and frames it has sent so far (the view plane's count; the summary's timeline)."""

    def set_allotment(self, fps: float, kbps: float) -> None: ...
    @property
    def bytes_sent(self) -> int: ...
    @property
    def frames_sent(self) -> int: ...


# A telemetry message is due when the cycle is at most this early (cycles jitter by a little;
# the next one may be a whole period later).
_TELEMETRY_SLACK_NS = 5_000_000
# Telemetry overhead (every key but the scan's beams) the plan assumes before it measured one.
_TELEMETRY_OVERHEAD_BYTES = 700.0


class RejectionLog:
    """Logs each rejection reason at most once per second, with the count since the last line."""

    def __init__(self) -> None:
        self._events = EventLog()

    def log(self, verdict: CommandVerdict, total: int, now_ns: int) -> None:
        assert verdict.rejection is not None
        reason = verdict.rejection.reason.value
        more = self._events.allow(reason, now_ns)
        if more is None:
            return
        log.warning(
            "rejected command (%s) from %s: %s%s [rejected so far: %d]",
            reason,
            verdict.command.op if verdict.command is not None else "?",
            verdict.rejection.detail,
            f" (+{more} more {reason} since the last line)" if more else "",
            total,
        )


class RobotNode:
    """Runs a RobotController against a driver and a Zenoh session until ``stop`` is set."""

    def __init__(
        self,
        session: zenoh.Session,
        robot_id: str,
        controller: RobotController,
        driver: Driver,
        rate_hz: float,
        recorder: Recorder | None = None,
        stats: RunStats | None = None,
        clock: Callable[[], int] = time.monotonic_ns,
        clock_id: str | None = None,
        budget: BudgetConfig | None = None,
        camera: CameraSink | None = None,
    ) -> None:
        self._controller = controller
        self._driver = driver
        self._period_ns = round(1e9 / rate_hz)
        self._recorder = recorder
        self._stats = stats
        self._clock = clock
        self._clock_id = clock_id  # which clock ``clock`` reads (egc_common.clock_id), if known
        self._lock = threading.Lock()
        self._last_state_ns = 0
        self._last_cycle_ns = -(1 << 62)  # no cycle yet
        self._cycle_late_ns = 0  # how late the newest timed cycle began
        self._faults = 0
        self._shut_down = False  # set under the lock: the zero command sent last stays last
        self._rejections = RejectionLog()
        self._events = EventLog()
        self._budget_cfg = budget if budget is not None else BudgetConfig()
        if camera is not None and not self._budget_cfg.camera:
            self._budget_cfg = replace(self._budget_cfg, camera=True)
        self._budget: BudgetState = initial_state(self._budget_cfg)
        self._camera = camera
        self._camera_bytes = 0 if camera is None else camera.bytes_sent
        self._view_sent = RateMeter()  # the view plane's bytes, for the budget and telemetry
        self._overhead_bytes = _TELEMETRY_OVERHEAD_BYTES
        self._plan: Plan = plan(self._budget, self._budget_cfg, self._overhead_bytes)
        self._allotment: tuple[float, float] | None = None
        self._next_telemetry_ns: int | None = None
        self.telemetry_sent = 0
        self._telemetry = view_publisher(session, keys.telemetry(robot_id))
        self._state = control_publisher(session, keys.state(robot_id))
        liveliness = session.liveliness()
        self._token = liveliness.declare_token(keys.alive_robot(robot_id))
        commands = session.declare_subscriber(
            keys.cmd(robot_id), zenoh.handlers.RingChannel(_COMMAND_QUEUE)
        )
        self._entities = [
            commands,
            session.declare_subscriber(keys.goal(robot_id), self._on_goal),
            session.declare_queryable(keys.clock(robot_id), self._on_clock_query),
            liveliness.declare_subscriber(
                keys.alive_operators(robot_id), self._on_liveliness, history=True
            ),
        ]
        self._transports: set[str] = set()
        listen = getattr(session.info, "declare_transport_events_listener", None)
        if listen is not None:  # recent Zenoh 1.x; without it, no such lines in the log
            self._entities.append(listen(self._on_transport, history=True))
        attach = getattr(driver, "set_scan_listener", None)
        if callable(attach):
            attach(self._on_fresh_scan)
        self._entities += self._declare_source_inputs(session, robot_id, driver)
        self._command_thread = threading.Thread(
            target=self._command_loop, args=(commands.handler,), name="commands", daemon=True
        )
        self._command_thread.start()

    @property
    def controller(self) -> RobotController:
        return self._controller

    # -- the command thread and Zenoh callbacks (Zenoh's threads) ------------------------------

    def _command_loop(self, channel: zenoh.handlers.Handler[zenoh.Sample]) -> None:
        """The command thread: wait for a command, take every one queued behind it, hand them
        on as one batch. Ends when the subscriber is undeclared (its channel closes)."""
        while True:
            try:
                batch = [channel.recv()]
                while (sample := channel.try_recv()) is not None:
                    batch.append(sample)
            except Exception:  # closed: shutdown undeclared the subscriber
                return
            self._on_commands(batch)

    def _on_commands(self, samples: list[zenoh.Sample]) -> None:
        """Vet each command in order; run a cycle on the newest accepted one, and on any
        accepted one whose control bits the next command changes (``command_batch``)."""
        tolerance = self._controller.config.centre_tolerance
        latencies: list[tuple[int, int]] = []  # (latency, arrival) of commands not yet cycled on
        pending: ControlBits | None = None  # the accepted command not yet cycled on
        with self._lock:
            if self._shut_down:  # a batch taken just before shutdown
                return
            for sample in samples:
                try:
                    payload = payload_bytes(sample)
                    decoded = decode_command(payload)  # once: for the batch and for vetting
                    if pending is not None and cycle_before(
                        pending, decoded_control_bits(decoded, tolerance)
                    ):
                        pending = None
                        self._command_cycle(latencies)
                    rx_ns = self._clock()
                    verdict = self._handle_command(payload, decoded, rx_ns)
                    if verdict.accepted and verdict.command is not None:
                        self._on_report(verdict, rx_ns)
                        pending = control_bits(verdict.command, tolerance)
                        if verdict.latency_ns is not None:
                            latencies.append((verdict.latency_ns, rx_ns))
                except Exception as exc:
                    pending = None
                    self._fail_safe(exc)
            if pending is not None:
                try:
                    self._command_cycle(latencies)
                except Exception as exc:
                    self._fail_safe(exc)

    def _command_cycle(self, latencies: list[tuple[int, int]]) -> None:
        """A cycle on the command just accepted; the ages of the commands it took go to the
        statistics after the base command (and are cleared)."""
        now = self._clock()
        self._poll_driver(now)
        self._cycle(now)
        if self._stats is not None:
            for latency_ns, rx_ns in latencies:
                self._stats.on_latency(latency_ns, rx_ns)
        latencies.clear()

    def _on_fresh_scan(self) -> None:
        """The driver has a new scan: run a cycle on it now (its thread)."""
        with self._lock:
            if self._shut_down:
                return
            try:
                now = self._clock()
                self._poll_driver(now)
                self._cycle(now)
            except Exception as exc:
                self._fail_safe(exc)

    def _on_goal(self, sample: zenoh.Sample) -> None:
        payload = payload_bytes(sample)
        with self._lock:
            if self._shut_down:
                return
            before = self._controller.route
            try:
                rejection = self._controller.on_goal(payload, self._clock())
            except Exception as exc:  # never out of the receive path
                log.error("goal message failed: %s", exc)
                return
            after = self._controller.route
        if rejection is not None:
            held = self._events.allow("goal rejected", self._clock())
            if held is not None:  # a flood must not flood the log
                log.warning(
                    "rejected goal (%s): %s%s",
                    rejection.reason.value,
                    rejection.detail,
                    f" (+{held} more rejected goals since the last line)" if held else "",
                )
        elif (
            after is not before and (held := self._events.allow("goal", self._clock())) is not None
        ):
            log.info(
                "via points from %s: %d in %s%s%s",
                after.op or "?",
                len(after.points),
                after.frame,
                f", active {after.active[0]:.2f},{after.active[1]:.2f}" if after.active else "",
                f" (+{held} more route changes since the last line)" if held else "",
            )

    def _on_liveliness(self, sample: zenoh.Sample) -> None:
        operator_id = keys.operator_id_from_alive_key(str(sample.key_expr))
        if operator_id is None:
            return
        alive = sample.kind == zenoh.SampleKind.PUT
        with self._lock:
            in_control = self._controller.operator
            driving = self._controller.driving_for_operator
            self._controller.on_operator_alive(operator_id, alive)
            if not alive and operator_id == in_control and driving and self._stats is not None:
                self._stats.on_operator_lost()
        # The operator in control always gets its line; others at most one a second.
        held = 0 if operator_id == in_control else self._events.allow("alive", self._clock())
        if held is not None:
            log.info(
                "operator %s %s%s",
                operator_id,
                "alive" if alive else "lost",
                f" (+{held} more liveliness changes since the last line)" if held else "",
            )

    def _on_transport(self, event: zenoh.TransportEvent) -> None:
        """A Zenoh connection to a router or peer opened or closed: the robot's log says so, so
        that "operators lost" after a router went down has its cause next to it."""
        try:
            transport = event.transport
            name = f"{str(transport.whatami).lower().rsplit('.', 1)[-1]} {str(transport.zid)[:8]}"
            opened = event.kind == zenoh.SampleKind.PUT
        except Exception as exc:  # never out of a Zenoh callback
            log.debug("transport event not understood: %s", exc)
            return
        with self._lock:
            known = name in self._transports
            if opened:
                self._transports.add(name)
            else:
                self._transports.discard(name)
            left = len(self._transports)
        if opened and not known:
            log.info("Zenoh connection to %s open", name)
        elif not opened and known:
            log.warning(
                "Zenoh connection to %s closed%s",
                name,
                "; no Zenoh connection left: no operator can reach this robot" if not left else "",
            )

    def _on_clock_query(self, query: zenoh.Query) -> None:
        try:
            reply = encode_clock_reply(self._clock(), self._clock_id)
            query.reply(query.key_expr, reply, **CONTROL_REPLY)  # control plane (DESIGN 12)
        except Exception as exc:  # a querier that went away must not kill the callback
            log.debug("clock reply failed: %s", exc)

    # -- command sources and locks (DESIGN 14) -------------------------------------------------

    def _declare_source_inputs(
        self, session: zenoh.Session, robot_id: str, driver: Driver
    ) -> list[zenoh.Subscriber[None]]:
        """Subscribers for the ``zenoh`` sources and Zenoh-fed locks; the driver's ROS 2 ones
        report through ``set_input_listeners`` (none without ``[[source]]`` tables)."""
        mux = self._controller.config.sources
        if mux is None:
            return []
        subscribers = []
        for source in mux.sources:
            if source.kind == "zenoh":
                key = keys.source(robot_id, source.name)
                subscribers.append(
                    session.declare_subscriber(
                        key, lambda s, n=source.name: self._on_source_sample(n, s)
                    )
                )
        for lock in mux.locks:
            if lock.topic is None:
                key = keys.lock(robot_id, lock.name)
                subscribers.append(
                    session.declare_subscriber(
                        key, lambda s, n=lock.name: self._on_lock_sample(n, s)
                    )
                )
        attach = getattr(driver, "set_input_listeners", None)
        if callable(attach):
            attach(self._on_ros_velocity, self._on_ros_lock)
        return subscribers

    def _on_source_sample(self, name: str, sample: zenoh.Sample) -> None:
        rx_ns = self._clock()
        payload = payload_bytes(sample)
        self._source_input(
            f"source {name}", lambda: self._controller.on_source(name, payload, rx_ns)
        )

    def _on_lock_sample(self, name: str, sample: zenoh.Sample) -> None:
        rx_ns = self._clock()
        payload = payload_bytes(sample)
        self._source_input(f"lock {name}", lambda: self._controller.on_lock(name, payload, rx_ns))

    def _on_ros_velocity(self, name: str, v_mps: float, w_radps: float, rx_ns: int) -> None:
        """A ``ros2`` source's Twist (the driver's executor thread)."""
        self._source_input(
            f"source {name}",
            lambda: self._controller.on_source_velocity(name, v_mps, w_radps, rx_ns),
        )

    def _on_ros_lock(self, name: str, value: bool, rx_ns: int) -> None:
        """A ROS 2 lock's ``std_msgs/Bool`` (the driver's executor thread)."""
        self._source_input(
            f"lock {name}", lambda: self._controller.on_lock_value(name, value, rx_ns)
        )

    def _source_input(self, what: str, apply: Callable[[], InputVerdict]) -> None:
        """Hand one source command or lock value to the controller; run a cycle on it now when
        it may change what drives. Never raises (a Zenoh or rclpy callback)."""
        with self._lock:
            if self._shut_down:
                return
            try:
                verdict = apply()
                if verdict.urgent:
                    now = self._clock()
                    self._poll_driver(now)
                    self._cycle(now)
            except Exception as exc:
                self._fail_safe(exc)
                return
        rejection = verdict.rejection
        if rejection is not None:
            held = self._events.allow(f"{what} {rejection.reason.value}", self._clock())
            if held is not None:  # a flood must not flood the log
                log.warning(
                    "rejected %s (%s): %s%s",
                    what,
                    rejection.reason.value,
                    rejection.detail,
                    f" (+{held} more since the last line)" if held else "",
                )

    # -- the fixed-rate loop ------------------------------------------------------------------

    def run(self, stop: StopRequest) -> None:
        period = self._period_ns
        deadline = self._clock() + period
        while not stop.wait(max(0, deadline - self._clock()) / 1e9):
            now = self._clock()
            with self._lock:
                self._cycle_late_ns = self._clock() - deadline  # the lock included
                if self._stats is not None:
                    self._stats.on_loop_start(self._cycle_late_ns, period)
                try:
                    if now - self._last_cycle_ns >= period // 2:
                        self._poll_driver(now)
                        self._cycle(now)
                except Exception as exc:
                    self._fail_safe(exc)
            deadline += period
            if deadline <= now:  # overran a whole period: skip, do not burst
                deadline = now + period

    def shutdown(self) -> None:
        """Stop the base, announce it, and undeclare everything."""
        for entity in self._entities:
            entity.undeclare()
        if threading.current_thread() is not self._command_thread:
            self._command_thread.join(_COMMAND_THREAD_JOIN_S)  # its channel closed: it ends
        with self._lock:
            self._shut_down = True
            now = self._clock()
            cycle = self._controller.counters.cycles + 1
            stop_cmd = BaseCommand(stamp_ns=now, seq=cycle, linear_mps=0.0, angular_radps=0.0)
            self._driver.send(stop_cmd)
            state = StateMessage(
                stamp_ns=now,
                state="HOLD",
                reason="robot shutting down",
                operator=None,
                rejected=self._controller.counters.rejected_total,
            )
            self._state.put(state.encode())
            if self._recorder is not None:
                self._recorder.on_base_command(stop_cmd)
                self._recorder.on_state(state)
                self._recorder.close()
        self._token.undeclare()

    # -- under the lock -------------------------------------------------------------------------

    def _fail_safe(self, exc: Exception) -> None:
        """A bug must not leave the base on its last command: stop it, log, keep serving.

        The next cycle starts again from the controller's state; if the fault persists, every
        cycle ends here and the base keeps receiving zero.
        """
        self._faults += 1
        if self._faults == 1 or self._faults % 100 == 0:
            log.error("control cycle failed (%d so far); base stopped", self._faults, exc_info=exc)
        try:
            now = self._clock()
            self._driver.send(BaseCommand(stamp_ns=now, seq=0, linear_mps=0.0, angular_radps=0.0))
            self._controller.on_base_stopped()
        except Exception as send_exc:
            log.error("could not stop the base: %s", send_exc)
        try:  # the operators see telemetry stop; the state says why, at most once a second
            now = self._clock()
            if now - self._last_state_ns >= _STATE_PERIOD_NS:
                self._last_state_ns = now
                state = StateMessage(
                    stamp_ns=now,
                    state="HOLD",
                    reason="control cycle failed (robot log)",
                    operator=self._controller.operator,
                    rejected=self._controller.counters.rejected_total,
                )
                self._state.put(state.encode())
        except Exception as state_exc:
            log.error("could not publish the failed cycle's state: %s", state_exc)

    def _handle_command(
        self, payload: bytes, decoded: OperatorCommand | Rejection, rx_ns: int
    ) -> CommandVerdict:
        """Vet one command, ``decoded`` from ``payload`` (accepted: it came from the operator
        in control and passed)."""
        controller = self._controller
        verdict = controller.vet_command(decoded, rx_ns)
        if self._recorder is not None:
            reason = None if verdict.rejection is None else str(verdict.rejection)
            self._recorder.on_command(payload, verdict.accepted, reason, rx_ns)
        if verdict.rejection is not None:
            self._rejections.log(verdict, controller.counters.rejected_total, rx_ns)
        elif verdict.took_from is not None:
            log.info(
                "operator %s took control from %s (higher priority)",
                controller.operator,
                verdict.took_from,
            )
        elif verdict.took_control:
            log.info("operator %s took control", controller.operator)
        return verdict

    def _poll_driver(self, now: int) -> None:
        update = self._driver.poll(now)
        if update.scan is not None:
            self._controller.on_scan(update.scan, update.scan_rx_ns)
            if self._recorder is not None:
                self._recorder.on_scan(update.scan, update.scan_rx_ns)
        if update.odometry is not None:
            self._controller.on_odometry(update.odometry)
            if self._stats is not None:
                self._stats.on_odometry(update.odometry)

    @property
    def plan(self) -> Plan:
        """The downlink budget's current plan (DESIGN 12)."""
        return self._plan

    def _on_report(self, verdict: CommandVerdict, rx_ns: int) -> None:
        """An accepted command's reports go to the downlink budget (DESIGN 12)."""
        cmd = verdict.command
        if cmd is None:
            return
        if self._stats is not None and cmd.camera_age_ms is not None:
            self._stats.on_camera_age(cmd.camera_age_ms, rx_ns)
        report = Report(
            view_age_ms=None if cmd.view_age_ms is None else float(cmd.view_age_ms),
            rx_kbps=None if cmd.rx_kbps is None else float(cmd.rx_kbps),
            camera_age_ms=None if cmd.camera_age_ms is None else float(cmd.camera_age_ms),
            stamp_ns=cmd.stamp_ns if cmd.stamp_ns > 0 else None,
        )
        before = self._budget
        self._budget = after = on_report(
            before,
            self._budget_cfg,
            report,
            rx_ns,
            self._plan,
            self._view_sent.kbps(rx_ns),
        )
        if after.undone > before.undone and self._events.allow("undo", rx_ns) is not None:
            log.info(
                "downlink budget cut taken back (%.0f kbit/s): its queue vanished faster than "
                "a link drains one (a stall of this machine or of the link, not its rate)",
                after.budget_kbps,
            )
        if after.cuts > before.cuts and (held := self._events.allow("cut", rx_ns)) is not None:
            camera = after.camera_queue_ms
            log.info(
                "downlink budget cut %.0f -> %.0f kbit/s: a queue of %.0f ms (camera's %s), "
                "the operator received %s kbit/s%s",
                before.budget_kbps,
                after.budget_kbps,
                after.queue_ms or 0.0,
                "--" if camera is None else f"{camera:.0f} ms",
                "--" if report.rx_kbps is None else f"{report.rx_kbps:.0f}",
                f" (+{held} more cuts since the last line)" if held else "",
            )

    def _replan(self, now: int) -> None:
        """Count the camera's bytes, let the budget probe, and apply its plan."""
        camera = self._camera
        if camera is not None:
            sent = camera.bytes_sent
            self._view_sent.add(now, sent - self._camera_bytes)
            self._camera_bytes = sent
        sent_kbps = self._view_sent.kbps(now)
        if self._stats is not None:
            frames = None if camera is None else camera.frames_sent
            self._stats.on_view_rate(now, sent_kbps, self._budget.budget_kbps, frames)
        cfg = self._budget_cfg
        beams_max = self._controller.scan_beams_max
        if beams_max is not None and beams_max != cfg.max_beams:
            cfg = self._budget_cfg = replace(cfg, max_beams=beams_max)
        self._budget = on_cycle(self._budget, cfg, now, sent_kbps)
        self._plan = plan(self._budget, cfg, self._overhead_bytes)
        self._controller.set_telemetry_beams(self._plan.scan_beams)
        allotment = (self._plan.camera_fps, self._plan.camera_kbps)
        if camera is not None and allotment != self._allotment:
            camera.set_allotment(*allotment)
            self._allotment = allotment

    def _publish_telemetry(self, out: CycleOutput, now: int) -> bool:
        """Send the cycle's telemetry if one is due (``telemetry_hz`` as the plan says); whether
        it did."""
        due = self._next_telemetry_ns
        if due is not None and now < due - _TELEMETRY_SLACK_NS:
            return False
        p = self._plan
        state = self._budget
        t = replace(
            out.telemetry,
            view_kbps=round(self._view_sent.kbps(now), 1),
            budget_kbps=round(p.budget_kbps, 1),
            link_kbps=None if state.link_kbps is None else round(state.link_kbps, 1),
            tel_hz=round(p.telemetry_hz, 2),
            scan_n=p.scan_beams,
            cam_fps=round(p.camera_fps, 2) if self._camera is not None else None,
            cam_kbps=round(p.camera_kbps, 1) if self._camera is not None else None,
            cut=p.cut,
        )
        payload = t.encode()
        self._telemetry.put(payload)
        self.telemetry_sent += 1
        if self._stats is not None:
            self._stats.on_telemetry_sent(len(payload))
        self._view_sent.add(now, len(payload))
        polar = t.scan_polar
        scan_bytes = 2 * polar.beams if polar is not None else 8 * len(t.scan_xy)
        self._overhead_bytes += 0.1 * (len(payload) - scan_bytes - self._overhead_bytes)
        period = round(1e9 / p.telemetry_hz)
        self._next_telemetry_ns = max((now if due is None else due) + period, now + period // 2)
        return True

    def _cycle(self, now: int) -> None:
        self._last_cycle_ns = now
        out = self._controller.step(now)
        self._driver.send(out.base)
        self._replan(now)
        if not self._publish_telemetry(out, now):
            self._controller.skip_telemetry(out)
        if self._recorder is not None:
            self._recorder.on_base_command(out.base)
        if self._stats is not None:
            self._stats.on_cycle(out.facts)
        if out.state_changed is not None:
            changed = out.state_changed
            scan_age = ""
            if changed.reason == "sensor stale":  # the lidar's driver, or this process, went quiet
                age_ms = self._controller.scan_age_ms(now)
                scan_age = (
                    ", no scan yet" if age_ms is None else f", newest scan {age_ms:.0f} ms old"
                )
                scan_age += (
                    f" (the fixed-rate loop last woke {self._cycle_late_ns / 1e6:.0f} ms late)"
                )
            log.info(
                "state %s (%s)%s%s%s%s",
                changed.state,
                changed.reason,
                scan_age,
                f", operator {changed.operator}" if changed.operator else "",
                f", source {changed.source}" if changed.source else "",
                f", lock {changed.lock}" if changed.lock else "",
            )
            if self._recorder is not None:
                self._recorder.on_state(out.state_changed)
        if out.state_changed is not None or now - self._last_state_ns >= _STATE_PERIOD_NS:
            self._state.put(self._controller.state_message(now).encode())
            self._last_state_ns = now
