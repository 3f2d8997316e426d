"""The remote driver: base and sensor in another process over Zenoh (DESIGN 7 keys).

Subscribes to ``egc/<robot>/scan`` and ``egc/<robot>/base/odom``, publishes
``egc/<robot>/base/cmd`` with command QoS (high priority, express). Payloads are decoded
strictly; a rejected payload is counted and logged, never raised. Arrival times are taken in
the Zenoh callback with the robot's monotonic clock, so scan freshness is measured on the robot.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter

import zenoh
from egc_common import keys
from egc_common.footprint import Footprint
from egc_common.messages import (
    BaseCommand,
    Odometry,
    Rejection,
    RejectReason,
    decode_odometry,
    decode_scan,
)
from egc_common.scan import Scan
from egc_common.transport import command_publisher, payload_bytes

from egc_robot.drivers import SensorUpdate, scan_from_message

log = logging.getLogger("egc.robot.driver")
_NOTHING_NEW = SensorUpdate()


class ZenohDriver:
    def __init__(
        self,
        session: zenoh.Session,
        robot_id: str,
        footprint_half_m: Footprint | tuple[float, float] | None = None,
    ) -> None:
        """``footprint_half_m``: the profile's footprint (or a centred rectangle's half sizes), for ``-inf`` readings."""
        self._footprint_half_m = footprint_half_m
        self._lock = threading.Lock()
        self._scan: Scan | None = None
        self._scan_rx_ns = 0
        self._odometry: Odometry | None = None
        self.rejected: Counter[str] = Counter()
        self._send_lock = threading.Lock()
        self._closed = False
        self._publisher = command_publisher(session, keys.base_cmd(robot_id))
        self._subscribers = [
            session.declare_subscriber(keys.scan(robot_id), self._on_scan),
            session.declare_subscriber(keys.base_odom(robot_id), self._on_odometry),
        ]

    def _on_scan(self, sample: zenoh.Sample) -> None:
        try:
            self._take_scan(sample)
        except Exception as exc:  # nothing from the network raises out of the receive path
            self._count(Rejection(RejectReason.OUT_OF_RANGE, f"unusable scan: {exc}"), "scan")

    def _take_scan(self, sample: zenoh.Sample) -> None:
        now_ns = time.monotonic_ns()
        decoded = decode_scan(payload_bytes(sample))
        if isinstance(decoded, Rejection):
            self._count(decoded, "scan")
            return
        scan = scan_from_message(decoded, self._footprint_half_m)
        if isinstance(scan, Rejection):
            self._count(scan, "scan")
            return
        # Prepared here, in the receiving thread, off the command path: the checked points and
        # their index by distance, which the filter and the sweep look near places with.
        scan.obstacles().index()
        with self._lock:
            self._scan, self._scan_rx_ns = scan, now_ns

    def _on_odometry(self, sample: zenoh.Sample) -> None:
        decoded = decode_odometry(payload_bytes(sample))
        if isinstance(decoded, Rejection):
            self._count(decoded, "odometry")
            return
        with self._lock:
            self._odometry = decoded

    def _count(self, rejection: Rejection, what: str) -> None:
        with self._lock:
            self.rejected[rejection.reason.value] += 1
            n = self.rejected[rejection.reason.value]
        if n == 1 or n % 100 == 0:
            log.warning("rejected %s from the driver (%d so far): %s", what, n, rejection)

    def poll(self, now_ns: int) -> SensorUpdate:
        with self._lock:
            scan, rx_ns, odometry = self._scan, self._scan_rx_ns, self._odometry
            self._scan, self._odometry = None, None
        if scan is None and odometry is None:
            return _NOTHING_NEW  # most polls, e.g. each command's between two scans
        return SensorUpdate(scan=scan, scan_rx_ns=rx_ns, odometry=odometry)

    def send(self, command: BaseCommand) -> None:
        # A command callback may still be sending while the process closes: Zenoh's publisher
        # must not be undeclared while another thread uses it ("Already borrowed").
        with self._send_lock:
            if not self._closed:
                self._publisher.put(command.encode())

    def close(self) -> None:
        for subscriber in self._subscribers:
            subscriber.undeclare()
        with self._send_lock:
            self._closed = True
            self._publisher.undeclare()
