"""Screenshot of the Rerun web viewer showing a recording, taken in headless Chromium.

    python docs/screenshot_web_viewer.py --demo 20       # egc-teleop demo -> docs/web_viewer.png
    python docs/screenshot_web_viewer.py --rrd run.rrd   # any recording
    python docs/screenshot_web_viewer.py                 # a synthetic corridor run (no Zenoh)
    python docs/screenshot_web_viewer.py --predictive    # predictive display, 300 ms each way
                                                         #   -> docs/predictive_display.png
    python docs/screenshot_web_viewer.py --camera 25     # the demo with its camera, through a
                                                         #   192 kbit/s downlink
                                                         #   -> docs/web_viewer_camera.png

Steps: host the web viewer bundled with rerun-sdk (``rerun --serve-web``) and serve the .rrd
over HTTP beside it, start ``chromium --headless`` with a DevTools port, open the viewer over the
DevTools protocol, wait for the wasm viewer to start (its ``window._handle``), hand it the
recording on a channel (the viewer follows it to its end), let it take the recording in on a
small page (cheap frames) until two captures a second apart agree, then set the page to
1600 x 1000 and save ``Page.captureScreenshot`` as a PNG once two captures 2 s apart agree.

``--demo S`` records ``egc-teleop demo --duration S --save FILE.rrd`` first (the simulated robot
and a scripted operator as separate processes over Zenoh). ``--camera S`` does the same through
a thin downlink (``--down`` ``CAMERA_LINK``, 80 ms each way at 192 kbit/s, DESIGN 12): the
camera panel shows the simulator's forward camera as it reached the operator (H.264, at the
rate the downlink budget allots it, its age on the robot's clock), beside the scan and the
status that says what the link carries; the script counts the camera frames the recording
holds and refuses to write a PNG without any. With neither option the recording is
made here from synthetic telemetry through the operator view's own API (what the test uses): a Pioneer 3-DX drives forward down a corridor with two boxes in it, the command pipeline
(EGC + footprint sweep) filters the constant forward command, and the resulting telemetry (with
720-beam scans) is fed to ``egc_operator.view.record_episode``. This script may import the robot
package because it is a documentation tool, not part of the operator.

``--predictive`` (``--delay-ms``, default 300) shows the predictive display (DESIGN 9) under a
one-way delay in both directions. It is a closed loop in simulated time, without Zenoh: the
simulator (``egc_sim.Simulator``) drives a Jackal in a room, the robot's own controller
(``egc_robot.controller.RobotController``: state machine, command ages, link statistics,
latency governor, EGC filter) runs at 20 Hz, a scripted operator sends 50 Hz commands, each
command reaches the controller ``delay`` after it was sent and each telemetry message reaches
the operator view ``delay`` after its stamp. The operator side does what ``OperatorNode`` does:
``view_age_ms`` on every command, the command history handed to ``OperatorView.on_commands``,
telemetry handed over with its arrival time. Both sides share one clock (a perfect clock
sync), and the link has no jitter and no loss. The run ends while the commands of a left turn
are on their way: the ghost turns, the robot the operator sees has not yet.
"""

from __future__ import annotations

import argparse
import base64
import contextlib
import functools
import http.server
import itertools
import json
import math
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
import urllib.parse
import urllib.request
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import websocket  # websocket-client (test extra): the DevTools protocol runs over a websocket
from egc_common.child_process import die_with_parent
from egc_common.messages import Telemetry

if TYPE_CHECKING:
    from egc_operator.view import OperatorView
    from egc_sim.grid_world import World

DOCS = Path(__file__).resolve().parent
DEFAULT_PNG = DOCS / "web_viewer.png"
DEFAULT_PREDICTIVE_PNG = DOCS / "predictive_display.png"
DEFAULT_CAMERA_PNG = DOCS / "web_viewer_camera.png"
CAMERA_LINK = ("--up", "delay=80", "--down", "delay=80,rate=192")
CHROMIUM_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
)


# ---------------------------------------------------------------------------------------------
# A synthetic corridor run (the recording shown when no --rrd is given)

