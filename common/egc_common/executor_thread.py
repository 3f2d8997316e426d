"""The thread that spins a ROS 2 executor, and the proof that it is out before the node goes.

Destroying an rclpy node while another thread is inside its executor crashed the process
("Fatal Python error: Segmentation fault" in ``destroy_node``, a CI run under load, issue 31).
Shutting the executor down with a timeout, joining the thread with a timeout and then destroying
the node anyway is not enough: under load the join times out with the thread still inside.

Here the thread does nothing but ``executor.spin_once(timeout_sec=WAIT_S)`` until its stop flag
is set, so it leaves within one wait plus the callback in progress. ``stop`` returns True only
once the thread has ended; only then may the owner shut the executor down and destroy the node
(from its own thread). False means a callback has not returned: the node must be left alone
(and to the process's exit), never destroyed under the thread.

Duck-typed (anything with ``spin_once(timeout_sec=...)``): ``egc_common`` imports no rclpy
(DESIGN 11: only ``egc_robot.ros2_driver`` and ``egc_sim.ros2_base`` do), and both of them, the
tests' fake base and the benchmarks share this one pattern.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Protocol

# How long one ``spin_once`` waits for work: the longest the thread takes to see its stop flag
# when idle. Scans and odometry wake it far more often on a working robot.
WAIT_S = 0.1


class SpinsOnce(Protocol):
    """What this needs of an rclpy executor."""

    def spin_once(self, timeout_sec: float | None = None) -> None: ...


class ExecutorThread:
    """A daemon thread running ``executor.spin_once`` until ``stop`` (see the module doc)."""

    def __init__(
        self,
        executor: SpinsOnce,
        on_error: Callable[[Exception], None],
        name: str = "ros2-executor",
        wait_s: float = WAIT_S,
    ) -> None:
        """``on_error``: called (in the thread) with an exception out of ``spin_once``, after
        which the thread ends; ``stop`` still reports it out."""
        self._executor = executor
        self._on_error = on_error
        self._wait_s = wait_s
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)

    def start(self) -> None:
        self._thread.start()

    def _run(self) -> None:
        try:
            while not self._stop.is_set():
                self._executor.spin_once(timeout_sec=self._wait_s)
        except Exception as exc:
            self._on_error(exc)

    def stop(self, patience_s: float | None) -> bool:
        """Ask the thread to leave and wait for it (``None``: as long as it takes). True when
        it is out (or never started): the executor and its nodes are the caller's alone."""
        self._stop.set()
        if self._thread.ident is None:
            return True
        if self._thread is not threading.current_thread():
            self._thread.join(patience_s)
        return not self._thread.is_alive()
