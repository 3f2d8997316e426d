"""The whole test run within a budget: past it, the run stops and names the tests then running.

pytest-timeout bounds each test (pyproject); nothing bounded the run: a CI run hung at 97% with
both pytest-xdist workers idle until it was stopped by hand 8 minutes later, and the summary of
what had failed never came (issue 31). With ``EGC_SUITE_BUDGET_S`` set (the Makefile's ``pytest``
target sets it), the process that reports (the xdist controller, which hears every worker's
logstart and logfinish, or the only process with ``-n 0``) keeps the tests that have started and
not finished. When the budget is spent it prints them, with how long each has been running, and
interrupts itself (SIGINT): pytest then prints its summary of what failed so far and exits 2.
Whatever the interrupted tests had started (servers in their own sessions, a browser) would
outlive the run; the processes below this one when the budget ran out are killed at its end.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
import time

import pytest

BUDGET_ENV = "EGC_SUITE_BUDGET_S"


class SuiteBudget:
    """A pytest plugin: the timer, and the tests started but not finished."""

    def __init__(self, budget_s: float) -> None:
        self._budget_s = budget_s
        self._lock = threading.Lock()
        self._running: dict[str, float] = {}
        self._finished = 0
        self._collected: int | None = None
        # The real stdout, whatever pytest's capturing does to fd 1 when the timer fires.
        self._out = os.dup(1)
        self._timer = threading.Timer(budget_s, self._expire)
        self._timer.daemon = True
        self._left_behind: list[tuple[int, str]] = []

    def pytest_sessionstart(self) -> None:
        self._timer.start()

    def pytest_unconfigure(self) -> None:
        self._timer.cancel()
        os.close(self._out)
        for pid, started in self._left_behind:
            if _start_time(pid) == started:  # the same process, not a reused pid
                with contextlib.suppress(OSError):
                    os.kill(pid, signal.SIGKILL)

    def pytest_collection_finish(self, session: pytest.Session) -> None:
        if session.items:  # -n 0; the xdist controller collects nothing itself
            self._collected = len(session.items)

    @pytest.hookimpl(optionalhook=True)
    def pytest_xdist_node_collection_finished(self, ids: list[str]) -> None:
        self._collected = len(ids)

    def pytest_runtest_logstart(self, nodeid: str) -> None:
        with self._lock:
            self._running[nodeid] = time.monotonic()

    def pytest_runtest_logfinish(self, nodeid: str) -> None:
        with self._lock:
            if self._running.pop(nodeid, None) is not None:
                self._finished += 1

    def pytest_runtest_logreport(self, report: pytest.TestReport) -> None:
        if report.when not in ("setup", "call", "teardown"):  # xdist's report of a crashed worker
            with self._lock:
                self._running.pop(report.nodeid, None)

    def report(self, now: float) -> str:
        """What the run was doing when the budget ran out."""
        with self._lock:
            running = sorted(self._running.items(), key=lambda item: item[1])
            finished = self._finished
        of = "" if self._collected is None else f" of {self._collected}"
        lines = [
            f"the test run used up its budget of {self._budget_s:g} s ({BUDGET_ENV}) after "
            f"{finished}{of} tests; running then:"
        ]
        lines += [f"    {nodeid} (for {now - start:.0f} s)" for nodeid, start in running]
        if not running and self._collected is None:
            lines.append("    none (the tests were still being collected)")
        elif not running:
            lines.append("    none (every worker idle: the run itself is stuck)")
        return "\n".join(lines)

    def _expire(self) -> None:
        text = self.report(time.monotonic())
        with contextlib.suppress(Exception):  # whatever capturing holds sys.stdout now
            sys.stdout.flush()
        os.write(self._out, f"\n{'!' * 30} {text}\n".encode())
        self._left_behind = [(pid, _start_time(pid)) for pid in descendants(os.getpid())]
        os.kill(os.getpid(), signal.SIGINT)


def _stat_fields(pid: int) -> list[str]:
    """/proc/PID/stat from the field after the command name on ([] if gone)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rpartition(")")[2].split()
    except OSError:
        return []


def _start_time(pid: int) -> str:
    fields = _stat_fields(pid)
    return fields[19] if len(fields) > 19 else ""


def descendants(root: int) -> list[int]:
    """Every process below ``root`` (Linux /proc; none elsewhere)."""
    children: dict[int, list[int]] = {}
    with contextlib.suppress(OSError):
        for name in os.listdir("/proc"):
            if name.isdigit() and (fields := _stat_fields(int(name))):
                children.setdefault(int(fields[1]), []).append(int(name))
    found, todo = [], [root]
    while todo:
        for child in children.get(todo.pop(), []):
            found.append(child)
            todo.append(child)
    return found


def configure(config: pytest.Config) -> None:
    """Register the budget in the reporting process when ``EGC_SUITE_BUDGET_S`` is set."""
    value = os.environ.get(BUDGET_ENV)
    if not value or hasattr(config, "workerinput"):  # unset, or an xdist worker
        return
    try:
        budget_s = float(value)
    except ValueError:
        raise pytest.UsageError(
            f"{BUDGET_ENV} must be a number of seconds, got {value!r}"
        ) from None
    if budget_s <= 0:
        raise pytest.UsageError(f"{BUDGET_ENV} must be > 0, got {value!r}")
    config.pluginmanager.register(SuiteBudget(budget_s), "egc-suite-budget")
