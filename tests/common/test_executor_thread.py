"""``egc_common.executor_thread``: ``stop`` says True only once the thread is out (issue 31).

A stand-in executor (the class is duck-typed; tests/ros2 runs it with rclpy's) whose
``spin_once`` can be held inside, as a callback that has not returned holds rclpy's.
"""

from __future__ import annotations

import threading

from egc_common.executor_thread import WAIT_S, ExecutorThread

DEADLINE_S = 30.0


class HeldExecutor:
    def __init__(self) -> None:
        self.timeouts: list[float | None] = []
        self.inside = threading.Event()
        self.release = threading.Event()
        self.release.set()
        self.error: Exception | None = None

    def spin_once(self, timeout_sec: float | None = None) -> None:
        self.timeouts.append(timeout_sec)
        self.inside.set()
        assert self.release.wait(DEADLINE_S)
        if self.error is not None:
            raise self.error


def test_stop_returns_once_the_thread_is_out() -> None:
    executor = HeldExecutor()
    errors: list[Exception] = []
    spinner = ExecutorThread(executor, errors.append)
    spinner.start()
    assert executor.inside.wait(DEADLINE_S)
    assert spinner.stop(DEADLINE_S)
    assert executor.timeouts and set(executor.timeouts) == {WAIT_S}
    assert errors == []


def test_a_thread_held_inside_is_reported_not_out() -> None:
    executor = HeldExecutor()
    executor.release.clear()
    spinner = ExecutorThread(executor, lambda exc: None)
    spinner.start()
    assert executor.inside.wait(DEADLINE_S)
    assert not spinner.stop(0.05)  # inside a callback that has not returned
    assert not spinner.stop(0.0)
    executor.release.set()
    assert spinner.stop(DEADLINE_S)


def test_an_error_out_of_spin_once_ends_the_thread_and_is_reported() -> None:
    executor = HeldExecutor()
    executor.error = RuntimeError("context shut down")
    errors: list[Exception] = []
    spinner = ExecutorThread(executor, errors.append)
    spinner.start()
    assert spinner.stop(DEADLINE_S)
    assert [str(e) for e in errors] == ["context shut down"]
    assert len(executor.timeouts) == 1


def test_stop_before_start_and_from_inside() -> None:
    assert ExecutorThread(HeldExecutor(), lambda exc: None).stop(0.0)
    # A callback that stops its own executor's thread cannot wait for itself: not out.
    verdicts: list[bool] = []

    class StopsItself(HeldExecutor):
        def spin_once(self, timeout_sec: float | None = None) -> None:
            verdicts.append(spinner.stop(DEADLINE_S))

    spinner = ExecutorThread(StopsItself(), lambda exc: None)
    spinner.start()
    assert spinner.stop(DEADLINE_S)
    assert verdicts == [False]
