"""Starting a local viewer (``viewer_target.launch_viewer``) and the spawn target's fallback.

rr.spawn waited ~6 s for a viewer that had exited in 20 ms (no X server), then its gRPC sink
waited 5 s more and the process's exit another 5 s: an operator with ``DISPLAY`` set and no
usable display took 16.4 s for a 2 s run (3.6 s with ``--no-view``). The viewer here is the
real one where it can show that (it exits at once without an X server); stand-ins where it
cannot (one that listens, one that never does).
"""

from __future__ import annotations

import socket
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from egc_common.transport import free_tcp_port
from egc_operator import viewer_target
from egc_operator.viewer_target import launch_viewer

from tests.view.test_viewer_target import RERUN_BINARY


@pytest.fixture
def no_display(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("DISPLAY", ":77")  # no X server there
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)


@pytest.fixture
def spawned() -> Iterator[None]:
    """Stops what a test's launch left running (a detached viewer outlives its operator)."""
    before = len(viewer_target._SPAWNED)
    yield
    for process in viewer_target._SPAWNED[before:]:
        process.kill()
        process.wait()
    del viewer_target._SPAWNED[before:]


def test_a_viewer_that_cannot_open_a_window_is_reported_at_once(no_display: None) -> None:
    t0 = time.monotonic()
    why = launch_viewer(free_tcp_port(), executable=RERUN_BINARY)
    took = time.monotonic() - t0
    assert why is not None and why.startswith("it exited with code"), why
    assert took < viewer_target.SPAWN_WAIT_S / 2, took  # not the wait for a slow viewer


def test_a_viewer_that_listens_is_kept_running(tmp_path: Path, spawned: None) -> None:
    port = free_tcp_port()
    stand_in = tmp_path / "viewer"
    # listens on the --port it is given, after a while, as a viewer opening its window does
    stand_in.write_text(
        f"#!{sys.executable}\n"
        "import socket, sys, time\n"
        "time.sleep(0.5)\n"
        "s = socket.create_server(('127.0.0.1', int(sys.argv[sys.argv.index('--port') + 1])))\n"
        "time.sleep(60)\n"
    )
    stand_in.chmod(0o755)
    assert launch_viewer(port, executable=str(stand_in)) is None
    assert viewer_target._SPAWNED and viewer_target._SPAWNED[-1].poll() is None
    with socket.create_connection(("127.0.0.1", port), timeout=1.0):
        pass


def test_a_viewer_that_never_listens_is_stopped(tmp_path: Path, spawned: None) -> None:
    stand_in = tmp_path / "viewer"
    stand_in.write_text(f"#!{sys.executable}\nimport time\ntime.sleep(60)\n")
    stand_in.chmod(0o755)
    before = len(viewer_target._SPAWNED)
    why = launch_viewer(free_tcp_port(), wait_s=0.5, executable=str(stand_in))
    assert why is not None and "did not listen" in why, why
    assert len(viewer_target._SPAWNED) == before  # killed and reaped, not kept


def test_a_viewer_already_listening_is_used(tmp_path: Path) -> None:
    with socket.create_server(("127.0.0.1", 0)) as server:
        port = server.getsockname()[1]
        missing = str(tmp_path / "no-such-viewer")
        assert launch_viewer(port, executable=missing) is None  # nothing started


def test_no_executable_is_a_reason(tmp_path: Path) -> None:
    why = launch_viewer(free_tcp_port(), executable=str(tmp_path / "no-such-viewer"))
    assert why is not None and "no-such-viewer" in why, why
