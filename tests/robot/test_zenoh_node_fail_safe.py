"""The robot node stops the base and keeps serving when a control cycle fails (a bug path)."""

from __future__ import annotations

import threading
import time

import pytest
from egc_common.messages import BaseCommand
from egc_common.profiles import PIONEER3DX
from egc_common.transport import ZenohOptions, open_session
from egc_robot.controller import ControllerConfig, CycleOutput, RobotController
from egc_robot.drivers import SensorUpdate
from egc_robot.pipeline import PipelineConfig
from egc_robot.zenoh_node import RobotNode


class RecordingDriver:
    def __init__(self) -> None:
        self.sent: list[BaseCommand] = []

    def poll(self, now_ns: int) -> SensorUpdate:
        return SensorUpdate(scan=None, scan_rx_ns=0, odometry=None)

    def send(self, command: BaseCommand) -> None:
        self.sent.append(command)

    def close(self) -> None:
        pass


class FaultyController(RobotController):
    """Fails every other cycle, as a latent bug might."""

    calls = 0

    def step(self, now_ns: int) -> CycleOutput:
        self.calls += 1
        if self.calls % 2:
            raise RuntimeError("injected fault")
        return super().step(now_ns)


@pytest.mark.integration
def test_failed_cycles_send_zero_and_the_loop_keeps_running(caplog):
    session = open_session(ZenohOptions(mode="peer"))
    try:
        controller = FaultyController(
            ControllerConfig(PipelineConfig(PIONEER3DX)), time.monotonic_ns()
        )
        driver = RecordingDriver()
        node = RobotNode(session, "failsafe", controller, driver, rate_hz=50.0)
        stop = threading.Event()
        loop = threading.Thread(target=node.run, args=(stop,))
        loop.start()
        deadline = time.monotonic() + 30.0  # 10 cycles at 50 Hz: 0.2 s on an idle machine
        while controller.calls < 10 and loop.is_alive() and time.monotonic() < deadline:
            time.sleep(0.01)
        stop.set()
        loop.join(timeout=5)
        node.shutdown()
    finally:
        session.close()
    assert not loop.is_alive()
    assert controller.calls >= 10  # the loop survived the faults
    assert driver.sent and all(c.linear_mps == 0.0 and c.angular_radps == 0.0 for c in driver.sent)
    assert sum(c.seq == 0 for c in driver.sent) >= controller.calls // 2 - 1  # one stop per fault
    assert "control cycle failed" in caplog.text


def test_event_lines_are_held_back_to_one_a_second_with_a_count():
    from egc_common.event_log import EventLog

    events, s = EventLog(), 1_000_000_000
    assert events.allow("alive", 0) == 0
    assert [events.allow("alive", t) for t in (1, 2, 3)] == [None, None, None]
    assert events.allow("goal", 5) == 0  # each kind on its own
    assert events.allow("alive", s) == 3  # the next line says how many were held back
    assert events.allow("alive", s + 1) is None
