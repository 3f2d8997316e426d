"""The test run's own budget (``tests/suite_budget.py``, issue 31): past it the run stops, names
the tests then running and prints its summary."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.inner_pytest import run_suite
from tests.suite_budget import BUDGET_ENV, SuiteBudget


class CrashReport:
    """What pytest-xdist reports for the test of a crashed worker (``when`` is ``???``)."""

    def __init__(self, nodeid: str) -> None:
        self.nodeid = nodeid
        self.when = "???"


def test_the_report_names_the_tests_started_and_not_finished() -> None:
    budget = SuiteBudget(60.0)
    try:
        budget.pytest_runtest_logstart("t.py::a")
        budget.pytest_runtest_logstart("t.py::b")
        budget.pytest_runtest_logstart("t.py::c")
        budget.pytest_runtest_logfinish("t.py::a")
        budget.pytest_runtest_logreport(CrashReport("t.py::c"))  # type: ignore[arg-type]
        budget.pytest_xdist_node_collection_finished(["t.py::a", "t.py::b", "t.py::c", "t.py::d"])
        text = budget.report(now=float("inf"))
    finally:
        budget.pytest_unconfigure()
    assert "budget of 60 s" in text and "after 1 of 4 tests" in text
    running = [line.strip() for line in text.splitlines()[1:]]
    assert len(running) == 1 and running[0].startswith("t.py::b (for ")


def test_an_idle_run_is_called_stuck() -> None:
    budget = SuiteBudget(60.0)
    try:
        budget.pytest_xdist_node_collection_finished(["t.py::a"])
        assert "every worker idle" in budget.report(now=0.0)
    finally:
        budget.pytest_unconfigure()


@pytest.mark.slow
def test_a_hanging_test_ends_the_run_with_its_name_and_the_summary(tmp_path: Path) -> None:
    hangs = """
            import os, subprocess, sys, time

            def test_fails():
                assert 1 == 2

            def test_hangs():
                # A server in its own session, as the screenshot test's viewer and browser are.
                server = subprocess.Popen(
                    [sys.executable, "-c", "import time; time.sleep(600)"],
                    start_new_session=True,
                )
                with open(os.environ["SERVER_PID_FILE"], "w") as f:
                    f.write(str(server.pid))
                time.sleep(600)

            def test_never_reached():
                pass
            """
    env = {BUDGET_ENV: "10", "SERVER_PID_FILE": str(tmp_path / "server.pid")}
    proc = run_suite(tmp_path, "suite_budget", {"test_hangs.py": hangs}, ["-n", "0"], env)
    out = proc.stdout
    assert proc.returncode == 2, out + proc.stderr  # interrupted
    assert "used up its budget of 10 s" in out and "after 1 of 3 tests" in out, out
    assert "test_hangs.py::test_hangs (for " in out, out
    assert "FAILED test_hangs.py::test_fails" in out, out  # the summary of what failed so far
    server = int((tmp_path / "server.pid").read_text())
    assert _state(server) in ("gone", "Z"), "the hanging test's server outlived the run"


def _state(pid: int) -> str:
    """A process's state letter from /proc ("gone" when there is none)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()[0]
    except OSError:
        return "gone"
