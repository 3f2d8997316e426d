"""A viewer that is not there, and view files that cannot be written (outside check).

- ``operator --connect rerun+http://127.0.0.1:<closed port>/proxy`` said the view was streamed,
  drove the whole run, then ended with ``RuntimeError: gRPC has been unable to connect for 6s``
  and exit 1; so did a spawned viewer that could not open a window (no X server).
- Then it waited 5 s before its first command (Rerun 0.41's ``connect_grpc`` waits that long for a
  viewer that is not there) and 6 s at close, and a viewer started later got only the layout.
- ``--save /proc/x.rrd``, ``--save <a file>/x.rrd``, ``demo --save``, ``episode --record`` to such
  paths and ``--serve-web`` on a port in use ended in tracebacks; ``--save /nonexistent/x.rrd``
  silently created the directory.
"""

from __future__ import annotations

import argparse
import os
import signal
import socket
import subprocess
import sys
import threading
import warnings
from pathlib import Path
from typing import Any

import pytest
from egc_common.child_process import die_with_parent
from egc_common.errors import UsageError
from egc_common.transport import free_tcp_port
from egc_operator.view import open_view
from egc_operator.viewer_target import add_view_arguments
from rerun.chunk import RrdReader

from tests.view.conftest import telemetry
from tests.view.test_viewer_target import RERUN_BINARY, _listening, _scan_rows, _wait_for

ROOT = Path(__file__).resolve().parents[2]


def _args(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    add_view_arguments(parser)
    return parser.parse_args(list(argv))


@pytest.fixture
def connects(monkeypatch: pytest.MonkeyPatch) -> list[threading.Thread]:
    """The threads that called Rerun's ``connect_grpc`` (which then goes on as usual)."""
    import rerun as rr

    real = rr.RecordingStream.connect_grpc
    callers: list[threading.Thread] = []

    def spy(self: rr.RecordingStream, *args: Any, **kwargs: Any) -> None:
        callers.append(threading.current_thread())
        real(self, *args, **kwargs)

    monkeypatch.setattr(rr.RecordingStream, "connect_grpc", spy)
    return callers


def test_a_viewer_that_is_not_there_is_said_once_and_closing_does_not_raise(
    capsys: pytest.CaptureFixture[str], connects: list[threading.Thread]
) -> None:
    url = f"rerun+http://127.0.0.1:{free_tcp_port()}/proxy"
    view = open_view(_args("--connect", url), "sim")
    for k in range(20):
        view.on_telemetry(telemetry(k))
    view.close()  # raised RuntimeError (gRPC unable to connect)
    err = capsys.readouterr().err
    assert err.count(f"warning: no viewer answers at {url}") == 1
    assert "Traceback" not in err
    # No gRPC connection was started to wait on (5 s at open, 5 s when dropped): not at the
    # start, not at close, not at exit.
    assert connects == []


def test_a_viewer_started_later_gets_the_whole_view_and_start_up_did_not_wait_for_it(
    tmp_path: Path, connects: list[threading.Thread]
) -> None:
    """Opening the view does not connect to a viewer that is not there (Rerun's connect_grpc
    waited 5 s for it, before the operator's first command); the view watcher connects once it
    answers, and the viewer gets the layout and every row, those logged before it came too."""
    received = tmp_path / "received.rrd"
    with socket.socket() as held:  # no one else takes the port while the viewer is missing
        held.bind(("127.0.0.1", 0))
        port = held.getsockname()[1]
        view = open_view(_args("--connect", f"rerun+http://127.0.0.1:{port}/proxy"), "sim")
        assert connects == []  # the opening thread did not wait on a connection
        for k in range(5):
            view.on_telemetry(telemetry(k))
    server = subprocess.Popen(
        [RERUN_BINARY, "--port", str(port), "--save", str(received)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
        preexec_fn=die_with_parent,
    )
    try:
        _wait_for(lambda: _listening(port))
        _wait_for(lambda: _scan_rows(received) == 5)  # before the view is closed
        for k in range(5, 10):
            view.on_telemetry(telemetry(k))
        view.close()
        _wait_for(lambda: _scan_rows(received) == 10)
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message="RRD file has no footer")
            assert len(RrdReader(received).blueprints()) == 1
    finally:
        os.killpg(server.pid, signal.SIGTERM)
        server.wait(timeout=10)
    assert [thread.name for thread in connects] == ["viewer-watch"]


@pytest.mark.parametrize("kind", ["proc", "under_a_file", "missing_dir", "a_directory"])
def test_an_unwritable_save_path_is_a_usage_error(tmp_path: Path, kind: str) -> None:
    a_file = tmp_path / "a-file"
    a_file.write_text("x")
    path = {
        "proc": Path("/proc/egc-x.rrd"),
        "under_a_file": a_file / "x.rrd",
        "missing_dir": tmp_path / "missing" / "x.rrd",
        "a_directory": tmp_path / "dir.rrd",
    }[kind]
    if kind == "a_directory":
        path.mkdir()
    with pytest.raises(UsageError, match=r"^--save "):
        open_view(_args("--save", str(path)), "sim")
    assert not (tmp_path / "missing").exists()  # no directory made for it


def test_a_web_port_in_use_is_a_usage_error() -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        with pytest.raises(UsageError, match=f"port {port} .* already in use"):
            open_view(_args("--serve-web", str(port)), "sim")


def _cli(*argv: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "egc_app.cli", *argv],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, **(env or {})},
    )


