"""The robot's ``egc/<robot>/info`` queryable (DESIGN 15): a thin Zenoh adapter.

It answers every query with the robot's self-description as ``describe()`` gives it at that
moment (state and the operator in control change; profile, driver, filter and camera do not).
The callable is the wiring's (``egc_app.robot_cmd``); nothing raised in it or by a querier that
went away escapes the Zenoh callback.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import zenoh
from egc_common import keys
from egc_common.robot_info import RobotInfo

log = logging.getLogger("egc.robot")


class InfoServer:
    def __init__(
        self, session: zenoh.Session, robot_id: str, describe: Callable[[], RobotInfo]
    ) -> None:
        self._describe = describe
        self._key = keys.info(robot_id)
        self._queryable = session.declare_queryable(self._key, self._on_query)

    def _on_query(self, query: zenoh.Query) -> None:
        try:
            query.reply(self._key, self._describe().encode())
        except Exception as exc:  # a querier that went away must not kill the callback
            log.debug("info reply failed: %s", exc)

    def close(self) -> None:
        try:
            self._queryable.undeclare()  # type: ignore[no-untyped-call]
        except Exception as exc:  # the session may be closing already
            log.debug("info queryable undeclare failed: %s", exc)
