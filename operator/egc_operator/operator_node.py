"""The operator process's IO shell (DESIGN 1, 4, 7; issue 4).

- Publishes an OperatorCommand on ``egc/<robot>/cmd`` at a fixed rate (default 50 Hz) on a
  monotonic deadline schedule, whether the stick moves or not, with command QoS (priority
  INTERACTIVE_HIGH, express). ``seq`` increases by one per command; ``stamp_ns`` is the robot's
  clock as estimated by ``ClockSync`` (0 until the first clock reply).
- Queries ``egc/<robot>/clock`` from its own thread (10 Hz until the robot's telemetry confirms
  the clock in use, then 1 Hz), taking every reply (no consolidation).
- Holds the liveliness token ``egc/<robot>/alive/operator/<id>``; closing the session (or the
  process dying) withdraws it, which releases control on the robot at once.
- Subscribes to telemetry and state for the status line and the operator view. Every message
  refused there (DESIGN 7: a decoder's reason, or telemetry stamped more than 1 s ahead of the
  robot's clock) is counted by reason (``Rejections``), logged at most once a second per
  reason with the count held back, and said on the status line; nothing from the network raises
  out of a callback.
- Clock replies are kept per replier (``ClockSync``): when more than one peer answers the
  clock query, the log names them (at most every 30 s, and at once when the clock in use
  changes) and the robot's own telemetry decides whose clock the stamps follow.
- Sends ``view_age_ms`` with every command (DESIGN 7, 9): the age, on the robot's clock, of the
  newest telemetry received (and handed to the view), once the clock is synchronised.
- Subscribes to the robot's camera (DESIGN 12, ``egc_operator.camera_view.CameraFeed``): frames
  decoded in their own thread and shown in the view with their age (``robot_clock``: the clock
  sync's estimate and its error, which also bounds how far ahead a frame's stamp may be);
  ``camera.shown_stamp_ns()`` is the newest shown frame's capture stamp, read without a lock.
- Sends ``rx_kbps`` with every command once view data came (DESIGN 12): the view plane's payload
  bytes received over the last second (telemetry, and camera samples counted through
  ``count_view_bytes``), in kbit/s, the robot's downlink budget's measure of what the link
  delivers; and ``camera_age_ms`` when there is a camera view (``CameraAge``), like
  ``view_age_ms`` for the newest frame shown, on the same reading of the robot's clock as the
  command's stamp (the robot tells the frame shown from the two). The status line says what
  the link carries.
- Keeps a bounded history of the commands it sent (robot-clock stamps) and hands it to the view
  after every command, for the predictive display (DESIGN 9, ``egc_operator.prediction``).
- Sends ``filter`` with every command (DESIGN 6): the source's pick (a gamepad button, a file's
  column), else the ``--filter`` default, else none (the robot runs its own default).
- Via points (DESIGN 7 ``egc/<robot>/goal``, ``egc_operator.via_route``): the route goes out on
  a reliable publisher (goals are rare and must not be lost), once the robot is seen with this
  operator in control (its state message says who is; the robot takes via points from that
  operator only) and then every second (the robot keeps its progress on a repeat; a robot that
  restarts, or control lost and taken again, still gets it), at once on taking control, and at
  once after the source's ``via_next`` / ``via_clear`` press (the sample's rising edge). Its own thread sends it, so a congested link that blocks a
  reliable put never holds back the commands.

``local_clock`` is the operator's monotonic clock; the hidden ``--clock-offset-s`` flag shifts it
to test clock sync against a machine whose clock differs by an hour.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any, Protocol

import numpy.typing as npt
import zenoh
from egc_common import keys
from egc_common.event_log import EventLog
from egc_common.joystick_file import RELEASED
from egc_common.messages import (
    MAX_VIEW_AGE_MS,
    OperatorCommand,
    Rejection,
    RejectReason,
    StateMessage,
    Telemetry,
    decode_clock_id,
    decode_clock_reply,
    decode_map,
    decode_state,
    decode_telemetry,
)
from egc_common.stop_flag import StopRequest
from egc_common.transport import command_publisher, payload_bytes
from egc_common.view_budget import RateMeter

from egc_operator.camera_view import CameraFeed, CameraView, RobotClock
from egc_operator.clock_sync import ClockSync
from egc_operator.command_source import CommandSource
from egc_operator.prediction import CommandHistory, SentCommand
from egc_operator.status_line import Episode, Rejections, Status, StatusLine, status_of
from egc_operator.via_route import Route, RoutePlanner, active_index

log = logging.getLogger("egc.operator")

NS_PER_S = 1_000_000_000
_STATUS_PERIOD_NS = 200_000_000
# Via points sent this long without the robot echoing one of them: say so on the status line.
VIA_UNTAKEN_NS = 3_000_000_000
_RELEASE_AFTER_END_NS = 300_000_000
_RELEASE_FLUSH_S = 0.1
_CLOCK_TIMEOUT_S = 3.0  # above the round trip of a satellite link (2 x 500 ms + jitter)
_START_WAIT_NS = 10 * NS_PER_S  # a script starts when the robot is seen, or after this
# The map is one large reply (a 500 x 500 grid is ~30 kB): over a 500 ms +- 100 ms link it
# takes a round trip of 1.2 s and more, and TCP's slow start adds round trips on top. A
# 1 s timeout never got it there (issue 12 drives at 500 ms), so allow well above that.
_MAP_TIMEOUT_S = 6.0
_MAP_RETRY_S = 1.0  # a query that got no map is repeated after this
_MAP_ATTEMPTS = 10  # a present robot that serves no map is asked this often, then left alone
_GOAL_POLL_S = 0.05  # the goal thread looks at the route this often (and at once on a press)
_FUTURE_TELEMETRY_MS = 1000  # ClockSync's future_tolerance_ns: telemetry further ahead is refused
_REPLIERS_LOG_NS = 30 * NS_PER_S  # "more than one peer answers the clock query", repeated


def goal_publisher(session: zenoh.Session, key: str) -> zenoh.Publisher:
    """Via points: rare and must not be lost, so reliable and blocking under congestion (unlike
    the best-effort command and data publishers); the goal thread is the only one it blocks.
    Control plane (DESIGN 12): INTERACTIVE_HIGH, express."""
    return session.declare_publisher(
        key,
        priority=zenoh.Priority.INTERACTIVE_HIGH,
        express=True,
        congestion_control=zenoh.CongestionControl.BLOCK,
        reliability=zenoh.Reliability.RELIABLE,
    )


class CameraAge(Protocol):
    """The camera decoder's report (``egc_operator.camera_view``, DESIGN 12): the capture
    stamp (robot clock) of the newest frame shown, None when none is shown. Read on every
    command, so it must not wait for the decoder (no lock: a decoder thread preempted on a busy
    machine while holding one delayed commands by hundreds of ms)."""

    def shown_stamp_ns(self) -> int | None: ...


class View(Protocol):
    """The operator view's interface (``egc_operator.view.OperatorView``)."""

    def on_telemetry(self, t: Telemetry, received_ns: int | None = None) -> None: ...
    def on_commands(self, history: CommandHistory, robot_now_ns: int) -> None: ...
    def on_state(self, s: StateMessage) -> None: ...
    def on_text(self, level: str, text: str) -> None: ...
    def on_link(self, rtt_ms: float, offset_ns: int) -> None: ...
    def close(self) -> None: ...
    def set_world(
        self,
        occupancy: npt.ArrayLike,
        resolution_m: float,
        origin_xy_m: tuple[float, float],
        goal_xy_m: tuple[float, float] | None = None,
    ) -> None: ...
    def on_route(self, points: tuple[tuple[float, float], ...], frame: str) -> None: ...


