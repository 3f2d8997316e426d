"""An operator driving one robot of a fleet at a time, switching at run time (DESIGN 8, 15).

``egc-teleop operator`` without ``--robot``: the session lists the robots it sees
(``FleetWatch``: liveliness ``egc/*/alive/robot`` with history, one info query per robot, and
every robot's state), drives the first one listed (or ``first``) and switches when asked: the
gamepad's button pair or a joystick file's ``robot_next`` / ``robot_prev`` columns
(``FleetSource``), or a line typed on the terminal (``typed``: ``robot NAME``, ``next``, ...).

One ``OperatorNode`` per driven robot, one after the other, each in its own thread, sharing the
session, the command source, the status line and the view's recording. A switch:

1. **Release.** The old node's source reads released from the press on (``NodeSource``): its
   next command, on the command stream, has the deadman released and the stick centred, so the
   robot holds at once for a reason it can tell (DESIGN 8 "deadman released"); then the node
   stops (a node stopped with the deadman held sends that command itself) and, once the
   robot's state says it no longer drives for this operator (``_await_release``, at most 1 s),
   closes, which withdraws its liveliness token ``egc/<old>/alive/operator/<id>``: control is
   handed over (DESIGN 8, "explicit release or loss hands it over"). The old robot is never driven again by
   this operator until it is switched back to, as a new session.
2. **Take.** A new node for the new robot starts at once, its source gated (nothing sent) until
   its clock sync has an estimate (the first command the robot takes is stamped on its clock, DESIGN 7; a
   robot that answers no clock query within a second gets unsynchronised commands, stamp 0,
   as an operator with ``--robot`` sends them). Its
   first commands come from a new operator session (new liveliness token, ``seq`` from 1), so
   the robot takes control only with the deadman held and drives only once the stick is
   centred (DESIGN 8); the status line says so meanwhile (the robot's own HOLD reason).

**Switch time**, logged for every switch (``switch r1 -> r2: 85.3 ms ...``) and kept in
``switch_ms``: from the press (a file's row time; a gamepad's or a typed line's when it was
read) to the first command the new robot accepted: the stamp, on the robot's clock, of its
first state message naming this operator in control (the robot publishes its state in the
cycle that took the command, on change), on this process's clock through the new node's clock
sync (error: half the round trip; 0 on one machine).

The other robots' link figures: one clock query a second each (``_probe_loop``), its round trip
for the fleet panel (and an estimate of that robot's clock, for its camera snapshot). The
status line shows the driven robot and the others' states (``fleet_line``); the view gets the
fleet rows once a second (``on_fleet``) and, while the driven robot's downlink budget leaves
room, snapshots of the other robots' cameras (``fleet_thumbnails``: one at a time, at most one
every 5 s).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import zenoh
from egc_common import keys
from egc_common.messages import decode_clock_reply
from egc_common.stop_flag import StopRequest
from egc_common.transport import payload_bytes

from egc_operator.camera_view import RobotClock
from egc_operator.command_source import CommandSource
from egc_operator.fleet_choice import (
    HELP,
    Help,
    ListRobots,
    Pick,
    Step,
    TypedError,
    cycled,
    listing,
    parse_typed,
    resolve,
)
from egc_operator.fleet_source import FleetSource, NodeSource
from egc_operator.fleet_table import FleetRow, fleet_rows, others_text
from egc_operator.fleet_thumbnails import FleetThumbnails, Thumbnail, snapshots_allowed
from egc_operator.fleet_watch import FleetWatch
from egc_operator.status_line import FleetLine, StatusLine

log = logging.getLogger("egc.operator")

NS_PER_S = 1_000_000_000
NS_PER_MS = 1_000_000
_POLL_S = 0.05  # the session's loop: requests wake it at once; this is for the rest
_SETTLE_NS = NS_PER_S // 2  # after the first robot appears, wait this long at most for info
_WAITING_LOG_NS = 5 * NS_PER_S  # "no robot seen yet", repeated
_PROBE_PERIOD_S = 1.0  # each robot's clock query (its round trip for the fleet panel)
_PROBE_TIMEOUT_S = 1.0
_FLEET_VIEW_PERIOD_NS = NS_PER_S
_JOIN_S = 8.0
_SYNC_WAIT_NS = NS_PER_S  # a new robot's commands wait this long at most for its clock
_RELEASE_ACK_NS = NS_PER_S  # a released robot's state confirms it, else its session ends anyway
_RELEASE_POLL_S = 0.005  # a closing node: its clock query may wait out its timeout (3 s)


class DrivingNode(Protocol):
    """What the session needs of the node driving one robot (``OperatorNode``)."""

    published: int

    def run(self, stop: StopRequest) -> None: ...
    def close(self) -> None: ...
    def robot_clock(self, local_ns: int) -> RobotClock | None: ...


class NodeFactory(Protocol):
    """Makes the node for ``robot``, sampling ``source``, drawing in ``view`` (a
    ``FleetView.for_robot`` view, or None)."""

    def __call__(self, robot: str, source: CommandSource, view: Any) -> DrivingNode: ...


class FleetView(Protocol):
    """What the session needs of the view (``egc_operator.view.OperatorView``)."""

    def for_robot(self, robot_id: str) -> Any: ...
    def on_fleet(self, rows: list[FleetRow], me: str, robot_now_ns: int | None) -> None: ...
    def on_thumbnail(self, thumb: Thumbnail, index: int, robot_now_ns: int | None) -> None: ...


class SessionStatus(StatusLine):
    """The status line shared by the session's nodes: a node's ``close`` leaves it open;
    ``finish`` closes it at the end of the session."""

    def close(self) -> None:
        pass

    def finish(self) -> None:
        super().close()


@dataclass(slots=True)
class _Drive:
    robot: str
    node: DrivingNode
    source: NodeSource
    stop: StopRequest
    thread: threading.Thread
    view: Any  # its view (``FleetView.for_robot``), or None
    press_ns: int | None = None  # the press that switched to it (None: the first robot)
    previous: str | None = None
    taken: bool = False  # the robot accepted a command of this node (its state said so)


@dataclass(slots=True)
class _Request:
    target: str
    press_ns: int
    why: str


@dataclass
class SwitchRecord:
    old: str
    new: str
    ms: float
    exact: bool  # through the clock sync (else: the state's arrival, an upper bound)


@dataclass
class _Probe:
    """The other robots' clock queries: round trip (ms) and clock offset (robot - local, ns)."""

    rtt_ms: dict[str, float] = field(default_factory=dict)
    offset_ns: dict[str, int] = field(default_factory=dict)