# Axis-aligned boxes (x0, y0, x1, y1) in the world frame, metres: a closed corridor 2.8 m wide
# with a box ahead and one on the right.
CORRIDOR_BOXES = (
    (-0.6, -1.5, 9.0, -1.4),  # right wall
    (-0.6, 1.4, 9.0, 1.5),  # left wall
    (-0.6, -1.5, -0.5, 1.5),  # back wall
    (8.9, -1.5, 9.0, 1.5),  # end wall
    (1.5, 0.15, 1.9, 0.9),  # a box ahead, to the left
    (5.0, -1.4, 5.4, -0.3),  # a box on the right
)
GOAL_XY = (8.0, 0.0)
BEAMS = 720
CYCLE_S = 0.05


def raycast(
    pose: tuple[float, float, float], beams: int = BEAMS, max_range_m: float = 12.0
) -> np.ndarray:
    """Ranges of a 360-degree lidar at ``pose`` against CORRIDOR_BOXES (slab method)."""
    angles = np.linspace(-math.pi, math.pi, beams, endpoint=False)
    dx, dy = np.cos(angles + pose[2]), np.sin(angles + pose[2])
    best = np.full(beams, max_range_m)
    with np.errstate(divide="ignore", invalid="ignore"):
        for x0, y0, x1, y1 in CORRIDOR_BOXES:
            tx0, tx1 = (x0 - pose[0]) / dx, (x1 - pose[0]) / dx
            ty0, ty1 = (y0 - pose[1]) / dy, (y1 - pose[1]) / dy
            t_in = np.maximum(np.minimum(tx0, tx1), np.minimum(ty0, ty1))
            t_out = np.minimum(np.maximum(tx0, tx1), np.maximum(ty0, ty1))
            hit = (t_in <= t_out) & (t_out > 0)
            best = np.where(hit & (t_in > 0) & (t_in < best), t_in, best)
    return best


def corridor_map(resolution_m: float = 0.05) -> tuple[np.ndarray, tuple[float, float]]:
    """CORRIDOR_BOXES rasterised: (occupancy bool H x W with row 0 = top, lower-left origin)."""
    x_min, y_min, x_max, y_max = -0.7, -1.6, 9.1, 1.6
    w, h = round((x_max - x_min) / resolution_m), round((y_max - y_min) / resolution_m)
    xs = x_min + (np.arange(w) + 0.5) * resolution_m
    ys = y_max - (np.arange(h) + 0.5) * resolution_m  # row 0 = top
    gx, gy = np.meshgrid(xs, ys)
    occ = np.zeros((h, w), bool)
    for x0, y0, x1, y1 in CORRIDOR_BOXES:
        occ |= (gx >= x0) & (gx <= x1) & (gy >= y0) & (gy <= y1)
    return occ, (x_min, y_min)


def corridor_run(seconds: float, start_ns: int = 1_000_000_000) -> list[Telemetry]:
    """Telemetry of a Pioneer 3-DX driven straight ahead (full stick) in shared mode.

    The robot's own command pipeline (EGC, limits, footprint sweep) filters the command against
    a 720-beam scan each 50 ms cycle; the pose integrates the filtered command exactly.
    """
    from egc_common.kinematics import integrate_arc
    from egc_common.profiles import PIONEER3DX
    from egc_robot.pipeline import PipelineConfig, filter_velocity

    config = PipelineConfig(profile=PIONEER3DX)
    angles = np.linspace(-math.pi, math.pi, BEAMS, endpoint=False)
    pose, previous = (0.0, 0.0, 0.0), (0.0, 0.0)
    out: list[Telemetry] = []
    for i in range(round(seconds / CYCLE_S)):
        ranges = raycast(pose)
        points = np.column_stack([ranges * np.cos(angles), ranges * np.sin(angles)])
        driving = i >= 10  # 0.5 s idle, then full stick forward
        v_ref = PIONEER3DX.v_max_mps if driving else 0.0
        r = filter_velocity(config, v_ref, 0.0, "shared", points, previous, CYCLE_S)
        f = r.filtered
        out.append(
            Telemetry(
                seq=i,
                stamp_ns=start_ns + i * round(CYCLE_S * 1e9),
                state="DRIVING" if driving else "IDLE",
                mode="shared",
                v_ref=r.v_ref_mps,
                w_ref=r.w_ref_radps,
                v_cmd=r.v_cmd_mps,
                w_cmd=r.w_cmd_radps,
                w_si=r.w_si,
                region=r.region.value,
                side=None if r.side is None else r.side.value,
                limiter=r.limiter.value,
                igc=None if f is None else f.igc,
                agc=None if f is None else f.agc,
                egc=None if f is None else f.egc,
                r_rc=0.0 if f is None else f.r_rc_m,
                scan_xy=points.astype(np.float32),
                pose=pose,
                cmd_age_ms=18.0 + 6.0 * math.sin(i / 7.0),
                scan_age_ms=25.0,
                operator="op1" if driving else None,
                profile=PIONEER3DX.name,
                cycle=i,
            )
        )
        previous = (r.v_cmd_mps, r.w_cmd_radps)
        pose = integrate_arc(pose, r.v_cmd_mps, r.w_cmd_radps, CYCLE_S)
    return out


