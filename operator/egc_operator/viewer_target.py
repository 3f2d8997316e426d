"""Where the operator view goes: a spawned viewer, the web viewer, a running viewer, or a file.

``choose_target`` is pure (arguments and environment in, a ``ViewerTarget`` out); ``attach``
connects a Rerun recording stream to it and returns one line saying where the view is.

Rules (issue 5): ``--save FILE.rrd`` -> file; ``--connect URL`` -> a running viewer (gRPC URL);
``--serve-web PORT`` -> the web viewer on PORT with the data on gRPC port PORT + 1; otherwise a
local viewer is spawned when a display exists (``DISPLAY`` or ``WAYLAND_DISPLAY``), and without
one the view is saved to ``egc-operator-<robot>-<time>.rrd`` in the working directory.
"""

from __future__ import annotations

import shutil
import sys
import urllib.parse
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import rerun as rr
import rerun.blueprint as rrb
from egc_common.errors import UsageError

Kind = Literal["spawn", "serve_web", "connect", "save", "none"]
GRPC_SCHEMES = ("rerun://", "rerun+http://", "rerun+https://")
# What the --serve-web gRPC server keeps for viewers that connect late (oldest dropped first):
# 20 Hz telemetry with 720-point scans is ~45 MB a minute, so about 20 minutes of history.
SERVE_MEMORY_LIMIT = "1GiB"


@dataclass(frozen=True, slots=True)
class ViewerTarget:
    kind: Kind
    path: Path | None = None  # save
    url: str | None = None  # connect
    web_port: int | None = None  # serve_web
    defaulted: bool = False  # save chosen because there is no display

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


def _rerun_executable() -> str | None:
    """The viewer binary of the installed rerun-sdk, also when the venv is not on PATH."""
    beside = Path(sys.executable).parent / "rerun"
    return shutil.which("rerun") or (str(beside) if beside.exists() else None)


def attach(rec: rr.RecordingStream, target: ViewerTarget, blueprint: rrb.Blueprint) -> str:
    """Connect ``rec`` to ``target`` with ``blueprint`` as default layout; say where, in a line."""
    if target.kind == "save":
        assert target.path is not None
        target.path.parent.mkdir(parents=True, exist_ok=True)
        rec.save(target.path, default_blueprint=blueprint)
        why = "no display (DISPLAY/WAYLAND_DISPLAY unset); " if target.defaulted else ""
        return f"{why}operator view saved to {target.path.resolve()} (open it with: rerun {target.path})"
    if target.kind == "connect":
        assert target.url is not None
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
    if target.kind == "spawn":
        rr.spawn(executable_path=_rerun_executable(), default_blueprint=blueprint, recording=rec)
        return "operator view in a spawned Rerun viewer"
    return "operator view disabled (--no-view)"