class FleetSession:
    def __init__(
        self,
        session: zenoh.Session,
        operator_id: str,
        source: CommandSource,
        make_node: NodeFactory,
        clock: Callable[[], int] = time.monotonic_ns,
        status: SessionStatus | None = None,
        view: FleetView | None = None,
        first: str | None = None,
        say: Callable[[str], None] | None = None,
    ) -> None:
        self._session = session
        self._op = operator_id
        self._make_node = make_node
        self._clock = clock
        self._status = status
        self._view = view
        self._first = first
        self._say_fn = say
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._requests: list[_Request] = []
        self._drive: _Drive | None = None
        self._closing: list[_Drive] = []
        self._probe = _Probe()
        self._snapshots_ns: dict[str, int] = {}  # when each robot's camera snapshot was taken
        self._thumb_index: dict[str, int] = {}  # its place in the view's row of snapshots
        self._thumbnails = (
            None
            if view is None
            else FleetThumbnails(
                session,
                self._snapshot_candidates,
                self._snapshots_allowed,
                self._on_thumbnail,
                self._robot_clock,
                clock,
            )
        )
        self.switches: list[SwitchRecord] = []
        self.published = 0  # commands sent by the nodes that have closed
        self.source = FleetSource(source, clock, self._on_button)
        self.watch = FleetWatch(
            session, states=True, clock=clock, on_change=self._wake.set, on_state=self._on_state
        )

    # -- what the status line and the view show ------------------------------------------------

    @property
    def driven(self) -> str | None:
        with self._lock:
            return None if self._drive is None else self._drive.robot

    def rows(self) -> list[FleetRow]:
        watch = self.watch
        robots = watch.robots()
        driven = self.driven
        if driven is not None and driven not in robots:
            robots = sorted([*robots, driven])
        states = {r: (s.state, s.rx_ns) for r, s in watch.states().items()}
        with self._lock:
            rtts = dict(self._probe.rtt_ms)
            snapshots = dict(self._snapshots_ns)
        infos = {r: watch.info(r) for r in robots}
        return fleet_rows(robots, infos, states, rtts, driven, self._clock(), snapshots)

    def fleet_line(self) -> FleetLine | None:
        driven = self.driven
        if driven is None:
            return None
        try:
            return FleetLine(driven, others_text(self.rows(), self._op))
        except Exception as exc:  # the status line must not fail on the fleet's part
            log.debug("fleet line: %s", exc)
            return None

    def _say(self, text: str) -> None:
        """A line for the person at the terminal (the listing, a switch, a typed error)."""
        if self._say_fn is not None:
            self._say_fn(text)
        elif self._status is not None:
            self._status.say(text)
        else:
            print(text, flush=True)

    def _list(self) -> None:
        watch = self.watch
        robots = [(r, watch.info(r)) for r in watch.robots()]
        if not robots:
            self._say("robots: none seen")
            return
        states = {r: s.state.state for r, s in watch.states().items()}
        self._say(f"robots ({len(robots)}; * driven):")
        for line in listing(robots, self.driven, states):
            self._say(line)

    # -- requests: the buttons (a node's thread) and typed lines (the terminal's thread) -------

    def _on_button(self, step: int, press_ns: int) -> bool:
        """The switch button pair was pressed (``FleetSource``, in the driving node's thread):
        True when there is a robot to switch to (the source then releases the old one)."""
        current = self.driven
        target = cycled(self.watch.robots(), current, step)
        if target is None:
            self._say(f"no other robot to switch to (driving {current})")
            return False
        self._request(_Request(target, press_ns, "button"))
        return True

    def typed(self, line: str) -> None:
        """A line typed on the terminal."""
        now = self._clock()
        command = parse_typed(line)
        if command is None:
            return
        if isinstance(command, ListRobots):
            self._list()
            return
        if isinstance(command, Help):
            self._say(HELP)
            return
        if isinstance(command, TypedError):
            self._say(command.text)
            return
        current = self.driven
        robots = self.watch.robots()
        if isinstance(command, Step):
            target: str | TypedError | None = cycled(robots, current, command.step)
            if target is None:
                self._say(f"no other robot to switch to (driving {current})")
                return
        else:
            assert isinstance(command, Pick)
            target = resolve(robots, command.which)
        if isinstance(target, TypedError):
            self._say(target.text)
            return
        if target == current:
            self._say(f"already driving {target}")
            return
        with self._lock:
            drive = self._drive
        if drive is not None:
            drive.source.release()  # its next command lets go of the robot
        self._request(_Request(target, now, "typed"))

    def _request(self, request: _Request) -> None:
        with self._lock:
            self._requests.append(request)
        self._wake.set()

    # -- the robots' states: the switch's end ---------------------------------------------------

    def _on_state(self, robot: str, state: Any, rx_ns: int) -> None:
        """A robot's state message (Zenoh's thread): the first one from the driven robot that
        names this operator in control ends the switch to it."""
        with self._lock:
            drive = self._drive
            if drive is None or drive.robot != robot or drive.taken or state.operator != self._op:
                return
            drive.taken = True
        press = drive.press_ns
        if press is None or drive.previous is None:
            log.info("robot %s took this operator's commands", robot)
            return
        clock = drive.node.robot_clock(rx_ns)
        if clock is not None:  # the robot's time of the cycle that took it, on our clock
            accepted_ns = min(rx_ns, state.stamp_ns - (clock.now_ns - rx_ns))
            exact = True
        else:
            accepted_ns, exact = rx_ns, False
        ms = max(0.0, (accepted_ns - press) / NS_PER_MS)
        self.switches.append(SwitchRecord(drive.previous, robot, ms, exact))
        log.info(
            "switch %s -> %s: %.1f ms from the press to the first command %s accepted%s",
            drive.previous,
            robot,
            ms,
            robot,
            "" if exact else " (at most: its state's arrival, the clock was not synchronised)",
        )

    # -- the session ------------------------------------------------------------------------------

    def run(self, stop: StopRequest) -> None:
        probe = threading.Thread(
            target=self._probe_loop, args=(stop,), name="fleet-clocks", daemon=True
        )
        probe.start()
        if self._thumbnails is not None:
            threading.Thread(
                target=self._thumbnails.run, args=(stop,), name="fleet-snapshots", daemon=True
            ).start()
        try:
            robot = self._wait_first(stop)
            if robot is None:
                return
            self._list()
            self._say(f"driving {robot}; {HELP}, or press the switch buttons")
            self._start(robot, None, None)
            self._loop(stop)
        finally:
            stop.set()
            self._stop_all()
            probe.join(timeout=2 * _PROBE_TIMEOUT_S)

    def _wait_first(self, stop: StopRequest) -> str | None:
        """The first robot to drive: ``first`` once it is seen, else the first listed once the
        robots seen have answered their info queries (or after ``_SETTLE_NS``)."""
        started = self._clock()
        seen_at: int | None = None
        said = started
        while not stop.is_set():
            now = self._clock()
            robots = self.watch.robots()
            if self._first is not None:
                if self._first in robots:
                    return self._first
            elif robots:
                seen_at = now if seen_at is None else seen_at
                answered = all(self.watch.info(r) is not None for r in robots)
                if answered or now - seen_at >= _SETTLE_NS:
                    return robots[0]
            if now - said >= _WAITING_LOG_NS:
                said = now
                wanted = f"robot {self._first}" if self._first else "a robot"
                log.info(
                    "waiting for %s (%.0f s; robots seen: %s)",
                    wanted,
                    (now - started) / NS_PER_S,
                    ", ".join(robots) or "none",
                )
            self._wake.wait(_POLL_S)
            self._wake.clear()
        return None

    def _start(self, robot: str, press_ns: int | None, previous: str | None) -> None:
        view = None if self._view is None else self._view.for_robot(robot)
        holder: list[DrivingNode] = []
        started = self._clock()
        unsynced: list[bool] = []

        def ready() -> bool:
            if holder and holder[0].robot_clock(self._clock()) is not None:
                return True
            if self._clock() - started < _SYNC_WAIT_NS:
                return False
            if not unsynced:  # a robot that answers no clock query is driven as before
                unsynced.append(True)
                log.warning("robot %s: no clock reply yet; commands go out unsynchronised", robot)
            return True

        source = self.source.node_source(gate=ready)
        node = self._make_node(robot, source, view)
        holder.append(node)
        stop = threading.Event()
        thread = threading.Thread(
            target=self._drive_loop, args=(robot, node, stop), name=f"drive-{robot}", daemon=True
        )
        drive = _Drive(robot, node, source, stop, thread, view, press_ns, previous)
        with self._lock:
            self._drive = drive
        thread.start()
        log.info("operator %r driving robot %r", self._op, robot)
        if view is not None:  # at that robot's time, in its view
            view.on_text("INFO", f"driving {robot}" + (f" (was {previous})" if previous else ""))

    def _drive_loop(self, robot: str, node: DrivingNode, stop: StopRequest) -> None:
        try:
            node.run(stop)
        except Exception:  # a bug in one node must not leave the others running blind
            log.exception("the node driving a robot failed")
        finally:
            stop.set()
            self._await_release(robot)
            node.close()
            with self._lock:
                self.published += node.published

    def _await_release(self, robot: str) -> None:
        """The node's last command released the deadman: before its liveliness token goes,
        wait (at most ``_RELEASE_ACK_NS``) until the robot's state says it no longer drives
        for this operator. The token's withdrawal can overtake the command on the way (a
        router forwards declarations and data separately; seen in the switching test), and the
        robot would then hold for "operator lost" instead of the release it was sent."""
        deadline = self._clock() + _RELEASE_ACK_NS
        while self._clock() < deadline:
            seen = self.watch.states().get(robot)
            if seen is None or seen.state.state != "DRIVING" or seen.state.operator != self._op:
                return
            time.sleep(_RELEASE_POLL_S)
        log.info("robot %s did not confirm the release in time: its session ends anyway", robot)

    def _loop(self, stop: StopRequest) -> None:
        next_view = self._clock()
        while not stop.is_set():
            self._wake.wait(_POLL_S)
            self._wake.clear()
            with self._lock:
                requests, self._requests = self._requests, []
                drive = self._drive
            assert drive is not None
            for request in requests[-1:]:  # several at once: the last one wins
                self._switch(drive, request)
                with self._lock:
                    drive = self._drive
                assert drive is not None
            if not requests and not drive.thread.is_alive():
                log.info("the command source ended: the session ends")
                return
            now = self._clock()
            if self._view is not None and now >= next_view:
                next_view = now + _FLEET_VIEW_PERIOD_NS
                self._show_fleet(drive)

    def _switch(self, old: _Drive, request: _Request) -> None:
        if request.target == old.robot:
            old.source.released = False  # nothing to switch to after all: drive on
            return
        old.source.release()
        if old.view is not None:
            old.view.clear_on_close = True  # the next robot's drawings replace its own
        old.stop.set()  # it sends the release (if its last command held the deadman) and closes
        self._closing.append(old)
        self._say(f"switching from {old.robot} to {request.target} ({request.why})")
        self._start(request.target, request.press_ns, old.robot)
        self._closing = [d for d in self._closing if d.thread.is_alive()]

    def _show_fleet(self, drive: _Drive) -> None:
        assert self._view is not None
        try:
            clock = drive.node.robot_clock(self._clock())
            self._view.on_fleet(self.rows(), self._op, None if clock is None else clock.now_ns)
        except Exception as exc:  # the view must not take the session down
            log.debug("fleet panel: %s", exc)

    def _stop_all(self) -> None:
        with self._lock:
            drive = self._drive
        drives = [*self._closing, *([drive] if drive is not None else [])]
        for d in drives:
            d.stop.set()
        for d in drives:
            d.thread.join(timeout=_JOIN_S)
        self.watch.close()

    # -- the other robots' camera snapshots -------------------------------------------------------

    def _snapshot_candidates(self) -> list[str]:
        driven = self.driven
        out = []
        for robot in self.watch.robots():
            info = self.watch.info(robot)
            if robot != driven and info is not None and info.camera != "none":
                out.append(robot)
        return out

    def _snapshots_allowed(self) -> bool:
        """The driven robot's budget leaves room (``fleet_thumbnails.snapshots_allowed``)."""
        with self._lock:
            drive = self._drive
        view = None if drive is None else drive.view
        latest = getattr(view, "latest_telemetry", None)
        return snapshots_allowed(None if latest is None else latest())

    def _on_thumbnail(self, thumb: Thumbnail) -> None:
        with self._lock:
            self._snapshots_ns[thumb.robot] = thumb.grabbed_ns
            index = self._thumb_index.setdefault(thumb.robot, len(self._thumb_index))
            drive = self._drive
        if self._view is None or drive is None:
            return
        clock = drive.node.robot_clock(self._clock())
        self._view.on_thumbnail(thumb, index, None if clock is None else clock.now_ns)

    def _robot_clock(self, robot: str, local_ns: int) -> RobotClock | None:
        """That robot's clock at ``local_ns`` from its clock probe (error: half the round
        trip), None before a reply."""
        with self._lock:
            offset = self._probe.offset_ns.get(robot)
            rtt_ms = self._probe.rtt_ms.get(robot)
        if offset is None or rtt_ms is None:
            return None
        return RobotClock(local_ns + offset, round(rtt_ms * NS_PER_MS) // 2)

    # -- the other robots' clocks: their round trips ----------------------------------------------

    def _probe_loop(self, stop: StopRequest) -> None:
        while not stop.wait(_PROBE_PERIOD_S):
            for robot in self.watch.robots():
                try:
                    self._probe_one(robot)
                except Exception as exc:  # a closing session
                    log.debug("clock probe of %s: %s", robot, exc)

    def _probe_one(self, robot: str) -> None:
        sent = self._clock()

        def on_reply(reply: zenoh.Reply) -> None:
            try:
                ok = reply.ok
                stamp = None if ok is None else decode_clock_reply(payload_bytes(ok))
                if isinstance(stamp, int):
                    received = self._clock()
                    with self._lock:
                        self._probe.rtt_ms[robot] = (received - sent) / NS_PER_MS
                        self._probe.offset_ns[robot] = stamp - (sent + received) // 2
            except Exception as exc:  # nothing from the network raises out of the callback
                log.debug("clock probe reply of %s: %s", robot, exc)

        self._session.get(
            keys.clock(robot),
            on_reply,
            timeout=_PROBE_TIMEOUT_S,
            priority=zenoh.Priority.INTERACTIVE_HIGH,
            express=True,
        )
