"""One command source shared by the operator nodes of a fleet session (DESIGN 15).

An operator driving a fleet runs one ``OperatorNode`` per driven robot, one after the other
(``egc_operator.fleet_session``); the stick, the buttons and a recorded script are one source
for all of them. ``FleetSource`` wraps that source:

- **One time line.** A node asks for the sample at its own time since it saw its robot; the
  fleet source answers with the sample at the time since the *first* robot was driven, so a
  script runs on across switches (the switch and the gap before the next robot takes commands
  are time the script's operator spends too) and a gamepad is drained by one caller at a time.
- **The switch buttons.** The press edge of ``robot_next`` / ``robot_prev`` (a gamepad's
  button pair, a joystick file's columns) calls ``on_switch(step, press_ns)``, with the press
  time on the session's clock (a file's row time, exact; a gamepad's, when it was sampled);
  it answers whether the session switches (there may be no other robot), and when it does the
  sample of the press is already released.
- **Release and gate per node** (``NodeSource``, what one node is given). A node's source is
  released when the session switches away from its robot (``release``): from then on it reads
  a centred stick with the deadman released, so the old robot's next command lets go (DESIGN 8
  explicit release) even before its node has stopped. A new node's source holds back (its node
  sends nothing: ``holding_back``) until its ``gate`` opens (its clock sync has converged: the first command the new robot takes is
  stamped on its clock, DESIGN 7), so the robot sees a new operator session start from the
  stick as it is then, and needs it centred (DESIGN 8).

Thread-safe: nodes sample from their own threads, the session releases from its own.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import replace

from egc_common.joystick_file import RELEASED, JoystickSample

from egc_operator.command_source import CommandSource

NS_PER_S = 1_000_000_000


class FleetSource:
    def __init__(
        self,
        inner: CommandSource,
        clock: Callable[[], int],
        on_switch: Callable[[int, int], bool] | None = None,
    ) -> None:
        self._inner = inner
        self._clock = clock
        self._on_switch = on_switch
        self._lock = threading.Lock()
        self._origin_ns: int | None = None  # the session's time 0: the first sample taken
        self._held = {"next": False, "prev": False}

    def set_on_switch(self, on_switch: Callable[[int, int], bool]) -> None:
        self._on_switch = on_switch

    def node_source(self, gate: Callable[[], bool] | None = None) -> NodeSource:
        """The source for one node; ``gate()`` false keeps it released (see the module doc)."""
        return NodeSource(self, gate)

    @property
    def finished(self) -> bool:
        return self._inner.finished

    @property
    def started(self) -> bool:
        with self._lock:
            return self._origin_ns is not None

    def _sample(self, node: NodeSource) -> JoystickSample:
        switch: tuple[int, int] | None = None
        with self._lock:
            if node.released:
                return RELEASED
            now = self._clock()
            if self._origin_ns is None:
                self._origin_ns = now
            sample = self._inner.sample((now - self._origin_ns) / NS_PER_S)
            for name, held, step in (
                ("next", sample.robot_next, +1),
                ("prev", sample.robot_prev, -1),
            ):
                if held and not self._held[name] and switch is None:
                    # the press on the session's clock: a file's row time, else now
                    press_ns = min(now, self._origin_ns + round(sample.t_s * NS_PER_S))
                    switch = (step, press_ns)
                self._held[name] = held
        # The session decides (outside the lock: it may release this node from its thread).
        if switch is not None and self._on_switch is not None and self._on_switch(*switch):
            node.released = True  # this very sample already lets go of the robot
            return replace(RELEASED, mode=sample.mode, filter=sample.filter)
        return sample

    def close(self) -> None:
        self._inner.close()


class NodeSource:
    """What one ``OperatorNode`` samples (a ``CommandSource``); closing it closes nothing: the
    session closes the fleet's source once."""

    def __init__(self, fleet: FleetSource, gate: Callable[[], bool] | None) -> None:
        self._fleet = fleet
        self._gate = gate
        self.released = False  # set under the fleet source's lock, or by ``release``

    def release(self) -> None:
        self.released = True

    def holding_back(self) -> bool:
        """True while the gate is closed: the robot would refuse this node's released commands
        as not in control (the demo over a 400 ms round trip had 21 of them), so none is sent."""
        return self._gate is not None and not self.released and not self._gate()

    def sample(self, t_s: float) -> JoystickSample:
        if self.holding_back():
            return RELEASED
        return self._fleet._sample(self)

    @property
    def finished(self) -> bool:
        return self._fleet.finished

    def close(self) -> None:
        pass
