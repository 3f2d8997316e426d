"""The robots on a Zenoh network, as their liveliness tokens and info replies tell (DESIGN 15).

A thin Zenoh adapter for ``egc-teleop robots`` and the operator's robot choice: a liveliness
subscriber with history on ``egc/*/alive/robot`` (robots already there are seen at once; a
robot whose session ends, or whose lease runs out, is gone) and one ``egc/<robot>/info`` query
per robot that appears. Replies are decoded like every message from the network: a bad one is
kept as a reason, never raised.

With ``states=True`` (the operator's fleet session) it also follows every robot's state
(``egc/*/state``, on change and at 1 Hz, control plane: small): the newest message per robot
and when it came (``clock``, this process's monotonic clock), for the status line's and the
view's fleet. A state that does not decode is counted per robot (``state_refused``), dropped.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass

import zenoh
from egc_common import keys
from egc_common.messages import Rejection, StateMessage, decode_state
from egc_common.robot_info import RobotInfo, decode_info
from egc_common.transport import payload_bytes

log = logging.getLogger("egc.operator")
_INFO_TIMEOUT_S = 1.5


@dataclass(frozen=True, slots=True)
class SeenState:
    """A robot's newest state message and when it arrived (local monotonic ns)."""

    state: StateMessage
    rx_ns: int


class FleetWatch:
    """Robots seen through their liveliness tokens, and their info replies (Zenoh's threads)."""

    def __init__(
        self,
        session: zenoh.Session,
        states: bool = False,
        clock: Callable[[], int] = time.monotonic_ns,
        on_change: Callable[[], None] | None = None,
        on_state: Callable[[str, StateMessage, int], None] | None = None,
    ) -> None:
        self._session = session
        self._clock = clock
        self._on_change = on_change  # a robot came or went
        self._on_state_cb = on_state  # every state message taken: (robot, state, arrival)
        self._lock = threading.Lock()
        self._alive: set[str] = set()
        self._info: dict[str, RobotInfo] = {}
        self._refused: dict[str, str] = {}
        self._states: dict[str, SeenState] = {}
        self.state_refused: Counter[str] = Counter()
        self._state_subscriber = (
            session.declare_subscriber(keys.ALL_ROBOTS_STATE, self._on_state) if states else None
        )
        self._subscriber = session.liveliness().declare_subscriber(
            keys.ALL_ROBOTS_ALIVE, self._on_alive, history=True
        )

    def _on_alive(self, sample: zenoh.Sample) -> None:
        robot = keys.robot_id_from_key(str(sample.key_expr))
        if robot is None:
            return
        alive = sample.kind == zenoh.SampleKind.PUT
        with self._lock:
            if alive:
                self._alive.add(robot)
            else:
                self._alive.discard(robot)
                self._info.pop(robot, None)
                self._states.pop(robot, None)
        if alive:
            threading.Thread(target=self._ask, args=(robot,), daemon=True).start()
        if self._on_change is not None:
            try:
                self._on_change()
            except Exception as exc:  # never out of a Zenoh callback
                log.warning("fleet change callback failed: %s", exc)

    def _on_state(self, sample: zenoh.Sample) -> None:
        try:
            robot = keys.robot_id_from_key(str(sample.key_expr))
            if robot is None:
                return
            s = decode_state(payload_bytes(sample))
            now = self._clock()
            with self._lock:
                if isinstance(s, Rejection):
                    self.state_refused[robot] += 1
                elif robot in self._alive:  # a late message of a robot gone is not its state
                    self._states[robot] = SeenState(s, now)
                else:
                    return
            if not isinstance(s, Rejection) and self._on_state_cb is not None:
                self._on_state_cb(robot, s, now)
        except Exception as exc:  # nothing from the network raises out of the callback
            log.debug("state of a robot not read: %s", exc)

    def _ask(self, robot: str) -> None:
        try:
            replies = self._session.get(keys.info(robot), timeout=_INFO_TIMEOUT_S)
            for reply in replies:
                if reply.ok is None:
                    continue
                info = decode_info(payload_bytes(reply.ok))
                with self._lock:
                    if isinstance(info, RobotInfo) and info.robot == robot:
                        self._info[robot] = info
                    else:
                        self._refused[robot] = (
                            str(info)
                            if not isinstance(info, RobotInfo)
                            else (f"it calls itself {info.robot!r}")
                        )
        except Exception as exc:  # the session closing under a query, a peer gone
            log.debug("info query for %s failed: %s", robot, exc)

    def snapshot(self) -> list[tuple[str, RobotInfo | None]]:
        with self._lock:
            return [(robot, self._info.get(robot)) for robot in sorted(self._alive)]

    def refused(self) -> dict[str, str]:
        with self._lock:
            return dict(self._refused)

    def robots(self) -> list[str]:
        with self._lock:
            return sorted(self._alive)

    def states(self) -> dict[str, SeenState]:
        """The newest state message of each robot present (``states=True``)."""
        with self._lock:
            return dict(self._states)

    def info(self, robot: str) -> RobotInfo | None:
        with self._lock:
            return self._info.get(robot)

    def close(self) -> None:
        self._subscriber.undeclare()  # type: ignore[no-untyped-call]
        if self._state_subscriber is not None:
            self._state_subscriber.undeclare()  # type: ignore[no-untyped-call]