@pytest.mark.parametrize(
    "argv",
    [
        ["operator", "--script", "demo", "--duration", "1", "--save", "/proc/egc-x.rrd"],
        ["demo", "--duration", "1", "--save", "/proc/egc-x.rrd"],
        ["episode", "--map", "hallway", "--record", "/proc/egc-x.rrd"],
    ],
    ids=["operator", "demo", "episode"],
)
def test_the_commands_refuse_an_unwritable_view_file_in_one_line(argv: list[str]) -> None:
    done = _cli(*argv)
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "/proc/egc-x.rrd" in lines[0], done.stderr


def test_the_operator_drives_on_and_exits_0_without_its_viewer(tmp_path: Path) -> None:
    url = f"rerun+http://127.0.0.1:{free_tcp_port()}/proxy"
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    done = _cli(
        "operator", "--script", "demo", "--duration", "2", "--no-status", "--connect", url,
        "--zenoh-connect", endpoint,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr
    assert done.stderr.count("warning: no viewer answers at") == 1


def test_a_spawned_viewer_that_did_not_start_names_a_file_that_is_there(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Outside check (DISPLAY=:77, no --save): 'the spawned viewer did not start (...);
    operator view saved to .../egc-operator-....rrd', and the file was not found: the hint to
    open it named the file relative to the operator's working directory."""
    from egc_operator import viewer_target

    monkeypatch.setenv("DISPLAY", ":77")  # no X server there: the real viewer exits at once
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr(viewer_target, "DEFAULT_VIEWER_PORT", free_tcp_port())
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    monkeypatch.chdir(run_dir)
    view = open_view(_args(), "sim")
    for k in range(5):
        view.on_telemetry(telemetry(k))
    view.close()
    err = capsys.readouterr().err
    assert "the spawned viewer did not start (it exited with code" in err, err
    # that display took no viewer: the hint gives the web viewer, not "open it with: rerun"
    assert "--serve-web" in err and "open it with:" not in err, err
    named = [word.strip("()") for word in err.split() if word.strip("()").endswith(".rrd")]
    assert named, err
    monkeypatch.chdir(tmp_path)  # read from elsewhere, as whoever follows the hint does
    for name in named:
        assert Path(name).is_file() and Path(name).stat().st_size > 0, (name, err)
