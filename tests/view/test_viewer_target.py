"""Choosing where the operator view goes (issue 5, viewer targets)."""

from __future__ import annotations

import argparse
import os
import signal
import socket
import subprocess
import time
import urllib.request
import warnings
from collections.abc import Callable
from pathlib import Path

import pytest
import rerun_cli
from egc_common.child_process import die_with_parent
from egc_common.errors import UsageError
from egc_common.transport import free_tcp_port
from egc_operator import view_blueprint as paths
from egc_operator.view import open_view
from egc_operator.viewer_target import ViewerTarget, add_view_arguments, choose_target

from tests.view.conftest import telemetry
from tests.view.rrd import read_recording

RERUN_BINARY = str(Path(rerun_cli.__file__).with_name("rerun"))

HEADLESS: dict[str, str] = {}


def _choose(env: dict[str, str] | None = None, **options: object) -> ViewerTarget:
    kwargs: dict[str, object] = {"save": None, "connect": None, "serve_web": None, "no_view": False}
    kwargs.update(options)
    return choose_target(
        env=HEADLESS if env is None else env,
        robot_id="sim",
        stamp="20250101-120000",
        **kwargs,  # type: ignore[arg-type]
    )


def test_each_option_picks_its_target() -> None:
    assert _choose(save="out.rrd") == ViewerTarget("save", path=Path("out.rrd"))
    url = "rerun+http://10.0.0.5:9876/proxy"
    assert _choose(connect=url) == ViewerTarget("connect", url=url)
    target = _choose(serve_web=9090)
    assert (target.kind, target.web_port, target.grpc_port) == ("serve_web", 9090, 9091)
    assert _choose(no_view=True).kind == "none"


def test_display_spawns_a_viewer_and_headless_saves_to_a_named_file() -> None:
    assert _choose(env={"DISPLAY": ":0"}).kind == "spawn"
    assert _choose(env={"WAYLAND_DISPLAY": "wayland-0"}).kind == "spawn"
    headless = _choose(env={"DISPLAY": ""})
    assert headless == ViewerTarget(
        "save", path=Path("egc-operator-sim-20250101-120000.rrd"), defaulted=True
    )


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"save": "a.rrd", "connect": "rerun+http://h:1/proxy"}, "--save and --connect"),
        ({"serve_web": 9090, "no_view": True}, "--serve-web and --no-view"),
        ({"save": "view.txt"}, ".rrd"),
        ({"connect": "http://h:9876"}, "rerun+http"),
        ({"serve_web": 0}, "1..65534"),
        ({"serve_web": 65535}, "1..65534"),
    ],
)
def test_bad_options_are_a_usage_error(options: dict[str, object], message: str) -> None:
    with pytest.raises(UsageError, match=message.replace(".", r"\.").replace("+", r"\+")):
        _choose(**options)


def _args(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    add_view_arguments(parser)
    return parser.parse_args(list(argv))


def test_arguments_parse() -> None:
    args = _args("--serve-web", "9090")
    assert (args.serve_web, args.connect, args.save, args.no_view) == (9090, None, None, False)
    assert _args("--no-view").no_view
    with pytest.raises(SystemExit):
        _args("--serve-web", "http")


def test_open_view_saves_and_says_where(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "op.rrd"
    view = open_view(_args("--save", str(out)), "sim")
    view.on_telemetry(telemetry(0))
    view.close()
    assert str(out.resolve()) in capsys.readouterr().err
    assert len(read_recording(out)["/" + paths.SCAN]) == 1


def test_headless_default_saves_in_the_working_directory(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    view = open_view(_args(), "sim")
    view.close()
    saved = list(tmp_path.glob("egc-operator-sim-*.rrd"))
    assert len(saved) == 1
    err = capsys.readouterr().err
    assert "no display" in err and str(saved[0].resolve()) in err


def test_no_view(capsys: pytest.CaptureFixture[str]) -> None:
    view = open_view(_args("--no-view"), "sim")
    view.on_telemetry(telemetry(0))
    view.close()
    assert "disabled" in capsys.readouterr().err


def _wait_for(check: Callable[[], bool], timeout_s: float = 60.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not check():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.1)


def _answers(url: str) -> bool:
    try:
        with urllib.request.urlopen(url, timeout=2) as reply:
            return b"<html" in reply.read(4096).lower()
    except OSError:
        return False


def _listening(port: int) -> bool:
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=1):
            return True
    except OSError:
        return False


def _scan_rows(path: Path) -> int:
    """Rows of the scan entity in a file another process is still writing (-1: not yet)."""
    try:
        with warnings.catch_warnings():  # no footer (yet): the server has the file open
            warnings.filterwarnings("ignore", message="RRD file has no footer")
            entity = read_recording(path).get("/" + paths.SCAN)
    except (RuntimeError, ValueError):  # caught in the middle of a frame, or before the first
        return -1  # store was written ("No recording store found in RRD file")
    return -1 if entity is None else len(entity)


def _start_saving_server(received: Path, attempts: int = 3) -> tuple[subprocess.Popen[bytes], int]:
    """A headless ``rerun`` server on a free port, saving to ``received``.

    A free port can be taken by another test process between ``free_tcp_port`` and the server's
    bind (tests run in parallel); the server then exits, and whatever else listens there must
    not be mistaken for it. So: wait until the port listens *and* our server is still alive,
    else try a fresh port.
    """
    for _ in range(attempts):
        port = free_tcp_port()
        server = subprocess.Popen(
            [RERUN_BINARY, "--port", str(port), "--save", str(received)],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,
            preexec_fn=die_with_parent,  # nothing left behind if this worker is killed
        )
        _wait_for(lambda: _listening(port) or server.poll() is not None)  # noqa: B023
        time.sleep(0.3)  # a server that lost the bind race exits right after
        if server.poll() is None and _listening(port):
            return server, port
        server.wait(timeout=10)
    raise AssertionError(f"no rerun server came up in {attempts} attempts")


def test_connect_streams_to_a_running_viewer(tmp_path: Path) -> None:
    """A headless `rerun` server that saves what it receives stands in for the viewer."""
    received = tmp_path / "received.rrd"
    server, port = _start_saving_server(received)
    try:
        view = open_view(_args("--connect", f"rerun+http://127.0.0.1:{port}/proxy"), "sim")
        for i in range(5):
            view.on_telemetry(telemetry(i))
        view.close()
        _wait_for(lambda: _scan_rows(received) == 5)
    finally:
        os.killpg(server.pid, signal.SIGTERM)
        server.wait(timeout=10)


def test_serve_web_hosts_the_viewer_and_the_data(capsys: pytest.CaptureFixture[str]) -> None:
    web_port = free_tcp_port()
    view = open_view(_args("--serve-web", str(web_port)), "sim")
    try:
        view.on_telemetry(telemetry(0))
        _wait_for(lambda: _answers(f"http://127.0.0.1:{web_port}/"))
        with socket.create_connection(("127.0.0.1", web_port + 1), timeout=5):
            pass  # the gRPC server the page reads from
        err = capsys.readouterr().err
        assert f"http://127.0.0.1:{web_port}/?url=rerun%2Bhttp%3A%2F%2F" in err
        assert f"%3A{web_port + 1}%2Fproxy" in err
    finally:
        view.close()