def record_corridor_run(path: Path, seconds: float = 20.0) -> Path:
    """Feed ``corridor_run`` through the operator view's API into ``path`` (a demo-like .rrd)."""
    from egc_common.messages import StateMessage
    from egc_operator.view import record_episode

    view = record_episode(path, "sim", recording_name="corridor demo (synthetic)")
    occupancy, origin = corridor_map()
    view.set_world(occupancy, 0.05, origin, GOAL_XY)
    view.on_text("info", "operator op1: connected to robot sim")
    state = None
    for t in corridor_run(seconds):
        if t.state != state:
            reason = "operator op1 in control" if t.state == "DRIVING" else "no operator"
            view.on_state(StateMessage(t.stamp_ns, t.state, reason, t.operator))
            state = t.state
        if t.cycle % 20 == 0:
            view.on_link(4.0 + (t.cycle % 60) / 20.0, t.stamp_ns - time.monotonic_ns())
        view.on_telemetry(t)
    view.close()
    return path


# ---------------------------------------------------------------------------------------------
# The predictive display under delay (--predictive)

ROOM_BOXES = (
    (0.0, 0.0, 14.0, 0.2),  # south wall
    (0.0, 8.8, 14.0, 9.0),  # north wall
    (0.0, 0.0, 0.2, 9.0),  # west wall
    (13.8, 0.0, 14.0, 9.0),  # east wall
    (6.0, 0.2, 7.0, 1.0),  # a crate on the south wall
    (10.5, 7.6, 12.0, 8.8),  # a shelf in the north-east corner
)
ROOM_START = (1.5, 3.0, 0.0)
OPERATOR_PERIOD_NS = 20_000_000  # 50 Hz commands
ROBOT_PERIOD_NS = 50_000_000  # 20 Hz control cycles
TICK_NS = 10_000_000


def room_world() -> World:
    """ROOM_BOXES as an ``egc_sim`` World (rows from the bottom, 5 cm cells)."""
    from egc_sim.grid_world import World

    res = 0.05
    w, h = round(14.0 / res), round(9.0 / res)
    xs = (np.arange(w) + 0.5) * res
    ys = (np.arange(h) + 0.5) * res  # row 0 = bottom (the World convention)
    gx, gy = np.meshgrid(xs, ys)
    occ = np.zeros((h, w), bool)
    for x0, y0, x1, y1 in ROOM_BOXES:
        occ |= (gx >= x0) & (gx <= x1) & (gy >= y0) & (gy <= y1)
    return World("room", occ, np.zeros_like(occ), res, 0.0, 0.0, start_pose=ROOM_START)


def predictive_stick(t_s: float, seconds: float) -> tuple[float, float]:
    """The scripted operator: centred to take control, a gentle right curve, straight, and a
    left turn begun 0.6 s before the end (still on its way to the robot when the run ends)."""
    if t_s < 0.6:
        return 0.0, 0.0
    if 1.6 <= t_s < 2.6:
        return 1.0, -0.12
    if t_s >= seconds - 0.6:
        return 1.0, 0.5
    return 1.0, 0.0


@dataclass
class PredictiveRun:
    """What the operator had at the end of a predictive run."""

    shown: Telemetry | None  # the newest telemetry the view showed
    status: str  # the operator's terminal status line then


