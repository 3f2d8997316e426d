"""The robots on a Zenoh network, as their liveliness tokens and info replies tell (DESIGN 15).

A thin Zenoh adapter for ``egc-teleop robots`` and the operator's robot choice: a liveliness
subscriber with history on ``egc/*/alive/robot`` (robots already there are seen at once; a
robot whose session ends, or whose lease runs out, is gone) and one ``egc/<robot>/info`` query
per robot that appears. Replies are decoded like every message from the network: a bad one is
kept as a reason, never raised.
"""

from __future__ import annotations

import logging
import threading

import zenoh
from egc_common import keys
from egc_common.robot_info import RobotInfo, decode_info
from egc_common.transport import payload_bytes

log = logging.getLogger("egc.operator")
_INFO_TIMEOUT_S = 1.5


class FleetWatch:
    """Robots seen through their liveliness tokens, and their info replies (Zenoh's threads)."""

    def __init__(self, session: zenoh.Session) -> None:
        self._session = session
        self._lock = threading.Lock()
        self._alive: set[str] = set()
        self._info: dict[str, RobotInfo] = {}
        self._refused: dict[str, str] = {}
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
        if alive:
            threading.Thread(target=self._ask, args=(robot,), daemon=True).start()

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

    def close(self) -> None:
        self._subscriber.undeclare()  # type: ignore[no-untyped-call]
