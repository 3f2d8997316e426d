"""A crashed pytest-xdist worker ends the run soon, naming its test (``tests/worker_crash.py``,
issue 31): a real two-worker run of a small suite in which one test segfaults."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.inner_pytest import run_suite

WAITING = 20
CRASHES = f"""
    import ctypes, os, time
    import pytest

    def log(what):
        with open(os.environ["STARTS_FILE"], "a") as f:
            f.write(f"{{what}} {{time.monotonic()}}\\n")

    def test_segfaults():
        time.sleep(1.0)
        log("crash")
        ctypes.string_at(0)  # a read of address 0: SIGSEGV, as rclpy's teardown did

    @pytest.mark.parametrize("n", range({WAITING}))
    def test_waits(n):
        log("start")
        time.sleep(2.0)
    """


@pytest.mark.slow
def test_a_segfaulting_test_stops_every_worker_and_is_named(tmp_path: Path) -> None:
    starts = tmp_path / "starts.txt"
    proc = run_suite(
        tmp_path,
        "worker_crash",
        {"test_crash.py": CRASHES},
        ["-n", "2", "--max-worker-restart=0", "-p", "no:faulthandler"],
        {"STARTS_FILE": str(starts)},
    )
    out = proc.stdout
    assert proc.returncode == 2, out + proc.stderr  # interrupted, not merely failed
    assert re.search(r"worker 'gw\d' crashed while running 'test_crash.py::test_segfaults'", out)
    assert re.search(r"Interrupted: worker gw\d crashed", out), out
    events = [line.split() for line in starts.read_text().splitlines()]
    crash = next(float(t) for what, t in events if what == "crash")
    after = [float(t) - crash for what, t in events if what == "start" and float(t) > crash]
    # Without the stop the other worker went on through its share of the 2 s tests (8 of them
    # began after the crash); with it, at most one that began while the news travelled.
    assert len(after) <= 1, (after, out)