def predictive_loop(view: OperatorView, seconds: float, delay_ms: float) -> PredictiveRun:
    """The closed loop described in the module docstring, fed to ``view``."""
    from egc_common.messages import Odometry, OperatorCommand, StateMessage
    from egc_common.profiles import JACKAL
    from egc_operator.operator_node import view_age_ms
    from egc_operator.prediction import CommandHistory, SentCommand
    from egc_operator.status_line import format_status, status_of
    from egc_robot.controller import ControllerConfig, RobotController
    from egc_robot.pipeline import PipelineConfig
    from egc_sim.grid_world import map_message
    from egc_sim.simulator import Simulator

    delay = round(delay_ms * 1e6)
    world = room_world()
    sim = Simulator(world, JACKAL, seed=1)
    start = 1_000_000_000
    controller = RobotController(ControllerConfig(pipeline=PipelineConfig(profile=JACKAL)), start)
    controller.on_operator_alive("op1", True)
    grid = map_message(world)
    view.set_world(grid.blocked, grid.resolution_m, (grid.origin_x_m, grid.origin_y_m))
    view.on_text("info", f"operator op1: {delay_ms:g} ms one-way delay in both directions")
    history = CommandHistory()
    uplink: list[tuple[int, bytes]] = []  # (arrival, payload), in order
    downlink: list[tuple[int, Telemetry | StateMessage]] = []  # (arrival, message), in order
    shown: Telemetry | None = None
    state: StateMessage | None = None
    base = (0.0, 0.0)
    command: OperatorCommand | None = None
    seq = 0
    for tick in range(round(seconds * 1e9 / TICK_NS) + 1):
        now = start + tick * TICK_NS
        while uplink and uplink[0][0] <= now:
            controller.on_command(uplink.pop(0)[1], now)
        if (now - start) % ROBOT_PERIOD_NS == 0:
            if now > start:
                sim.step(*base, ROBOT_PERIOD_NS / 1e9)
            controller.on_scan(sim.scan(now), now)
            x, y, th = sim.odometry
            controller.on_odometry(Odometry(now, x, y, th, *sim.twist))
            out = controller.step(now)
            base = (out.base.linear_mps, out.base.angular_radps)
            if out.state_changed is not None:
                downlink.append((now + delay, out.state_changed))
            downlink.append((now + delay, out.telemetry))
        while downlink and downlink[0][0] <= now:
            message = downlink.pop(0)[1]
            if isinstance(message, StateMessage):
                view.on_state(message)
                state = message
                continue
            view.on_telemetry(message, received_ns=now)
            shown = message
            if message.cycle % 20 == 1:  # a clock-sync round trip about once a second
                view.on_link(2 * delay_ms, now - time.monotonic_ns())
        if (now - start) % OPERATOR_PERIOD_NS == 0:
            sx, sy = predictive_stick((now - start) / 1e9, seconds)
            seq += 1
            command = OperatorCommand(
                seq=seq,
                stamp_ns=now,
                x=sx,
                y=sy,
                mode="shared",
                deadman=True,
                estop=False,
                reset=False,
                op="op1",
                view_age_ms=view_age_ms(now, True, None if shown is None else shown.stamp_ns),
            )
            uplink.append((now + delay, command.encode()))
            history.add(SentCommand(now, sx, sy, "shared"))
            view.on_commands(history, now)
    assert command is not None
    status = status_of(command, shown, state, 2 * delay_ms, True)
    return PredictiveRun(shown, format_status(status))


WORLD_FRAME_HALF_M = 3.0  # the screenshot's world view: 6 m around the end of the run


def record_predictive_run(
    path: Path, seconds: float = 5.0, delay_ms: float = 300.0
) -> tuple[Path, PredictiveRun]:
    """``predictive_loop`` recorded through the operator view, its world view framed on the end
    of the run (a first, unrecorded pass finds where that is: the loop is deterministic)."""
    from egc_operator.view import OperatorView, record_episode

    dry = predictive_loop(OperatorView(None, "sim"), seconds, delay_ms)
    assert dry.shown is not None and dry.shown.pose is not None
    x, y, _ = dry.shown.pose
    r = WORLD_FRAME_HALF_M
    view = record_episode(
        path,
        "sim",
        recording_name=f"predictive display, {delay_ms:g} ms each way",
        world_bounds_m=(x - r + 1.0, x + r + 1.0, y - r, y + r),
    )
    run = predictive_loop(view, seconds, delay_ms)
    view.close()
    return path, run


