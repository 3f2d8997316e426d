"""StopFlag: a stop request that a signal handler can raise at any moment (egc_common.stop_flag)."""

from __future__ import annotations

import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

from egc_common.stop_flag import StopFlag

COMMON = Path(__file__).resolve().parents[2] / "common"

# The processes' main loop, reduced: wait for the stop with no timeout left (where
# threading.Event holds its condition's lock longest: its set() from the handler deadlocked in
# about every second stop) or with a short one (about 1 stop in 200).
_CHILD = textwrap.dedent(
    """
    import sys
    sys.path.insert(0, sys.argv[1])
    from egc_common.stop_flag import stop_on_signals
    stop = stop_on_signals()
    print("ready", flush=True)
    timeout = float(sys.argv[2])
    while not stop.wait(timeout):
        pass
    """
)


def test_wait_times_out_then_a_set_from_another_thread_wakes_every_waiter() -> None:
    stop = StopFlag()
    started = time.monotonic()
    assert stop.wait(0.05) is False
    assert time.monotonic() - started >= 0.05
    assert stop.wait(0) is False and not stop.is_set()
    woken: list[bool] = []
    waiters = [threading.Thread(target=lambda: woken.append(stop.wait(10))) for _ in range(3)]
    for w in waiters:
        w.start()
    time.sleep(0.05)
    setter = time.monotonic()
    stop.set()
    for w in waiters:
        w.join(5)
    assert woken == [True, True, True]
    assert time.monotonic() - setter < 1
    stop.set()  # a second set changes nothing
    assert stop.is_set() and stop.wait(0) and stop.wait(None)


def test_sigterm_at_any_moment_of_the_wait_loop_ends_it() -> None:
    """30 processes stopped at varied moments: each one ends. With threading.Event in place of
    the flag, about half of the first 20 hung in the handler's set()."""
    hung = []
    for i in range(30):
        timeout = "0" if i < 20 else "1e-4"
        proc = subprocess.Popen(
            [sys.executable, "-c", _CHILD, str(COMMON), timeout], stdout=subprocess.PIPE, text=True
        )
        assert proc.stdout is not None and proc.stdout.readline() == "ready\n"
        time.sleep(0.001 * (i % 7))
        proc.send_signal(signal.SIGTERM)
        try:
            assert proc.wait(10) == 0
        except subprocess.TimeoutExpired:
            hung.append(i)
            proc.kill()
            proc.wait()
    assert hung == []
