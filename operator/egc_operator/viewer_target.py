"""Where the operator view goes: a spawned viewer, the web viewer, a running viewer, or a file.

``choose_target`` is pure (arguments and environment in, a ``ViewerTarget`` out); ``attach``
connects a Rerun recording stream to it and returns one line saying where the view is.

Rules (issue 5): ``--save FILE.rrd`` -> file; ``--connect URL`` -> a running viewer (gRPC URL);
``--serve-web PORT`` -> the web viewer on PORT with the data on gRPC port PORT + 1; otherwise a
local viewer is spawned when a display exists (``DISPLAY`` or ``WAYLAND_DISPLAY``), and without
one the view is saved to ``egc-operator-<robot>-<time>.rrd`` in the working directory.

``check_target`` refuses, before anything starts, what cannot work: a ``--save`` file that cannot
be written (a missing directory is not created: it is most likely a typo), a ``--serve-web``
port already in use. A viewer that is not there (``--connect``, or a spawned viewer that could
not open a window) is not an error: driving does not depend on it, the view says so (see
``reachable`` and ``OperatorView``).
"""

from __future__ import annotations

import argparse
import os
import shlex
import shutil
import socket
import subprocess
import sys
import time
import urllib.parse
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

if TYPE_CHECKING:  # rerun (with pyarrow, ~60 MB) is loaded only when a view is attached
    import rerun as rr
    import rerun.blueprint as rrb

from egc_common.cli_args import check_writable
from egc_common.errors import UsageError

Kind = Literal["spawn", "serve_web", "connect", "save", "none"]
GRPC_SCHEMES = ("rerun://", "rerun+http://", "rerun+https://")
# What the --serve-web gRPC server keeps for viewers that connect late (oldest dropped first).
# The view is live: a viewer that joins needs the last minutes, not the session. The view logs
# about 8 MB a minute with the camera (compact 20 Hz telemetry, JPEG frames at a few per
# second), so this is some 4 minutes. Rerun's default, 1 GiB, grew a 40-minute soak's
# operator from 320 to 922 MB (issue 31) and would have grown it to 1.3 GB.
SERVE_MEMORY_LIMIT = "32MiB"


@dataclass(frozen=True, slots=True)
class ViewerTarget:
    kind: Kind
    path: Path | None = None  # save
    url: str | None = None  # connect
    web_port: int | None = None  # serve_web
    defaulted: bool = False  # save chosen because there is no display
    viewer_failed: bool = False  # save chosen because a spawned viewer did not start here

    @property
    def grpc_port(self) -> int | None:
        """The gRPC port the web viewer reads from (web port + 1)."""
        return None if self.web_port is None else self.web_port + 1


def has_display(env: Mapping[str, str]) -> bool:
    return bool(env.get("DISPLAY") or env.get("WAYLAND_DISPLAY"))


def default_save_path(robot_id: str, stamp: str) -> Path:
    """``egc-operator-<robot>-<stamp>.rrd`` in the working directory."""
    return Path(f"egc-operator-{robot_id}-{stamp}.rrd")


def choose_target(
    *,
    save: str | None,
    connect: str | None,
    serve_web: int | None,
    no_view: bool,
    env: Mapping[str, str],
    robot_id: str,
    stamp: str,
) -> ViewerTarget:
    """Pick the target from the CLI options; raises UsageError on a bad combination or URL."""
    chosen = [
        name
        for name, value in (
            ("--save", save),
            ("--connect", connect),
            ("--serve-web", serve_web),
            ("--no-view", no_view or None),
        )
        if value is not None
    ]
    if len(chosen) > 1:
        raise UsageError(f"choose one viewer target, not {' and '.join(chosen)}")
    if no_view:
        return ViewerTarget("none")
    if save is not None:
        if not save.endswith(".rrd"):
            raise UsageError(f"--save needs a .rrd file name, got {save!r}")
        return ViewerTarget("save", path=Path(save))
    if connect is not None:
        if not connect.startswith(GRPC_SCHEMES) or not connect.rstrip("/").endswith("/proxy"):
            raise UsageError(
                f"--connect needs a viewer URL like rerun+http://127.0.0.1:9876/proxy, got {connect!r}"
            )
        return ViewerTarget("connect", url=connect)
    if serve_web is not None:
        if not 1 <= serve_web <= 65534:
            raise UsageError(f"--serve-web PORT must be in 1..65534, got {serve_web}")
        return ViewerTarget("serve_web", web_port=serve_web)
    if has_display(env):
        return ViewerTarget("spawn")
    return ViewerTarget("save", path=default_save_path(robot_id, stamp), defaulted=True)