def rerun_binary() -> str:
    """The viewer binary of the installed rerun-sdk, run directly (``python -m rerun`` would
    run it as a grandchild, out of reach of ``die_with_parent``)."""
    import rerun_cli

    return str(Path(rerun_cli.__file__).with_name("rerun"))


def find_chromium() -> str | None:
    """Path of a Chromium binary on PATH, or None."""
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    return None


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def _wait_http(url: str, timeout_s: float) -> bytes:
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            with urllib.request.urlopen(url, timeout=2) as reply:
                body: bytes = reply.read()
                return body
        except OSError:
            if time.monotonic() > deadline:
                raise TimeoutError(f"nothing answered at {url} within {timeout_s:.0f} s") from None
            time.sleep(0.2)


@contextlib.contextmanager
def _process(cmd: list[str], log: Path) -> Iterator[subprocess.Popen[bytes]]:
    """Run ``cmd`` in its own process group with output to ``log``; end that group on exit.

    The group matters: Chromium's helpers would outlive it if only Chromium were terminated.
    The child also dies with this process (``die_with_parent``): a run killed from outside
    (the suite's budget) leaves no viewer or browser behind.
    """
    with log.open("wb") as out:
        proc = subprocess.Popen(
            cmd,
            stdout=out,
            stderr=subprocess.STDOUT,
            start_new_session=True,
            preexec_fn=die_with_parent,
        )
        try:
            yield proc
        finally:
            os.killpg(proc.pid, signal.SIGTERM)
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()


class _RecordingHandler(http.server.SimpleHTTPRequestHandler):
    """Serves one directory's files to the viewer's page (another port: CORS), quietly."""

    def end_headers(self) -> None:
        self.send_header("Access-Control-Allow-Origin", "*")
        super().end_headers()

    def log_message(self, format: str, *args: object) -> None:
        pass


@dataclass(frozen=True)
class Served:
    """Where the web viewer's page and the recording to show are served."""

    viewer_url: str
    rrd_url: str
    rrd_bytes: int


@contextlib.contextmanager
def serve_recording(rrd: Path, workdir: Path) -> Iterator[Served]:
    """Host the web viewer bundled with rerun-sdk and serve ``rrd`` over HTTP beside it.

    The recording is handed to the page by ``screenshot`` (``WebHandle.send_rrd_to_channel``),
    not through ``rerun --serve-web FILE``'s gRPC proxy: that server keeps polling the file it
    has read to its end (a fifth of a core for as long as it runs, taken from the browser that
    renders the page), and a recording opened from an HTTP URL would play from its start
    instead of showing its end. Given an HTTP URL, ``--serve-web`` hosts only the viewer.
    """
    handler = functools.partial(_RecordingHandler, directory=str(rrd.resolve().parent))
    files = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=files.serve_forever, name="rrd-http", daemon=True)
    thread.start()
    try:
        rrd_url = f"http://127.0.0.1:{files.server_address[1]}/{urllib.parse.quote(rrd.name)}"
        web_port = free_port()
        cmd = [rerun_binary(), "--serve-web", "--bind", "127.0.0.1"]
        cmd += ["--web-viewer-port", str(web_port), rrd_url]
        with _process(cmd, workdir / "rerun.log"):
            _wait_http(f"http://127.0.0.1:{web_port}/", 30)
            # No ``url`` parameter: the page starts empty and waits for the recording.
            viewer_url = f"http://127.0.0.1:{web_port}/?hide_welcome_screen"
            yield Served(viewer_url, rrd_url, rrd.stat().st_size)
    finally:
        files.shutdown()
        files.server_close()
        thread.join()


