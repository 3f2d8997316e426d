"""Commands that queued while a control cycle ran are vetted one by one and driven on as one: a
cycle on the newest, not one per queued command (``egc_robot.command_batch``). One cycle per
command let a queue stand ~1 s deep on a busy machine (DWA cycles slower than the command
period); the robot drove on commands just under the stale limit."""

from __future__ import annotations

import threading
import time

import pytest
from egc_common import keys
from egc_common.messages import BaseCommand, OperatorCommand, decode_command
from egc_common.profiles import PIONEER3DX
from egc_common.transport import ZenohOptions, command_publisher, open_session
from egc_robot.command_batch import ControlBits, control_bits, cycle_before, decoded_control_bits
from egc_robot.controller import ControllerConfig, CycleOutput, RobotController
from egc_robot.drivers import SensorUpdate
from egc_robot.pipeline import PipelineConfig
from egc_robot.zenoh_node import RobotNode

WAIT_S = 30.0  # generous: the conditions below are waited on, never timed


def command(seq: int, *, deadman: bool = True, x: float = 0.0, estop: bool = False):
    # stamp 0: an unsynchronised operator, never stale (the test must not depend on the load)
    return OperatorCommand(
        seq=seq, stamp_ns=0, x=x, y=0.0, mode="shared", deadman=deadman, estop=estop,
        reset=False, op="op1",
    )  # fmt: skip


class GatedController(RobotController):
    """Records which command each cycle ran on; its first cycle waits for the test's gate, so
    that commands queue behind it as they do behind a slow cycle on a busy machine."""

    def __init__(self) -> None:
        super().__init__(ControllerConfig(PipelineConfig(PIONEER3DX)), time.monotonic_ns())
        self.gate = threading.Event()
        self.entered = threading.Event()
        self.cycled_on: list[int | None] = []  # the seq of the command each cycle saw

    def step(self, now_ns: int) -> CycleOutput:
        self.entered.set()
        if not self.cycled_on:
            self.gate.wait(WAIT_S)
        self.cycled_on.append(None if self._command is None else self._command.seq)
        return super().step(now_ns)


class NullDriver:
    def __init__(self) -> None:
        self.sent: list[BaseCommand] = []

    def poll(self, now_ns: int) -> SensorUpdate:
        return SensorUpdate()

    def send(self, command: BaseCommand) -> None:
        self.sent.append(command)

    def close(self) -> None:
        pass


def wait_for(condition, what: str) -> None:
    deadline = time.monotonic() + WAIT_S
    while not condition():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.01)


def drive_queued(queued: list[OperatorCommand]) -> GatedController:
    """Command 1, then ``queued`` published while the cycle on command 1 is held; the node's
    fixed-rate loop does not run, so every cycle is a command's."""
    session = open_session(ZenohOptions(mode="peer"))
    try:
        controller = GatedController()
        node = RobotNode(session, "batch", controller, NullDriver(), rate_hz=20.0)
        publisher = command_publisher(session, keys.cmd("batch"))
        try:
            publisher.put(command(1).encode())
            assert controller.entered.wait(WAIT_S), "no cycle on the first command"
            # Same session: each put is in the node's channel when it returns.
            for cmd in queued:
                publisher.put(cmd.encode())
            controller.gate.set()
            last = queued[-1].seq
            wait_for(lambda: last in controller.cycled_on, f"a cycle on command {last}")
        finally:
            controller.gate.set()
            publisher.undeclare()
            node.shutdown()
    finally:
        session.close()
    return controller


@pytest.mark.integration
def test_commands_queued_behind_a_cycle_are_all_vetted_and_driven_on_as_one():
    queued = [command(seq, x=0.5) for seq in range(2, 51)]
    controller = drive_queued(queued)
    assert controller.counters.accepted == 50  # every one vetted
    assert controller.link_totals == (50, 0)  # ... and counted: no seq missing
    # One cycle on the newest, where one per command ran 49 cycles on older sticks first.
    assert controller.cycled_on == [1, 50]


@pytest.mark.integration
def test_a_deadman_release_in_a_queue_gets_its_own_cycle():
    held = [command(seq, x=0.5) for seq in range(2, 11)]
    released = [command(11, deadman=False)]
    again = [command(seq, x=0.5) for seq in range(12, 21)]
    controller = drive_queued(held + released + again)
    assert controller.counters.accepted == 20
    # The state machine sees held, released, held again (DESIGN 8: a release holds, and the
    # stick must be centred before driving again), as it did with a cycle per command.
    assert controller.cycled_on == [1, 10, 11, 20]


def test_control_bits_separate_what_the_state_machine_acts_on():
    tol = 0.05
    base = control_bits(command(1, x=0.5), tol)
    assert control_bits(command(2, x=0.9), tol) == base  # another stick value: superseded
    for changed in (
        command(2, deadman=False, x=0.5),
        command(2, estop=True, x=0.5),
        command(2, x=0.01),  # centred
    ):
        assert control_bits(changed, tol) != base
    assert cycle_before(base, control_bits(command(2, deadman=False), tol))
    assert not cycle_before(base, control_bits(command(2, x=0.7), tol))
    assert not cycle_before(None, base)  # nothing pending: no cycle owed
    assert not cycle_before(base, None)  # an undecodable payload changes nothing
    assert decoded_control_bits(decode_command(b"\x00not msgpack"), tol) is None
    assert decoded_control_bits(decode_command(command(3, x=0.5).encode()), tol) == base
    assert isinstance(base, ControlBits)