def port_free(port: int) -> bool:
    """Nothing listens on TCP ``port`` (a server of ours could bind it)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind(("0.0.0.0", port))
        except OSError:
            return False
    return True


def check_target(target: ViewerTarget) -> None:
    """Raise UsageError for a target that cannot work (see the module docstring)."""
    if target.kind == "save" and target.path is not None:
        check_writable(target.path, "--save")
    if target.kind == "serve_web" and target.web_port is not None:
        for port, what in ((target.web_port, "web viewer"), (target.grpc_port, "its data")):
            if port is not None and not port_free(port):
                raise UsageError(
                    f"--serve-web {target.web_port}: port {port} ({what}) is already in use"
                )


DEFAULT_VIEWER_PORT = 9876  # where a spawned viewer listens


def viewer_address(target: ViewerTarget) -> tuple[str, int] | None:
    """(host, port) of the viewer a connect or spawn target streams to; None for the others."""
    if target.kind == "spawn":
        return "127.0.0.1", DEFAULT_VIEWER_PORT
    if target.kind == "connect" and target.url is not None:
        parsed = urllib.parse.urlsplit(
            target.url.replace("rerun+", "", 1).replace("rerun", "http", 1)
        )
        try:
            port = parsed.port
        except ValueError:
            return None
        default = 443 if parsed.scheme == "https" else DEFAULT_VIEWER_PORT
        return parsed.hostname or "127.0.0.1", port or default
    return None


def reachable(address: tuple[str, int], timeout_s: float = 0.5) -> str | None:
    """None when something accepts a TCP connection at ``address``, else why not."""
    try:
        with socket.create_connection(address, timeout=timeout_s):
            return None
    except OSError as exc:
        return exc.strerror or str(exc) or type(exc).__name__


# A viewer that opens its window takes 1-3 s to listen; one that cannot (no X server) listens
# for some 30 ms, then exits. rr.spawn did not tell the two apart: it waited ~6 s for a viewer
# that had exited, then its gRPC sink waited 5 s more, and the process's exit another 5 s. A
# viewer still running ``SPAWN_SETTLE_S`` after it began to listen has its window.
SPAWN_WAIT_S = 10.0
SPAWN_SETTLE_S = 1.0
SPAWN_POLL_S = 0.05
_SPAWNED: list[subprocess.Popen[bytes]] = []  # detached viewers, kept until this process exits


def launch_viewer(
    port: int = DEFAULT_VIEWER_PORT, wait_s: float = SPAWN_WAIT_S, executable: str | None = None
) -> str | None:
    """Start a Rerun viewer listening on ``port`` (in a session of its own, so it outlives the
    operator, as rr.spawn's does) and wait until it accepts connections; None when it does
    and is still running ``SPAWN_SETTLE_S`` later (or a viewer already listens there), else
    why not: no executable, the viewer exited (its own message is on stderr), or it did not
    listen within ``wait_s`` (then it is stopped). ``executable``: the installed rerun-sdk's
    viewer unless given."""
    address = ("127.0.0.1", port)
    if reachable(address, timeout_s=0.2) is None:
        return None
    executable = executable or _rerun_executable()
    if executable is None:
        return "no rerun executable found"
    argv = [executable, "--port", str(port), "--memory-limit", "75%", "--expect-data-soon"]
    try:
        viewer = subprocess.Popen(
            argv,
            stdin=subprocess.DEVNULL,
            env={**os.environ, "RERUN_APP_ONLY": "true"},  # as rr.spawn: no analytics prompt
            start_new_session=True,
        )
    except OSError as exc:
        return f"{executable}: {exc.strerror or exc}"
    deadline = time.monotonic() + wait_s
    listening_since: float | None = None
    while (code := viewer.poll()) is None:
        now = time.monotonic()
        if listening_since is None and reachable(address, timeout_s=SPAWN_POLL_S) is None:
            listening_since = now
        if listening_since is not None and now - listening_since >= SPAWN_SETTLE_S:
            _SPAWNED.append(viewer)
            return None
        if listening_since is None and now >= deadline:
            viewer.kill()
            viewer.wait()
            return f"it did not listen on port {port} within {wait_s:g} s"
        time.sleep(SPAWN_POLL_S)
    return f"it exited with code {code}"


def _rerun_executable() -> str | None:
    """The viewer binary of the installed rerun-sdk, also when the venv is not on PATH."""
    beside = Path(sys.executable).parent / "rerun"
    return shutil.which("rerun") or (str(beside) if beside.exists() else None)


# ``rerun --serve-web FILE``'s defaults: the web viewer over HTTP, the data over gRPC.
SERVE_WEB_HTTP_PORT = 9090
SERVE_WEB_GRPC_PORT = 9876


def _rerun_command() -> str:
    """How to type the viewer here: ``rerun`` when it is on PATH, else the venv's own, by path
    (``make demo`` runs from a venv that is not activated)."""
    if shutil.which("rerun"):
        return "rerun"
    return _rerun_executable() or "rerun"


def open_hint(where: Path, display: bool, rerun: str = "rerun") -> str:
    """How to open the saved view ``where`` (a full path, so the hint works from any directory).

    With a display, the viewer: ``rerun FILE``. Without one, that fails on this machine (winit
    finds no X server): the viewer elsewhere (``rerun`` there; ``rerun`` is this machine's way
    to type it), or here ``rerun --serve-web FILE`` (the web viewer
    on HTTP port 9090, the data on gRPC port 9876; the page shows the recording only with the
    ``?url=`` of the data, the bare page is Rerun's welcome screen) and a browser.
    """
    path = shlex.quote(str(where))
    if display:
        return f"open it with: {rerun} {path}"
    proxy = urllib.parse.quote(f"rerun+http://127.0.0.1:{SERVE_WEB_GRPC_PORT}/proxy", safe="")
    return (
        f"on a machine with a display: rerun {path} ; from this one, in a browser: run "
        f"{rerun} --serve-web {path} and open "
        f"http://127.0.0.1:{SERVE_WEB_HTTP_PORT}/?url={proxy} (from another machine: this "
        f"host's name for both 127.0.0.1, ports {SERVE_WEB_HTTP_PORT} and {SERVE_WEB_GRPC_PORT})"
    )


def attach(
    rec: rr.RecordingStream, target: ViewerTarget, blueprint: rrb.Blueprint, *, defer: bool = False
) -> str:
    """Connect ``rec`` to ``target`` with ``blueprint`` as default layout; say where, in a line.

    ``defer``: a ``connect`` target's viewer is not there yet; say where the view will go but do
    not connect (``rec`` buffers until a later ``attach`` does, see ``OperatorView.watch_viewer``).
    """
    import rerun as rr

    if target.kind == "save":
        assert target.path is not None
        rec.save(target.path, default_blueprint=blueprint)
        why = "no display (DISPLAY/WAYLAND_DISPLAY unset); " if target.defaulted else ""
        where = target.path.resolve()
        display = has_display(os.environ) and not (target.defaulted or target.viewer_failed)
        hint = open_hint(where, display, _rerun_command())
        return f"{why}operator view saved to {where} ({hint})"
    if target.kind == "connect":
        assert target.url is not None
        if not defer:
            rec.connect_grpc(target.url, default_blueprint=blueprint)
        return f"operator view streamed to the viewer at {target.url}"
    if target.kind == "serve_web":
        assert target.web_port is not None
        grpc_url = rec.serve_grpc(
            grpc_port=target.grpc_port,
            default_blueprint=blueprint,
            server_memory_limit=SERVE_MEMORY_LIMIT,
        )
        rr.serve_web_viewer(web_port=target.web_port, open_browser=False, connect_to=grpc_url)
        query = urllib.parse.quote(grpc_url, safe="")
        return (
            f"operator view served: open http://127.0.0.1:{target.web_port}/?url={query} "
            f"(from another machine, use this host's name; ports {target.web_port} and "
            f"{target.grpc_port})"
        )
    if target.kind == "spawn":  # the viewer ``launch_viewer`` started (``viewer_address``)
        url = f"rerun+http://127.0.0.1:{DEFAULT_VIEWER_PORT}/proxy"
        rec.connect_grpc(url, default_blueprint=blueprint)
        return "operator view in a spawned Rerun viewer"
    return "operator view disabled (--no-view)"


def add_view_arguments(parser: argparse.ArgumentParser, *, with_connect: bool = True) -> None:
    """The viewer-target options: --serve-web PORT, --connect URL, --save FILE.rrd, --no-view.

    ``with_connect=False`` leaves ``--connect`` to the caller, which must then store a viewer URL
    in ``args.connect`` itself (the operator shares that option with its Zenoh endpoints).
    """
    group = parser.add_argument_group(
        "operator view (Rerun)",
        "default: spawn a local viewer when a display exists, else save to "
        "./egc-operator-<robot>-<time>.rrd",
    )
    group.add_argument(
        "--serve-web",
        metavar="PORT",
        type=int,
        help="serve the web viewer on PORT (data on gRPC port PORT+1)",
    )
    if with_connect:
        group.add_argument(
            "--connect",
            metavar="URL",
            help="stream to a running viewer, e.g. rerun+http://HOST:9876/proxy",
        )
    group.add_argument("--save", metavar="FILE.rrd", help="save the view to a recording file")
    group.add_argument("--no-view", action="store_true", help="no operator view at all")