class DevTools:
    """A minimal DevTools-protocol session on one page target."""

    def __init__(self, ws_url: str) -> None:
        self._ws = websocket.create_connection(ws_url, timeout=60, suppress_origin=True)
        self._ids = itertools.count(1)

    def call(self, method: str, **params: object) -> dict[str, object]:
        msg_id = next(self._ids)
        self._ws.send(json.dumps({"id": msg_id, "method": method, "params": params}))
        while True:
            reply = json.loads(self._ws.recv())
            if reply.get("id") == msg_id:  # skip events
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                result: dict[str, object] = reply.get("result", {})
                return result

    def evaluate(self, expression: str, await_promise: bool = False) -> object:
        """The value of a JavaScript expression in the page (``Runtime.evaluate``)."""
        reply = self.call(
            "Runtime.evaluate",
            expression=expression,
            awaitPromise=await_promise,
            returnByValue=True,
        )
        result = reply["result"]
        assert isinstance(result, dict)
        if "exceptionDetails" in reply:
            raise RuntimeError(f"{expression[:60]}...: {reply['exceptionDetails']}")
        return result.get("value")

    def close(self) -> None:
        self._ws.close()


# The page's ``window._handle`` (the viewer's ``WebHandle``) once the wasm viewer has started.
_STARTED_JS = "typeof window._handle === 'object' && !window._handle.has_panicked()"
# Fetch the recording and hand it to the viewer on a channel (a stream: the viewer follows it
# to its end, where a live operator view would be); resolves to the number of bytes handed over.
_SEND_JS = """(async () => {
  const reply = await fetch(%s);
  const data = new Uint8Array(await reply.arrayBuffer());
  window._handle.open_channel("screenshot", "screenshot");
  window._handle.send_rrd_to_channel("screenshot", data);
  return data.length;
})()"""
# While the viewer ingests the recording it draws a frame per slice of it; a small page makes
# those frames cheap (the software rasteriser's cost is per pixel), the full size is set after.
INGEST_SIZE = (320, 200)


def _capture(tools: DevTools) -> str:
    return str(tools.call("Page.captureScreenshot", format="png")["data"])


def _settle(tools: DevTools, period_s: float, deadline: float) -> tuple[str, bool]:
    """Capture every ``period_s`` until two captures agree or ``deadline``; (last, agreed)."""
    shot = _capture(tools)
    while time.monotonic() < deadline:
        time.sleep(period_s)
        previous, shot = shot, _capture(tools)
        if shot == previous:
            return shot, True
    return shot, False


def screenshot(
    chromium: str,
    served: Served,
    png: Path,
    workdir: Path,
    start_max_s: float = 180.0,
    settle_max_s: float = 180.0,
    size: tuple[int, int] = (1600, 1000),
) -> bool:
    """Open the viewer in headless Chromium, give it the recording, save a PNG of the page;
    True if the page settled.

    Waits (at most ``start_max_s``) for the viewer's ``WebHandle`` on the page, hands it the
    recording, captures a small page every second until two captures agree (the recording is
    in), then the page at ``size`` every 2 s until two agree (at most ``settle_max_s``).
    """
    port = free_port()
    cmd = [chromium, *CHROMIUM_FLAGS, f"--user-data-dir={workdir / 'profile'}"]
    cmd += [f"--remote-debugging-port={port}", f"--window-size={size[0]},{size[1]}", "about:blank"]
    with _process(cmd, workdir / "chromium.log"):
        _wait_http(f"http://127.0.0.1:{port}/json/version", 30)
        targets = json.loads(_wait_http(f"http://127.0.0.1:{port}/json/list", 10))
        page = next(t for t in targets if t.get("type") == "page")
        tools = DevTools(page["webSocketDebuggerUrl"])

        def page_size(width: int, height: int) -> None:
            tools.call(
                "Emulation.setDeviceMetricsOverride",
                width=width,
                height=height,
                deviceScaleFactor=1,
                mobile=False,
            )

        try:
            page_size(*INGEST_SIZE)
            tools.call("Page.enable")
            tools.call("Page.navigate", url=served.viewer_url)
            deadline = time.monotonic() + start_max_s
            while not tools.evaluate(_STARTED_JS):
                if time.monotonic() > deadline:
                    raise TimeoutError(f"the web viewer did not start within {start_max_s:.0f} s")
                time.sleep(0.5)
            sent = tools.evaluate(_SEND_JS % json.dumps(served.rrd_url), await_promise=True)
            if sent != served.rrd_bytes:
                raise RuntimeError(f"the viewer got {sent} of {served.rrd_bytes} bytes")
            deadline = time.monotonic() + settle_max_s
            _settle(tools, 1.0, deadline)
            page_size(*size)
            shot, settled = _settle(tools, 2.0, deadline)
        finally:
            tools.close()
    png.write_bytes(base64.b64decode(shot))
    return settled