def view_age_ms(
    robot_now_ns: int, synchronised: bool, telemetry_stamp_ns: int | None
) -> int | None:
    """``OperatorCommand.view_age_ms``: the robot-clock age of the newest telemetry shown.

    None (the key is left out) until the clock is synchronised and telemetry has arrived, and
    for telemetry stamped more than ``_FUTURE_TELEMETRY_MS`` ahead of the clock (taken before
    the clock was known: it is on no clock of this robot's, and said 0, the freshest, to the
    robot); clamped to [0, MAX_VIEW_AGE_MS] (a clock-sync error can make a fresh one look
    negative).
    """
    if not synchronised or telemetry_stamp_ns is None or robot_now_ns <= 0:
        return None
    age_ms = (robot_now_ns - telemetry_stamp_ns) // 1_000_000
    if age_ms < -_FUTURE_TELEMETRY_MS:
        return None
    return max(0, min(MAX_VIEW_AGE_MS, age_ms))


def _camera_stamp(camera: CameraAge) -> int | None:
    """The capture stamp of the newest camera frame shown, None when unknown or when the
    decoder fails (it must not stop the commands)."""
    try:
        return camera.shown_stamp_ns()
    except Exception as exc:
        log.debug("camera age unknown: %s", exc)
        return None


def _replier_of(reply: zenoh.Reply) -> str:
    """Who answered a query: the replier's Zenoh session id and its queryable's entity id
    (``zid/eid``), "" when the reply does not say."""
    try:
        replier = reply.replier_id
        return "" if replier is None else f"{replier.zid}/{replier.eid}"
    except Exception:  # a binding without it: one replier as far as we can tell
        return ""


