"""``egc-teleop episode --random-worlds N --jobs 2``: SIGTERM or SIGINT to the batch stops its
worker processes too (outside check: after SIGTERM the two workers, children of the fork
server, ran on at about 80 % CPU for over a minute)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = [pytest.mark.integration, pytest.mark.timeout(60)]


def _ppid_and_state(pid: int) -> tuple[int, str] | None:
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = text[text.rindex(")") + 2 :].split()
    return int(fields[1]), fields[0]


def descendants(pid: int) -> dict[int, int]:
    """Every live process below ``pid``: {pid: its parent}."""
    parents = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit() and (info := _ppid_and_state(int(entry))) and info[1] != "Z":
            parents[int(entry)] = info[0]
    found: dict[int, int] = {}
    frontier = [pid]
    while frontier:
        parent = frontier.pop()
        for child, ppid in parents.items():
            if ppid == parent and child not in found:
                found[child] = ppid
                frontier.append(child)
    return found


def alive(pid: int) -> bool:
    info = _ppid_and_state(pid)
    return info is not None and info[1] != "Z"


@pytest.mark.skipif(sys.platform != "linux", reason="reads /proc")
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_a_stopped_batch_stops_its_workers(tmp_path, sig):
    out = tmp_path / "runs.jsonl"
    # Long episodes (egc stalls the blind operator; no stall limit): the workers stay busy.
    proc = subprocess.Popen(
        [sys.executable, "-m", "egc_app.cli", "episode", "--random-worlds", "4", "--jobs", "2",
         "--profile", "jackal", "--filter", "egc", "--max-time", "3000", "--out", str(out)],
        stdout=subprocess.DEVNULL,
        stderr=(tmp_path / "stderr").open("w"),  # a pipe would stay open while a worker lives
    )  # fmt: skip
    below: dict[int, int] = {}
    try:
        deadline = time.monotonic() + 30.0
        while True:
            below = descendants(proc.pid)
            workers = [p for p, parent in below.items() if parent != proc.pid]
            if len(workers) >= 2:
                break
            assert proc.poll() is None and time.monotonic() < deadline, below
            time.sleep(0.1)
        time.sleep(1.0)  # into their first episodes
        below = descendants(proc.pid)
        proc.send_signal(sig)
        proc.wait(timeout=10)
        deadline = time.monotonic() + 5.0
        while (left := [p for p in below if alive(p)]) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not left, f"still running 5 s after {sig.name}: {left} of {below}"
        err = (tmp_path / "stderr").read_text()
        assert proc.returncode == 128 + sig, err
        assert "episodes written, the workers ended" in err
        assert "Traceback" not in err, err
    finally:
        proc.kill()
        proc.wait()
        for p in below:  # leave nothing behind, whatever the outcome
            if alive(p):
                os.kill(p, signal.SIGKILL)