def record_demo(path: Path, seconds: float, link: tuple[str, ...] = ()) -> Path:
    """Run ``egc-teleop demo --duration S --save path [link flags]`` (headless; the simulated
    camera is on by default) and return ``path``."""
    cmd = [sys.executable, "-m", "egc_app.cli", "demo", "--duration", f"{seconds:g}", *link]
    subprocess.run([*cmd, "--save", str(path)], check=True, timeout=seconds + 120)
    return path


def camera_frames(rrd: Path) -> int:
    """How many camera frames a recording holds (rows at the view's camera image)."""
    from egc_operator.view_blueprint import CAMERA_IMAGE
    from rerun.chunk import RrdReader

    wanted = "/" + CAMERA_IMAGE
    return sum(
        chunk.num_rows
        for chunk in RrdReader(rrd).stream().to_chunks()
        if chunk.entity_path == wanted and not chunk.is_static
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    source = parser.add_mutually_exclusive_group()
    source.add_argument("--rrd", type=Path, help="recording to show (default: a synthetic run)")
    source.add_argument("--demo", type=float, metavar="S", help="record S seconds of the demo")
    source.add_argument(
        "--camera",
        type=float,
        metavar="S",
        help="record S seconds of the demo with its camera through a 192 kbit/s downlink "
        "(default PNG: docs/web_viewer_camera.png)",
    )
    source.add_argument(
        "--predictive",
        action="store_true",
        help="the predictive display under --delay-ms each way (default PNG: "
        "docs/predictive_display.png)",
    )
    parser.add_argument(
        "--delay-ms", type=float, default=300.0, help="one-way delay (--predictive)"
    )
    parser.add_argument("--out", type=Path, default=None, help="PNG to write")
    parser.add_argument(
        "--wait", type=float, default=180.0, help="most seconds for the web viewer to start"
    )
    parser.add_argument("--seconds", type=float, default=14.0, help="length of the synthetic run")
    args = parser.parse_args(argv)
    if args.out is None:
        args.out = (
            DEFAULT_PREDICTIVE_PNG
            if args.predictive
            else DEFAULT_CAMERA_PNG
            if args.camera
            else DEFAULT_PNG
        )
    chromium = find_chromium()
    if chromium is None:
        print(
            "screenshot_web_viewer: chromium is not installed (apt-get install chromium)",
            file=sys.stderr,
        )
        return 2
    with tempfile.TemporaryDirectory(prefix="egc-shot-") as tmp:
        workdir = Path(tmp)
        if args.rrd:
            rrd = args.rrd
        elif args.demo:
            rrd = record_demo(workdir / "demo.rrd", args.demo)
        elif args.camera:
            rrd = record_demo(workdir / "camera.rrd", args.camera, CAMERA_LINK)
            frames = camera_frames(rrd)
            if frames == 0:
                print("screenshot_web_viewer: the demo recorded no camera frame", file=sys.stderr)
                return 1
            print(f"the recording holds {frames} camera frames")
        elif args.predictive:
            rrd, run = record_predictive_run(workdir / "predictive.rrd", delay_ms=args.delay_ms)
            print(f"operator status line at the end: {run.status}")
        else:
            rrd = record_corridor_run(workdir / "corridor.rrd", args.seconds)
        with serve_recording(rrd, workdir) as served:
            settled = screenshot(chromium, served, args.out, workdir, args.wait)
    what = args.rrd or (f"{args.demo:g} s of egc-teleop demo" if args.demo else "a synthetic run")
    if args.predictive:
        what = f"the predictive display, {args.delay_ms:g} ms each way (simulated closed loop)"
    if args.camera:
        what = f"{args.camera:g} s of egc-teleop demo with its camera, {' '.join(CAMERA_LINK)}"
    print(f"wrote {args.out} ({args.out.stat().st_size} bytes) showing {what}")
    if not settled:
        print("warning: the page was still changing at the last capture", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