class OperatorNode:
    def __init__(
        self,
        session: zenoh.Session,
        robot_id: str,
        operator_id: str,
        source: CommandSource,
        rate_hz: float = 50.0,
        local_clock: Callable[[], int] = time.monotonic_ns,
        clock_id: str | None = None,
        view: View | None = None,
        status: StatusLine | None = None,
        route: Route | None = None,
        filter_default: str | None = None,
        camera: CameraAge | None = None,
    ) -> None:
        self._session = session
        self._camera = camera
        self._rx = RateMeter()  # view-plane payload bytes received (DESIGN 12 rx_kbps)
        self._robot = robot_id
        self._op = operator_id
        self._source = source
        self._period_ns = round(NS_PER_S / rate_hz)
        self._clock = local_clock
        self._clock_id = clock_id  # which clock local_clock reads (egc_common.clock_id)
        self._view = view
        self._status = status
        self._sync = ClockSync()
        self._lock = threading.Lock()
        self._telemetry: Telemetry | None = None
        self.history = CommandHistory()  # the commands sent, for the predictive display
        self._state: StateMessage | None = None
        self._robot_alive = False
        self._telemetry_rx_ns: int | None = None  # our clock, when the newest telemetry came
        self._state_rx_ns: int | None = None  # ... and the newest state message
        # Messages on the robot's keys that were refused, by kind and reason (DESIGN 7).
        self.rejections = Rejections()
        self._reject_log = EventLog()
        self._replier_log = EventLog(_REPLIERS_LOG_NS)
        self._replier_key: tuple[object, ...] | None = None
        # The robot's current state and reason from telemetry: since when, and its link
        # figures' peaks (the status line's HOLD and resume texts).
        self._episode = Episode()
        # Counts the robot's (re)appearances (liveliness PUTs): the map is fetched again for
        # each, and a clock reply to a query sent before one is not this robot's.
        self._robot_epoch = 0
        self._map_wake = threading.Event()
        self._sync_wake = threading.Event()  # the clock sync's thread: ask the robot's clock now
        self.published = 0
        self._filter_default = filter_default
        self._planner = RoutePlanner(route)
        self._actions: list[str] = []  # "next" / "clear" presses for the goal thread (locked)
        self._goal_wake = threading.Event()
        self._goal_in_control = False
        # Whether the robot has echoed a point of the route as sent (DESIGN 7), and since when
        # this route goes out unechoed: a robot that never takes them (an ACL without
        # egc/<robot>/goal) must not fail silently.
        self._route_echoed = False
        self._route_pending_since_ns: int | None = None
        self._last_route: Route | None = None
        self.goals_published = 0
        # The robot's camera (DESIGN 12): decoded in its own thread, shown in the view, its
        # newest frame's age for the command (shown_stamp_ns()), refusals counted with the
        # rest. Made before the robot's liveliness subscriber, whose callback resets it.
        self.camera = CameraFeed(
            session,
            robot_id,
            self.robot_clock,
            view if isinstance(view, CameraView) else None,
            local_clock,
            on_reject=self._reject,
            on_bytes=self.count_view_bytes,
        )
        if self._camera is None:  # its frames' age goes with every command (camera_age_ms)
            self._camera = self.camera
        self._publisher = command_publisher(session, keys.cmd(robot_id))
        self._goal_publisher = goal_publisher(session, keys.goal(robot_id))
        liveliness = session.liveliness()
        self._token = liveliness.declare_token(keys.alive_operator(robot_id, operator_id))
        self._entities: list[Any] = [
            session.declare_subscriber(keys.telemetry(robot_id), self._on_telemetry),
            session.declare_subscriber(keys.state(robot_id), self._on_state),
            liveliness.declare_subscriber(
                keys.alive_robot(robot_id), self._on_robot_alive, history=True
            ),
        ]

    def robot_clock(self, local_ns: int) -> RobotClock | None:
        """The clock sync's estimate of the robot's clock at ``local_ns`` and its error (half
        the best round trip), or None before it is synchronised."""
        with self._lock:
            best = self._sync.best
            if best is None or not self._sync.synchronised:
                return None
            return RobotClock(self._sync.robot_now(local_ns), best.rtt_ns // 2)

    # -- callbacks ----------------------------------------------------------------------------

    def _reject(self, kind: str, rejection: Rejection) -> None:
        """Count a refused message and log it, at most once a second per reason."""
        now = self._clock()
        reason = rejection.reason.value
        with self._lock:  # callbacks of several Zenoh threads, the clock and map threads
            self.rejections.add(kind, reason, rejection.detail, now)
            total = self.rejections.total
            held = self._reject_log.allow(f"{kind} {reason}", now)
        if held is None:
            return
        log.warning(
            "rejected %s from robot %s (%s): %s%s [rejected so far: %d]",
            kind,
            self._robot,
            reason,
            rejection.detail,
            f" (+{held} more {kind} {reason} since the last line)" if held else "",
            total,
        )

    def _on_telemetry(self, sample: zenoh.Sample) -> None:
        try:
            self._telemetry_in(sample)
        except Exception as exc:  # nothing from the network raises out of the callback
            log.warning("telemetry callback failed: %s: %s", type(exc).__name__, exc)

    def count_view_bytes(self, nbytes: int) -> None:
        """View-plane payload bytes received (telemetry here; a camera subscriber calls it for
        its samples), for ``rx_kbps`` (DESIGN 12). Any thread."""
        now = self._clock()
        with self._lock:
            self._rx.add(now, nbytes)

    def _telemetry_in(self, sample: zenoh.Sample) -> None:
        payload = payload_bytes(sample)
        self.count_view_bytes(len(payload))  # refused or not, it crossed the link
        t = decode_telemetry(payload)
        if isinstance(t, Rejection):
            self._reject("telemetry", t)
            return
        with self._lock:
            now = self._clock()
            ahead_ns = self._sync.admit_telemetry(t.stamp_ns, now)
            if ahead_ns is None:
                self._telemetry = t
                self._telemetry_rx_ns = now
                self._episode.update(t)
                synced = self._sync.synchronised
                received = self._sync.robot_now(now) if synced else None
        if ahead_ns is not None:
            detail = f"stamped {ahead_ns / NS_PER_S:.3g} s ahead of the robot's clock estimate"
            self._reject("telemetry", Rejection(RejectReason.STALE, detail))
            return
        if self._view is not None:
            self._view.on_telemetry(t, received_ns=received)

    def _on_state(self, sample: zenoh.Sample) -> None:
        try:
            self._state_in(sample)
        except Exception as exc:  # nothing from the network raises out of the callback
            log.warning("state callback failed: %s: %s", type(exc).__name__, exc)

    def _state_in(self, sample: zenoh.Sample) -> None:
        s = decode_state(payload_bytes(sample))
        if isinstance(s, Rejection):
            self._reject("state", s)
            return
        with self._lock:
            previous, self._state = self._state, s
            self._state_rx_ns = self._clock()
        if previous is None or (previous.state, previous.reason) != (s.state, s.reason):
            log.info("robot %s: %s", s.state, s.reason)
        if self._view is not None:
            self._view.on_state(s)  # the view logs state changes itself

    def _on_robot_alive(self, sample: zenoh.Sample) -> None:
        alive = sample.kind == zenoh.SampleKind.PUT
        with self._lock:
            # A PUT while the robot is present is another token: a new robot session.
            changed = alive != self._robot_alive or alive
            self._robot_alive = alive
            if changed:
                # A robot that went away (or a new one, after a restart or a long outage) says
                # nothing about the one that is there now: forget its state and figures, and
                # its round trip and clock (a restarted robot's clock is another one). The
                # arrival time stays, for "no telemetry for N s".
                self._state = None
                self._state_rx_ns = None
                self._telemetry = None
                self._episode = Episode()
                self._sync = ClockSync()
                self._robot_epoch += 1
        if changed:
            self.camera.reset()  # the old robot's frames are not this one's
        if changed:
            self._sync_wake.set()
        if alive:
            self._map_wake.set()  # its map, again (a restarted robot may serve another one)
        text = "robot present" if alive else "robot gone (its liveliness token was withdrawn)"
        log.info("%s", text)
        if self._view is not None:
            self._view.on_text("INFO" if alive else "WARN", text)
            presence = getattr(self._view, "on_robot_presence", None)
            if presence is not None:  # OperatorView; other views need not have it
                presence(alive)

    # -- clock sync thread --------------------------------------------------------------------

    def _clock_sync(self, stop: StopRequest) -> None:
        key = keys.clock(self._robot)
        while not stop.is_set():
            try:
                with self._lock:
                    epoch = self._robot_epoch
                sent = self._clock()
                replies = self._session.get(
                    key,
                    timeout=_CLOCK_TIMEOUT_S,
                    priority=zenoh.Priority.INTERACTIVE_HIGH,
                    express=True,
                    # every reply, as it comes: consolidated, only one replier's reached us
                    # (the quickest), so a rogue answering first hid the robot altogether
                    consolidation=zenoh.ConsolidationMode.NONE,
                )
                for reply in replies:
                    received = self._clock()
                    ok = reply.ok
                    payload = None if ok is None else payload_bytes(ok)
                    stamp = None if payload is None else decode_clock_reply(payload)
                    if isinstance(stamp, Rejection):
                        self._reject("clock reply", stamp)
                    if isinstance(stamp, int):
                        same = self._clock_id is not None and self._clock_id == decode_clock_id(
                            payload
                        )
                        replier = _replier_of(reply)
                        with self._lock:
                            # asked before the robot (re)appeared: the old robot's round trip
                            current = epoch == self._robot_epoch
                            sample = (
                                self._sync.add(sent, stamp, received, same, replier)
                                if current
                                else None
                            )
                            in_use = self._sync.driver == replier
                        if sample is not None and in_use and self._view is not None:
                            # the view wants the offset from this process's monotonic clock
                            skew = self._clock() - time.monotonic_ns()
                            self._view.on_link(sample.rtt_ns / 1e6, sample.offset_ns + skew)
                self._say_repliers()
            except Exception as exc:  # a closing session must not kill the thread noisily
                if stop.is_set():
                    return
                log.debug("clock query failed: %s", exc)
            with self._lock:
                confirmed = self._sync.confirmed
                raced = epoch != self._robot_epoch
            if raced:  # the robot (re)appeared during the query, its reply was dropped: ask now
                continue
            # 10 Hz until the robot's telemetry confirms the clock in use (a second replier
            # that comes later is then seen within 0.1 s), then 1 Hz; at once when the robot
            # (re)appears (its clock was forgotten: a new operator session waits for it)
            self._sync_wake.wait(1.0 if confirmed else 0.1)
            self._sync_wake.clear()

    def _say_repliers(self) -> None:
        """More than one peer answers the clock query: name them in the log (at once when the
        clock in use changes, else every ``_REPLIERS_LOG_NS`` at most)."""
        with self._lock:
            views = self._sync.repliers()
        if len(views) < 2:
            self._replier_key = None
            return
        key = tuple((v.replier, v.drives) for v in views)
        now = self._clock()
        if key != self._replier_key:
            self._replier_key = key
            self._replier_log = EventLog(_REPLIERS_LOG_NS)
        if self._replier_log.allow("repliers", now) is None:
            return
        with self._lock:
            telemetry_seen = self._telemetry_rx_ns is not None
        parts = []
        for v in views:
            if v.drives:
                role = "its clock drives the command stamps"
            elif v.telemetry_age_ns is not None:
                age_s = v.telemetry_age_ns / NS_PER_S
                role = f"ignored, the robot's telemetry is {age_s:+.3g} s old on its clock"
            elif telemetry_seen:
                role = "ignored, its clock does not fit the robot's telemetry"
            else:
                role = "ignored until telemetry tells the clocks apart"
            parts.append(f"{v.replier}: {role}")
        using = "" if any(v.drives for v in views) else "; commands go out unsynchronised"
        log.warning(
            "%d peers answer the clock query of robot %s (a rogue, or two robots with that id?):"
            " %s%s",
            len(views),
            self._robot,
            "; ".join(parts),
            using,
        )

    def _map_loop(self, stop: StopRequest) -> None:
        """The robot's static map (``egc/<robot>/map``) for the view's world frame, once per
        appearance of the robot: again after a restart or a long outage (a liveliness PUT), and
        it replaces the map the view has.

        Its own thread: a query waits up to ``_MAP_TIMEOUT_S`` for a reply that crosses a slow
        link, and must hold back neither the commands nor the clock sync. Asked again every
        ``_MAP_RETRY_S`` while none came, counting only the attempts made while the robot is
        present (a robot that serves no map is left alone after ``_MAP_ATTEMPTS``, until it
        appears again).
        """
        done_epoch: int | None = None  # the appearance whose map came (or was given up on)
        asked_epoch: int | None = None  # the appearance ``attempts`` counts for
        attempts = 0
        while not stop.is_set():
            with self._lock:
                present, epoch = self._robot_alive, self._robot_epoch
            if not present or epoch == done_epoch:
                self._map_wake.wait(_MAP_RETRY_S)
                self._map_wake.clear()
                continue
            if epoch != asked_epoch:
                asked_epoch, attempts = epoch, 0
            attempts += 1
            if self._fetch_map(stop) or attempts >= _MAP_ATTEMPTS:
                done_epoch = epoch  # one that reappeared during the query is asked again
            else:
                stop.wait(_MAP_RETRY_S)

    def _fetch_map(self, stop: StopRequest) -> bool:
        """One map query; True once the view has the map."""
        try:
            replies = self._session.get(keys.world_map(self._robot), timeout=_MAP_TIMEOUT_S)
            for reply in replies:
                ok = reply.ok
                world = None if ok is None else decode_map(payload_bytes(ok))
                if isinstance(world, Rejection):
                    self._reject("map", world)
                elif world is not None and self._view is not None and not stop.is_set():
                    self._view.set_world(
                        world.blocked,
                        world.resolution_m,
                        (world.origin_x_m, world.origin_y_m),
                        world.goal,
                    )
                    log.info("map %d x %d cells from the robot", *world.blocked.shape)
                    return True
        except Exception as exc:  # a closing session
            log.debug("map query failed: %s", exc)
        return False

    # -- the publishing loop --------------------------------------------------------------------

    def run(self, stop: StopRequest) -> None:
        """Publish until ``stop`` is set or a finite source ends (then release the deadman)."""
        sync_thread = threading.Thread(
            target=self._clock_sync, args=(stop,), name="clock-sync", daemon=True
        )
        sync_thread.start()
        goal_thread = threading.Thread(
            target=self._goal_loop, args=(stop,), name="via-points", daemon=True
        )
        goal_thread.start()
        if self._view is not None:
            threading.Thread(
                target=self._map_loop, args=(stop,), name="world-map", daemon=True
            ).start()
        pressed = {"next": False, "clear": False}
        opened = self._clock()
        start: int | None = None  # a script's time 0: when the robot is first seen
        deadline = opened
        next_status = opened
        ended_at: int | None = None
        seq = 0
        last: OperatorCommand | None = None
        holding_back = getattr(self._source, "holding_back", None)
        while not stop.is_set():
            stop.wait(max(0, deadline - self._clock()) / NS_PER_S)
            now = self._clock()
            if start is None:
                with self._lock:
                    present = self._robot_alive
                if present or now - opened >= _START_WAIT_NS:
                    start = now
            # Until the robot is there (a slow link takes seconds to connect), nothing is sent
            # and a recorded script does not run ahead of the robot: a command could reach the
            # robot before its liveliness token reaches us, and be refused as not in control.
            # A fleet's node also holds back until its clock sync converges (``holding_back``).
            sending = start is not None and not (holding_back is not None and holding_back())
            sample = RELEASED if start is None else self._source.sample((now - start) / NS_PER_S)
            if self._source.finished:
                ended_at = now if ended_at is None else ended_at
                sample = RELEASED
                if now - ended_at >= _RELEASE_AFTER_END_NS:
                    break
            for action, held in (("next", sample.via_next), ("clear", sample.via_clear)):
                if held and not pressed[action]:  # the press edge
                    with self._lock:
                        self._actions.append(action)
                    self._goal_wake.set()
                pressed[action] = held
            if sending:
                seq += 1
            frame_ns = None if self._camera is None else _camera_stamp(self._camera)
            with self._lock:
                stamp = self._sync.robot_now(now)
                shown = self._telemetry
                synchronised = self._sync.synchronised
                age = view_age_ms(stamp, synchronised, None if shown is None else shown.stamp_ns)
                rx = round(self._rx.kbps(now)) if self._rx.total_bytes else None
            # The camera's age on the same reading of the robot's clock as the stamp: the robot
            # finds the frame shown from the two (egc_common.view_budget).
            camera_age = None
            if frame_ns is not None and age is not None:
                camera_age = view_age_ms(stamp, synchronised, frame_ns)
            command = OperatorCommand(
                seq=seq,
                stamp_ns=stamp,
                x=sample.x,
                y=sample.y,
                mode=sample.mode,
                deadman=sample.deadman,
                estop=sample.estop,
                reset=sample.reset,
                op=self._op,
                view_age_ms=age,
                filter=sample.filter if sample.filter is not None else self._filter_default,
                rx_kbps=rx,
                camera_age_ms=camera_age,
            )
            if sending:
                self._publisher.put(command.encode())
                self.published += 1
            if sending and stamp > 0:
                self.history.add(
                    SentCommand(
                        stamp, sample.x, sample.y, sample.mode, sample.deadman, sample.estop
                    )
                )
                if self._view is not None:
                    self._view.on_commands(self.history, stamp)
            if now >= next_status:
                if self._status is not None:
                    self._status.show(self._status_of(command), now / NS_PER_S)
                self.camera.tick()  # the camera's age line, and its stale mark
                next_status = now + _STATUS_PERIOD_NS
            deadline += self._period_ns
            if deadline <= now:
                deadline = now + self._period_ns
            last = command if sending else last
        if last is not None and last.deadman:
            self._release_on_exit(last)
        stop.set()
        self._goal_wake.set()
        self._sync_wake.set()
        sync_thread.join(timeout=2 * _CLOCK_TIMEOUT_S)
        goal_thread.join(timeout=2 * _CLOCK_TIMEOUT_S)

    def _release_on_exit(self, last: OperatorCommand) -> None:
        """Stopped (a --duration, a signal) with the deadman held: one last command releases it,
        so the robot holds because the operator let go, before the liveliness token goes (it
        would otherwise see an operator lost while driving)."""
        frame_ns = None if self._camera is None else _camera_stamp(self._camera)
        with self._lock:
            stamp = self._sync.robot_now(self._clock())
            shown = self._telemetry
            synchronised = self._sync.synchronised
        # Its ages on its own stamp, as every command's (not the last command's: older by up
        # to a period, they would say the view was fresher than it was).
        age = view_age_ms(stamp, synchronised, None if shown is None else shown.stamp_ns)
        camera_age = None
        if frame_ns is not None and age is not None:
            camera_age = view_age_ms(stamp, synchronised, frame_ns)
        try:
            release = replace(
                last,
                seq=last.seq + 1,
                stamp_ns=stamp,
                x=0.0,
                y=0.0,
                deadman=False,
                estop=False,
                view_age_ms=age,
                camera_age_ms=camera_age,
            )
            self._publisher.put(release.encode())
            self.published += 1
            # Closing the session right away can close the transport before the release has
            # left the transmission queue; the robot then sees the token go first.
            time.sleep(_RELEASE_FLUSH_S)
        except Exception as exc:  # a closing session: the token's withdrawal stops it anyway
            log.debug("release on exit not sent: %s", exc)

    # -- via points thread ------------------------------------------------------------------------

    def _goal_loop(self, stop: StopRequest) -> None:
        """Apply next/clear presses and publish the route when due (see the module docstring)."""
        if self._view is not None and self._planner.engaged:
            route = self._planner.route
            self._view.on_route(route.points, route.frame)
        while not stop.is_set():
            self._goal_wake.wait(_GOAL_POLL_S)
            self._goal_wake.clear()
            if stop.is_set():
                return
            try:
                self._goal_step()
            except Exception as exc:  # a closing session must not kill the thread noisily
                if stop.is_set():
                    return
                log.warning("via points not sent: %s", exc)

    def _goal_step(self) -> None:
        with self._lock:
            actions, self._actions = self._actions, []
            t, present, state = self._telemetry, self._robot_alive, self._state
            stamp = self._sync.robot_now(self._clock())
        planner = self._planner
        in_control = present and state is not None and state.operator == self._op
        if in_control and not self._goal_in_control:
            planner.resend()  # control (re)taken: the robot has no via points of ours
        self._goal_in_control = in_control
        for action in actions:
            before = planner.route
            if action == "clear":
                planner.clear()
                log.info("via points cleared")
            elif t is None or not planner.next(t.goal, t.goal_frame, t.goals_left):
                log.info("next via point: no active via point of this route to skip")
                continue
            else:
                log.info("via point skipped: %d left", len(planner.route.points))
            if self._view is not None and planner.route != before:
                self._view.on_route(planner.route.points, planner.route.frame)
            if self._view is not None:
                self._view.on_text("INFO", f"via points: {action}")
        now = self._clock()
        route = planner.route
        if route is not self._last_route:
            self._last_route, self._route_echoed, self._route_pending_since_ns = route, False, None
        if t is not None and active_index(route, t.goal, t.goal_frame, t.goals_left) is not None:
            self._route_echoed = True
        if planner.due(now, in_control):
            if route.points and self._route_pending_since_ns is None:
                self._route_pending_since_ns = now
            message = planner.message(self._op, stamp, now)
            self._goal_publisher.put(message.encode())
            self.goals_published += 1
            if message.seq == 1 or actions:
                log.info(
                    "via points sent: %d in %s (seq %d)",
                    len(message.points),
                    message.frame,
                    message.seq,
                )

    def _status_of(self, command: OperatorCommand) -> Status:
        with self._lock:
            t, s, alive = self._telemetry, self._state, self._robot_alive
            latest = self._sync.latest
            synced = self._sync.synchronised
            rx = self._telemetry_rx_ns
            state_rx = self._state_rx_ns
            episode = self._episode
            now = self._clock()
            rtt_ms = None if latest is None else latest.rtt_ns / 1e6
            age_s = None if rx is None else (now - rx) / NS_PER_S
            state_age_s = None if state_rx is None else (now - state_rx) / NS_PER_S
            status = status_of(
                command,
                t,
                s,
                rtt_ms,
                synced,
                alive,
                age_s,
                episode,
                state_age_s=state_age_s,
                rejections=self.rejections.recent(now),
                clock_note=self._sync.note(),
                rx_kbps=command.rx_kbps,
            )
        pending = self._route_pending_since_ns
        if (
            pending is not None
            and not self._route_echoed
            and status.in_control
            and now - pending > VIA_UNTAKEN_NS
        ):
            status = replace(status, via_untaken=True)
        return status

    def close(self) -> None:
        self.camera.close()
        for entity in self._entities:
            entity.undeclare()
        self._token.undeclare()
        self._publisher.undeclare()
        self._goal_publisher.undeclare()
        if self._status is not None:
            self._status.close()
        if self._view is not None:
            self._view.close()
