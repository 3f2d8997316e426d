"""A driver that announces its scans (the ROS 2 driver) gets a control cycle on each one, at once,
not at the next deadline of the fixed-rate loop."""

from __future__ import annotations

import time

import numpy as np
import pytest
from egc_common.messages import BaseCommand
from egc_common.profiles import PIONEER3DX
from egc_common.scan import Scan
from egc_common.transport import ZenohOptions, open_session
from egc_robot.controller import ControllerConfig, RobotController
from egc_robot.drivers import SensorUpdate
from egc_robot.pipeline import PipelineConfig
from egc_robot.zenoh_node import RobotNode


class AnnouncingDriver:
    """Stands in for a sensor and base that are not here: scans are handed in by the test."""

    def __init__(self) -> None:
        self.sent: list[BaseCommand] = []
        self.listener = None
        self._scan: Scan | None = None

    def set_scan_listener(self, listener) -> None:
        self.listener = listener

    def arrive(self, scan: Scan) -> None:
        self._scan = scan
        self.listener()

    def poll(self, now_ns: int) -> SensorUpdate:
        scan, self._scan = self._scan, None
        return SensorUpdate(scan=scan, scan_rx_ns=0 if scan is None else scan.stamp_ns)

    def send(self, command: BaseCommand) -> None:
        self.sent.append(command)

    def close(self) -> None:
        pass


def wall_scan(stamp_ns: int) -> Scan:
    angles = np.linspace(-np.pi, np.pi, 360, endpoint=False)
    return Scan.uniform(
        np.full(360, 2.0),
        float(angles[0]),
        float(angles[1] - angles[0]),
        0.05,
        8.0,
        stamp_ns=stamp_ns,
    )


@pytest.mark.integration
def test_each_announced_scan_runs_one_cycle_and_none_after_shutdown():
    session = open_session(ZenohOptions(mode="peer"))
    try:
        controller = RobotController(
            ControllerConfig(PipelineConfig(PIONEER3DX)), time.monotonic_ns()
        )
        driver = AnnouncingDriver()
        node = RobotNode(session, "scan-cycle", controller, driver, rate_hz=20.0)
        assert driver.listener is not None  # attached by the node, no loop running
        for _ in range(3):
            driver.arrive(wall_scan(time.monotonic_ns()))
        assert len(driver.sent) == 3 and controller.counters.cycles == 3
        node.shutdown()
        stopped = len(driver.sent)  # the shutdown's zero command
        driver.arrive(wall_scan(time.monotonic_ns()))
        assert len(driver.sent) == stopped  # nothing runs after shutdown
    finally:
        session.close()
