"""The operator view (paper Fig. 8) in Rerun, fed with decoded telemetry and state messages.

The operator process decodes ``egc/<robot>/telemetry`` and ``egc/<robot>/state`` and calls
``OperatorView.on_telemetry`` / ``on_state``; a headless episode calls the same methods, so live
runs and episodes produce the same recording. What is drawn is computed by the pure functions of
``view_scene``; this module only turns them into Rerun log calls on an explicit
``rr.RecordingStream`` (several views can coexist in one process). Entity paths, timelines and
the default layout are in ``view_blueprint``; viewer targets in ``viewer_target``.

The operator process also hands over every command it sends (``on_commands``, with its bounded
history): the view then draws the predictive display (DESIGN 9, ``prediction``) in the world
frame, a dashed magenta ghost footprint where the robot will be when that command takes effect
and the path to it, labelled as a prediction, and the link figures in plain numbers. It is
logged at the robot time of the telemetry it starts from, so a saved recording replays the ghost
next to the measured pose the operator saw with it.

The operator process also hands over its via points (``on_route``): the world frame shows
them with the robot's echo of the active one (telemetry ``goal``, ``goals_left``), and the
robot frame the direction the filter suggests (``suggested_rad``), see ``view_scene.via_scene``.

An operator driving a fleet (DESIGN 15) opens one view with the fleet layout (``fleet=True``)
and gives each driven robot its own ``for_robot`` view on that recording (a robot's telemetry,
clock and trajectory are its own; closing it leaves the recording open); ``on_fleet`` draws
the fleet panel (``view_blueprint.FLEET_TABLE``) and the robots that share the driven robot's
map frame at their map poses (``FLEET_POSES``).

Every method is thread-safe (Zenoh delivers on its own threads) and never raises on a message:
a view must not take the operator process down.
"""

from __future__ import annotations

import argparse
import functools
import os
import shutil
import statistics
import sys
import threading
import time
import uuid
from collections import deque
from collections.abc import Callable
from datetime import timedelta
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import rerun as rr
from egc_common.errors import UsageError
from egc_common.messages import StateMessage, Telemetry

from egc_operator import view_blueprint as paths
from egc_operator.camera_view import ShownFrame
from egc_operator.fleet_table import FleetRow, fleet_markdown, on_shared_map
from egc_operator.fleet_thumbnails import THUMB_WIDTH_PX, Thumbnail
from egc_operator.prediction import (
    CommandHistory,
    Prediction,
    predict_from_history,
    uplink_estimate_ms,
)
from egc_operator.view_blueprint import operator_blueprint
from egc_operator.view_scene import (
    CBF_TEAL,
    CIRCLE_COLOURS,
    CIRCLE_NAMES,
    GOAL_GREEN,
    LANE_COLOURS,
    LATENCY_BROWN,
    LINK_SERIES,
    PREDICTED_MAGENTA,
    REFERENCE_BLUE,
    ROBOT_TO_SCREEN,
    SCAN_INK,
    SENT_RED,
    STALE_GREY,
    TRAJECTORY_TEAL,
    VIA_ORANGE,
    WORLD_TO_SCREEN,
    footprint_half_size,
    footprint_is_box,
    footprint_outline,
    ghost_scene,
    is_stale,
    link_text,
    map_image,
    pose_moved,
    profile_named,
    robot_frame_scene,
    stale_texts,
    status_changes,
    suggested_vector,
    time_series,
    via_scene,
)
from egc_operator.viewer_target import (
    ViewerTarget,
    attach,
    check_target,
    choose_target,
    default_save_path,
    launch_viewer,
    reachable,
    viewer_address,
)

TRAJECTORY_STEP_M = 0.02
VIEWER_PROBE_S = 2.0  # how often a streamed view checks that its viewer is still there
# Recording streams whose viewer never came: kept until the process exits, as dropping one
# waits 5 s for a last connection attempt.
_ABANDONED: list[rr.RecordingStream] = []
MAX_PENDING_TEXT = 100  # text events kept while the robot's clock is unknown (oldest dropped)
THIN_LINE = rr.Radius.ui_points(1.0)
THICK_LINE = rr.Radius.ui_points(2.0)
SCAN_RADIUS_M = 0.02
PREDICTION_PERIOD_NS = 50_000_000  # the ghost is redrawn at most this often (robot clock)
# A recording that failed with less free space than this beside it: "the disk is full".
FULL_DISK_BYTES = 1024 * 1024
DOWNLINK_SAMPLES = 20  # telemetry arrivals in the downlink median
CAMERA_STALE_OPACITY = 0.3  # a camera frame older than camera_view.STALE_AFTER_MS is dimmed
CAMERA_LABEL_AT = (6.0, 6.0)  # the age line's anchor, in the picture's pixels
CAMERA_FRESH_INK = (40, 160, 40)
CAMERA_STALE_INK = (200, 40, 40)
TEXT_LEVELS = {
    "trace": "TRACE",
    "debug": "DEBUG",
    "info": "INFO",
    "warn": "WARN",
    "warning": "WARN",
    "error": "ERROR",
    "critical": "CRITICAL",
}
STATE_LEVELS = {"IDLE": "INFO", "DRIVING": "INFO", "HOLD": "WARN", "ESTOP": "ERROR"}
# The fleet's robots on the map, by state (DESIGN 15).
FLEET_STATE_COLOURS = {
    "IDLE": (120, 120, 120),
    "DRIVING": (30, 150, 60),
    "HOLD": (220, 150, 0),
    "ESTOP": (210, 30, 30),
}
FLEET_MARK_RADIUS_M = 0.25
# What a fleet's driven robot draws, cleared when the operator switches to another one.
_DRIVEN_PATHS = (
    paths.SCAN,
    paths.STATUS,
    paths.CIRCLES,
    paths.TRAJECTORY,
    paths.ROBOT_POSE,
    paths.PREDICTED,
    paths.VIA,
    paths.CAMERA_IMAGE,
    paths.CAMERA_AGE,
    paths.LINK_TEXT,
)
# (series path under plots/, legend name, colour): the paper's Fig. 11 has the operator's
# reference in blue and the modified command in red.
SERIES_STYLE = (
    ("v/ref", "v_ref (operator)", REFERENCE_BLUE),
    ("v/cmd", "v_cmd (sent)", SENT_RED),
    ("w/ref", "w_ref (operator)", REFERENCE_BLUE),
    ("w/cmd", "w_cmd (sent)", SENT_RED),
    ("w_si", "w_SI", (90, 90, 90)),
    ("latency/cmd_age_ms", "command age on arrival", (200, 120, 0)),
    ("latency/scan_age_ms", "scan age", (120, 120, 120)),
    ("latency/link_rtt_ms", "link round trip", (0, 130, 160)),
    ("v/lim_latency", "v cap (latency governor)", LATENCY_BROWN),
    ("w/lim_latency", "w cap (latency governor)", LATENCY_BROWN),
    *(
        (f"latency/{name}", label, colour)
        for name, label, colour in zip(
            LINK_SERIES,
            (
                "command age p50",
                "command age p90",
                "largest command gap",
                "view age (operator)",
                "loop delay tau",
            ),
            ((230, 160, 60), (160, 80, 0), (200, 0, 120), (60, 60, 200), LATENCY_BROWN),
            strict=True,
        )
    ),
)


def open_view(
    args: argparse.Namespace,
    robot_id: str,
    *,
    application_id: str = "egc-teleop",
    recording_name: str | None = None,
    fleet: bool = False,
) -> OperatorView:
    """The operator view at the target chosen by ``add_view_arguments``' options (``fleet``:
    the layout of an operator driving a fleet, DESIGN 15).

    Prints one line on stderr saying where the view is. Raises ``UsageError`` for a bad
    combination of options, a malformed URL, a file that cannot be written or a web port in use
    (the CLI turns it into exit code 2), before anything is opened. A viewer that cannot be
    reached is no error (driving does not need it): the view warns on stderr, once; a spawned
    viewer that did not start (no usable display) is replaced by the default .rrd file.
    """
    stamp = time.strftime("%Y%m%d-%H%M%S")
    target = choose_target(
        save=args.save,
        connect=args.connect,
        serve_web=args.serve_web,
        no_view=args.no_view,
        env=os.environ,
        robot_id=robot_id,
        stamp=stamp,
    )
    check_target(target)
    address = viewer_address(target)
    # Rerun 0.41's connect_grpc blocks 5 s when no viewer answers, then its sink sends nothing
    # (a viewer started later got only the layout), and dropping it waits 5 s more (at close or
    # exit). So a missing viewer is connected to once it answers (``watch_viewer``); until then
    # the recording buffers in memory, as that sink did, and the viewer gets all of it.
    later = target.kind == "connect" and address is not None and reachable(address) is not None
    why = launch_viewer(address[1]) if target.kind == "spawn" and address is not None else None
    if why is None:
        view = _open(target, robot_id, application_id, recording_name, fleet=fleet, later=later)
    else:
        # The display did not take a viewer: the hint must not say "rerun FILE" here.
        fallback = ViewerTarget("save", path=default_save_path(robot_id, stamp), viewer_failed=True)
        check_target(fallback)
        view = _open(fallback, robot_id, application_id, recording_name, fleet=fleet)
        assert fallback.path is not None
        view.flush()
        if fallback.path.exists():
            view.where = f"the spawned viewer did not start ({why}); {view.where}"
        else:  # never claim a file that is not there
            view.abandon()
            view = OperatorView(None, robot_id)
            view.where = (
                f"the spawned viewer did not start ({why}) and the view could not be "
                f"saved to {fallback.path.resolve()}; no view (use --save FILE.rrd)"
            )
        address = None
    print(f"egc-teleop: {view.where}", file=sys.stderr)
    if address is not None:
        view.watch_viewer(address, target.url or f"127.0.0.1:{address[1]}")
    return view


def record_episode(
    path: str | Path,
    robot_id: str,
    *,
    application_id: str = "egc-teleop",
    recording_name: str | None = None,
    world_bounds_m: tuple[float, float, float, float] | None = None,
) -> OperatorView:
    """The operator view saved to ``path`` (.rrd), for headless episodes (``--record``).

    ``world_bounds_m`` frames the world view (see ``view_blueprint.operator_blueprint``).
    """
    target = ViewerTarget("save", path=Path(path))
    return _open(target, robot_id, application_id, recording_name, world_bounds_m)


# A saved view has no one watching live, so it batches a second of telemetry per chunk instead of
# Rerun's 200 ms: the file sink keeps a little memory per chunk for the recording's index, and at
# 20 Hz this grows memory about 3x slower and makes the file about 45% smaller (measured).
FILE_BATCHER = rr.ChunkBatcherConfig(flush_tick=timedelta(seconds=1))


def _open(
    target: ViewerTarget,
    robot_id: str,
    application_id: str,
    recording_name: str | None,
    world_bounds_m: tuple[float, float, float, float] | None = None,
    fleet: bool = False,
    later: bool = False,
) -> OperatorView:
    """``later``: connect to the viewer when it answers (see ``open_view``), not now."""
    if target.kind == "none":
        return OperatorView(None, robot_id, where="operator view disabled (--no-view)")
    batcher = FILE_BATCHER if target.kind == "save" else None
    rec = rr.RecordingStream(application_id, recording_id=uuid.uuid4(), batcher_config=batcher)
    blueprint = operator_blueprint(robot_id, world_bounds_m=world_bounds_m, fleet=fleet)
    try:
        where = attach(rec, target, blueprint, defer=later)
    except (RuntimeError, OSError) as exc:  # e.g. the file or port was taken since the check
        option = {"save": "--save", "serve_web": "--serve-web", "connect": "--connect"}
        raise UsageError(f"{option.get(target.kind, 'view')}: {exc}") from None
    rec.send_recording_name(recording_name or f"{robot_id}: operator view")
    connect = functools.partial(attach, rec, target, blueprint) if later else None
    view = OperatorView(rec, robot_id, where=where, connect_later=connect)
    view.save_path = target.path if target.kind == "save" else None
    return view


class OperatorView:
    """Logs telemetry, state, text and link statistics of one robot to one recording.

    ``recording`` None makes a view that drops everything (``--no-view``); ``where`` is the
    line ``open_view`` prints (where the view goes).
    """

    def __init__(
        self,
        recording: rr.RecordingStream | None,
        robot_id: str,
        where: str = "",
        owns_recording: bool = True,
        connect_later: Callable[[], object] | None = None,
    ) -> None:
        """``connect_later``: attaches the viewer that was missing when the view opened; the
        viewer watch (``watch_viewer``) calls it once the viewer answers."""
        self.robot_id = robot_id
        self.where = where
        self._rec = recording
        self._owns_recording = owns_recording  # False: a ``for_robot`` view of a fleet
        # A ``for_robot`` view the operator switched away from: ``close`` clears its drawings.
        self.clear_on_close = False
        self._fleet_drawn = False
        self._lock = threading.Lock()
        self._last: Telemetry | None = None
        self._world_profile: str | None = None
        self._trajectory_end: tuple[float, float] | None = None
        self._state_key: tuple[str, str, str | None, str | None, str | None] | None = None
        self._rejected_seen = 0
        self._offset_ns: int | None = None
        self._robot_ns: int | None = None  # the latest robot stamp seen
        self._pending_text: deque[tuple[str, str]] = deque(maxlen=MAX_PENDING_TEXT)
        self._rtt_ms: float | None = None
        self._downlink_ms: deque[float] = deque(maxlen=DOWNLINK_SAMPLES)
        self._predicted_ns: int | None = None  # robot time of the last ghost drawn
        self._ghost_drawn = False
        self._route: tuple[tuple[float, float], ...] = ()  # the operator's via points
        self._route_frame: str | None = None
        self._via_key: object = None  # what the via points were last drawn from
        self._suggested_drawn = False
        # Staleness (DESIGN 9): no ghost and no link figures from telemetry that is not the
        # robot now. ``clock`` is this process's monotonic clock (a test's fake).
        self.clock = time.monotonic_ns
        self._rx_ns: int | None = None  # when the newest telemetry arrived (``clock``)
        self._present = True  # the robot's liveliness token (``on_robot_presence``)
        self._stale_drawn: tuple[str, str] | None = None  # the stale texts last drawn
        self._viewer_missing: str | None = None  # why the viewer cannot be reached, if not
        self._camera_ns: int | None = None  # robot time of the camera's newest row
        self._camera_stale = False
        self._watch_stop = threading.Event()
        self._watcher: threading.Thread | None = None
        self._connect = connect_later
        self.save_path: Path | None = None  # the recording file, when the view is saved to one
        if recording is not None:
            self._log_static(recording)

    # -- public API ------------------------------------------------------------------------------

    def for_robot(self, robot_id: str) -> OperatorView:
        """A view of one driven robot on this view's recording (DESIGN 15): its telemetry,
        clock, trajectory and camera are its own; ``close`` leaves the recording open (this
        view's ``close`` closes it) and, with ``clear_on_close`` (switched away from), clears
        what it drew at its last time."""
        with self._lock:
            rec = self._rec
        view = OperatorView(rec, robot_id, where=self.where, owns_recording=False)
        view.clock = self.clock
        return view

    def latest_telemetry(self) -> Telemetry | None:
        """The newest telemetry drawn (None: none yet, or no view)."""
        with self._lock:
            return self._last

    def on_thumbnail(self, thumb: Thumbnail, index: int, robot_now_ns: int | None) -> None:
        """Another robot's camera snapshot in the fleet's row of snapshots (DESIGN 15), the
        ``index``-th from the left, at the driven robot's time now."""
        with self._lock:
            rec = self._rec
            if rec is None or robot_now_ns is None or robot_now_ns <= 0:
                return
            _set_time(rec, robot_now_ns, self._cycle)
            base = f"{paths.FLEET_CAMERAS}/{thumb.robot}"
            rec.log(base, rr.Transform3D(translation=(index * (THUMB_WIDTH_PX + 8), 0.0, 0.0)))
            rec.log(f"{base}/image", rr.EncodedImage(contents=thumb.jpeg, media_type="image/jpeg"))
            rec.log(
                f"{base}/label",
                rr.Points2D([(4.0, 6.0)], radii=2.0, labels=[thumb.robot], show_labels=True),
            )

    def on_fleet(self, rows: list[FleetRow], me: str, robot_now_ns: int | None) -> None:
        """The fleet panel and the robots sharing the driven robot's map (DESIGN 15), at the
        driven robot's time now (``robot_now_ns``; None: its clock is not known yet, the
        panel waits)."""
        with self._lock:
            rec = self._rec
            if rec is None or robot_now_ns is None or robot_now_ns <= 0:
                return
            _set_time(rec, robot_now_ns, self._cycle)
            rec.log(
                paths.FLEET_TABLE,
                rr.TextDocument(fleet_markdown(rows, me), media_type="text/markdown"),
            )
            shown = [row for row in on_shared_map(rows) if not row.driven]
            if not shown and not self._fleet_drawn:
                return
            poses = [row.map_pose for row in shown if row.map_pose is not None]
            rec.log(
                paths.FLEET_POSES,
                rr.Points2D(
                    [(p[0], p[1]) for p in poses],
                    radii=FLEET_MARK_RADIUS_M,
                    colors=[FLEET_STATE_COLOURS.get(row.state or "", STALE_GREY) for row in shown],
                    labels=[f"{row.robot} {row.state or '?'}" for row in shown],
                    show_labels=True,
                    draw_order=20.0,
                ),
            )
            self._fleet_drawn = bool(shown)

    def on_telemetry(self, t: Telemetry, received_ns: int | None = None) -> None:
        """One control cycle: robot-frame view, time series, status lanes, world frame (pose).

        ``received_ns``: the robot's clock when it arrived (the operator's estimate), for the
        downlink figure; None when unknown (headless episodes, clock not synchronised).
        """
        with self._lock:
            rec = self._rec
            if rec is None:
                return
            if received_ns is not None and received_ns > 0:
                self._downlink_ms.append((received_ns - t.stamp_ns) / 1e6)
            self._rx_ns = self.clock()
            self._stale_drawn = None
            _set_time(rec, t.stamp_ns, t.cycle)
            self._log_robot_frame(rec, t)
            for name, value in time_series(t).items():
                rec.log(paths.plot_path(name), rr.Scalars(value))
            for lane, state in status_changes(self._last, t).items():
                rec.log(paths.lane_path(lane), rr.StateChange(state=state))
            self._note_rejections(rec, t.rejected)
            if t.pose is not None:
                self._log_pose(rec, t)
            self._log_via(rec, t)
            self._last = t
            self._robot_ns = t.stamp_ns
            self._log_pending_text(rec)

    def on_state(self, s: StateMessage) -> None:
        """A state message: logged to the text log when state, reason or operator changed."""
        with self._lock:
            rec = self._rec
            if rec is None:
                return
            self._robot_ns = s.stamp_ns
            self._log_pending_text(rec)
            _set_time(rec, s.stamp_ns, self._cycle)
            key = (s.state, s.reason, s.operator, s.source, s.lock)
            if key != self._state_key:
                who = f" (operator {s.operator})" if s.operator else ""
                if s.source is not None:
                    who += f" (source {s.source})"
                if s.lock is not None:
                    who += f" (lock {s.lock})"
                text = f"robot state {s.state}: {s.reason}{who}"
                rec.log(paths.TEXT_LOG, rr.TextLog(text, level=STATE_LEVELS.get(s.state, "INFO")))
                self._state_key = key
            self._note_rejections(rec, s.rejected)

    def on_text(self, level: str, text: str) -> None:
        """An operator-side event (a rejected message, a link event) for the text log.

        Before anything tells the robot's clock (telemetry, state or a link sample) the event
        waits, and is logged at the first robot time known: a stamp of 0 would stretch the
        ``robot_time`` timeline from zero to the robot's uptime.
        """
        with self._lock:
            rec = self._rec
            if rec is None:
                return
            self._pending_text.append((TEXT_LEVELS.get(level.lower(), "INFO"), text))
            self._log_pending_text(rec)

    def on_link(self, rtt_ms: float, offset_ns: int) -> None:
        """A clock-sync round trip; ``offset_ns`` = robot clock - this process's monotonic clock."""
        with self._lock:
            rec = self._rec
            if rec is None:
                return
            self._offset_ns = int(offset_ns)
            self._rtt_ms = float(rtt_ms)
            _set_time(rec, self._robot_now() or 0, self._cycle)
            rec.log(paths.LINK_RTT, rr.Scalars(float(rtt_ms)))
            self._log_pending_text(rec)

    def on_robot_presence(self, present: bool) -> None:
        """The robot's liveliness token came or went (the operator node's liveliness
        subscriber). Gone: the view says so at once, and draws no ghost and no link figures
        from its last telemetry. Back (a restart, or after a long outage): the old robot's
        telemetry is forgotten. Either way its round trip is (the new one's comes with the next
        clock reply)."""
        with self._lock:
            if present == self._present:
                return
            self._present = present
            if present:  # a new robot (or one back from a long outage): its own telemetry
                self._last = None
            self._trajectory_end = None
            self._downlink_ms.clear()
            self._rejected_seen = 0
            self._rtt_ms = None  # the old robot's round trip (the uplink's "rtt/2" estimate)
            rec = self._rec
            now = self._robot_now()
            if rec is not None and not present and now is not None:
                self._log_stale(rec, now)

    def on_commands(self, history: CommandHistory, robot_now_ns: int) -> None:
        """The operator sent a command at ``robot_now_ns`` (robot clock): redraw the ghost.

        ``history`` holds the commands sent, newest last; it is read during the call only. The
        ghost and the link figures are redrawn at most every ``PREDICTION_PERIOD_NS``. While
        the telemetry is stale (``view_scene.is_stale``) there is no ghost, and the view says
        how old it is instead of the link figures.
        """
        with self._lock:
            rec = self._rec
            if rec is None or robot_now_ns <= 0:
                return
            last = self._predicted_ns
            if last is not None and 0 <= robot_now_ns - last < PREDICTION_PERIOD_NS:
                return
            self._predicted_ns = robot_now_ns
            if is_stale(self._telemetry_age_s(), self._present):
                self._log_stale(rec, robot_now_ns)
                return
            t = self._last
            prediction = None
            uplink_ms = None
            if t is not None:
                uplink_ms = uplink_estimate_ms(t.cmd_age_p50_ms, self._rtt_ms)
                prediction = predict_from_history(t, history, robot_now_ns, self._rtt_ms)
            # At the robot time of the telemetry it starts from: a replay then shows the ghost
            # next to the measured pose it was predicted from, as the operator saw them.
            _set_time(rec, robot_now_ns if t is None else t.stamp_ns, self._cycle)
            self._log_prediction(rec, t, prediction)
            downlink = statistics.median(self._downlink_ms) if self._downlink_ms else None
            text = link_text(
                uplink_ms,
                t is not None and t.cmd_age_p50_ms is None and uplink_ms is not None,
                downlink,
                None if t is None else max(0.0, (robot_now_ns - t.stamp_ns) / 1e6),
                t,
                prediction,
            )
            rec.log(paths.LINK_TEXT, rr.TextDocument(text))

    def on_camera(self, frame: ShownFrame, text: str, robot_now_ns: int | None) -> None:
        """The robot's camera (DESIGN 12): the newest frame and its age line, logged at the
        robot's time now (when it is shown; its capture time is in the line) and never before
        the camera's previous row, so that the latest row is always the newest frame."""
        with self._lock:
            rec = self._rec
            if rec is None:
                return
            self._set_camera_time(rec, robot_now_ns or frame.stamp_ns)
            rec.log(
                paths.CAMERA_IMAGE,
                rr.EncodedImage(contents=frame.jpeg(), media_type="image/jpeg", opacity=1.0),
            )
            self._camera_stale = False
            self._log_camera_text(rec, text, stale=False)

    def on_camera_text(self, text: str, stale: bool, robot_now_ns: int | None) -> None:
        """The age line again, as the shown frame grows older; ``stale``: dim the frame."""
        with self._lock:
            rec = self._rec
            now = robot_now_ns or self._robot_now()
            if rec is None or now is None or self._camera_ns is None:
                return
            self._set_camera_time(rec, now)
            if stale != self._camera_stale:
                opacity = CAMERA_STALE_OPACITY if stale else 1.0
                rec.log(paths.CAMERA_IMAGE, rr.EncodedImage.from_fields(opacity=opacity))
                self._camera_stale = stale
            self._log_camera_text(rec, text, stale)

    def _set_camera_time(self, rec: rr.RecordingStream, robot_ns: int) -> None:
        self._camera_ns = max(robot_ns, self._camera_ns or 0)
        _set_time(rec, self._camera_ns, self._cycle)

    @staticmethod
    def _log_camera_text(rec: rr.RecordingStream, text: str, stale: bool) -> None:
        ink = CAMERA_STALE_INK if stale else CAMERA_FRESH_INK
        rec.log(
            paths.CAMERA_AGE,
            rr.Points2D([CAMERA_LABEL_AT], radii=2.0, colors=ink, labels=[text], show_labels=True),
        )

    def on_route(self, points: tuple[tuple[float, float], ...], frame: str) -> None:
        """The operator's via points (in order, in ``frame``); empty: none or cleared."""
        with self._lock:
            self._route = tuple((float(x), float(y)) for x, y in points)
            self._route_frame = frame
            rec = self._rec
            if rec is None or self._last is None:
                return  # drawn with the next telemetry
            _set_time(rec, self._last.stamp_ns, self._cycle)
            self._log_via(rec, self._last)

    def set_world(
        self,
        occupancy: npt.ArrayLike,
        resolution_m: float,
        origin_xy_m: tuple[float, float],
        goal_xy_m: tuple[float, float] | None = None,
    ) -> None:
        """The static map of the world-frame view (bool H x W, row 0 = top; origin = lower-left)."""
        image = map_image(occupancy, resolution_m, origin_xy_m)
        with self._lock:
            rec = self._rec
            if rec is None:
                return
            rec.log(
                paths.MAP,
                rr.Transform3D(translation=image.translation, mat3x3=image.mat3x3),
                rr.Image(image.pixels, color_model="L", draw_order=-100.0),
                static=True,
            )
            goal = [] if goal_xy_m is None else [goal_xy_m]
            rec.log(
                paths.GOAL,
                rr.Points2D(goal, radii=0.12, colors=GOAL_GREEN, labels=["goal"] * len(goal)),
                static=True,
            )

    def flush(self) -> None:
        """Block until everything logged so far has reached the sink."""
        with self._lock:
            rec = self._rec
        if rec is not None:
            rec.flush()

    def close(self) -> None:
        """Flush and close the sink; a saved .rrd is complete and readable afterwards.

        Text events still waiting for a robot time (no robot was ever heard) go at time 0.
        """
        self._watch_stop.set()
        if self._watcher is not None:
            self._watcher.join()  # a connection under way ends before the recording is closed
        with self._lock:
            rec, self._rec = self._rec, None
            if rec is not None:
                self._log_pending_text(rec, at_ns=self._robot_now() or 0)
        if rec is not None and not self._owns_recording:
            if not self.clear_on_close:
                return
            # A fleet's robot no longer driven: its drawings go at its last time, so the next
            # robot's are not shown mixed with them.
            with self._lock:
                now = self._robot_now()
                if now is not None:
                    _set_time(rec, now, self._cycle)
                    for path in _DRIVEN_PATHS:
                        rec.log(path, rr.Clear(recursive=True))
            return
        if rec is None:
            return
        # A viewer that went away must not end the run with a traceback: the driving is done.
        missing = self._viewer_missing is not None
        try:
            rec.flush(timeout_sec=1.0) if missing else rec.flush()
            rec.disconnect()
        except Exception as exc:  # Rerun raises RuntimeError when its gRPC sink cannot connect
            if self.save_path is not None:  # or when its file writer failed (disk full, ...)
                print(f"egc-teleop: warning: {cut_short(self.save_path, exc)}", file=sys.stderr)
                return
            print(
                f"egc-teleop: warning: the view did not reach the viewer ({exc}); "
                "nothing was saved (--save FILE.rrd keeps a view)",
                file=sys.stderr,
            )

    def abandon(self) -> None:
        """Drop the recording without waiting for its viewer (one that never came)."""
        with self._lock:
            rec, self._rec = self._rec, None
        if rec is not None:
            _ABANDONED.append(rec)

    def watch_viewer(self, address: tuple[str, int], url: str) -> None:
        """Check every ``VIEWER_PROBE_S`` that the viewer at ``address`` accepts connections;
        say once on stderr when it does not (and when it is back). Rerun buffers the view for
        it meanwhile; the driving never waits for it. A view opened without its viewer is
        connected to it here, once it answers."""

        def watch() -> None:
            while True:
                why = reachable(address)
                if why is None and self._connect is not None:
                    self._connect_now(url)
                if why is not None and self._viewer_missing is None:
                    print(
                        f"egc-teleop: warning: no viewer answers at {url} ({why}); the view "
                        "is not shown (driving goes on; start a viewer there, or use --save "
                        "FILE.rrd to keep the view)",
                        file=sys.stderr,
                        flush=True,
                    )
                elif why is None and self._viewer_missing is not None:
                    print(f"egc-teleop: viewer at {url} reachable again", file=sys.stderr)
                self._viewer_missing = why
                if self._watch_stop.wait(VIEWER_PROBE_S):
                    return

        self._watcher = threading.Thread(target=watch, name="viewer-watch", daemon=True)
        self._watcher.start()

    def _connect_now(self, url: str) -> None:
        with self._lock:
            connect, self._connect = self._connect, None
        try:
            if connect is not None:
                connect()
        except (RuntimeError, OSError) as exc:
            print(f"egc-teleop: warning: could not connect to {url}: {exc}", file=sys.stderr)

    # -- internals -------------------------------------------------------------------------------

    def _telemetry_age_s(self) -> float | None:
        return None if self._rx_ns is None else (self.clock() - self._rx_ns) / 1e9

    def _log_stale(self, rec: rr.RecordingStream, robot_now_ns: int) -> None:
        """No telemetry from the robot now: clear the ghost, say so in the robot frame and the
        link panel (at the robot's time now, after its last telemetry)."""
        texts = stale_texts(self._telemetry_age_s(), self._present)
        if texts == self._stale_drawn and not self._ghost_drawn:
            return
        _set_time(rec, robot_now_ns, self._cycle)
        self._log_prediction(rec, None, None)
        if texts != self._stale_drawn:
            status, panel = texts
            anchor = (-0.5, 0.0)
            rec.log(
                paths.STATUS,
                rr.Points2D([anchor], colors=_colour_array(STALE_GREY), labels=[status]),
            )
            rec.log(paths.LINK_TEXT, rr.TextDocument(panel))
            self._stale_drawn = texts

    @property
    def _cycle(self) -> int:
        return 0 if self._last is None else self._last.cycle

    def _robot_now(self) -> int | None:
        """The robot's clock now: from the link offset once known, else the latest robot stamp."""
        if self._offset_ns is not None:
            return max(0, time.monotonic_ns() + self._offset_ns)
        return self._robot_ns

    def _log_pending_text(self, rec: rr.RecordingStream, at_ns: int | None = None) -> None:
        """Log the waiting text events once a robot time is known (``at_ns`` forces one)."""
        robot_ns = self._robot_now() if at_ns is None else at_ns
        if robot_ns is None or not self._pending_text:
            return
        _set_time(rec, robot_ns, self._cycle)
        while self._pending_text:
            level, text = self._pending_text.popleft()
            rec.log(paths.TEXT_LOG, rr.TextLog(text, level=level))

    def _log_static(self, rec: rr.RecordingStream) -> None:
        """Transforms and styling, logged once: per cycle only the geometry is sent."""
        rec.send_property("robot", rr.AnyValues(robot_id=self.robot_id))
        rec.log(paths.ROBOT, rr.Transform3D(mat3x3=ROBOT_TO_SCREEN), static=True)
        rec.log(paths.WORLD, rr.Transform3D(mat3x3=WORLD_TO_SCREEN), static=True)
        rec.log(
            paths.SCAN, rr.Points2D.from_fields(radii=SCAN_RADIUS_M, colors=SCAN_INK), static=True
        )
        rec.log(paths.FOOTPRINT, rr.Boxes2D.from_fields(radii=THICK_LINE), static=True)
        rec.log(paths.STATUS, rr.Points2D.from_fields(radii=0.03), static=True)
        for name in CIRCLE_NAMES:
            rec.log(
                paths.circle_path(name),
                rr.Ellipses2D.from_fields(colors=CIRCLE_COLOURS[name], line_radii=THIN_LINE),
                static=True,
            )
        for path, colour in ((paths.REFERENCE_ARROW, REFERENCE_BLUE), (paths.SENT_ARROW, SENT_RED)):
            rec.log(path, rr.Arrows2D.from_fields(origins=[(0.0, 0.0)], colors=colour), static=True)
        rec.log(
            paths.SUGGESTED_ARROW,
            rr.Arrows2D.from_fields(
                origins=[(0.0, 0.0)], colors=VIA_ORANGE, labels=["suggested"], show_labels=True
            ),
            static=True,
        )
        rec.log(
            paths.TRAJECTORY,
            rr.LineStrips2D.from_fields(radii=THIN_LINE, colors=TRAJECTORY_TEAL),
            static=True,
        )
        for path, radius in (
            (paths.PREDICTED_FOOTPRINT, THICK_LINE),
            (paths.PREDICTED_PATH, THIN_LINE),
        ):
            rec.log(
                path,
                rr.LineStrips2D.from_fields(
                    radii=radius, colors=PREDICTED_MAGENTA, draw_order=40.0
                ),
                static=True,
            )
        rec.log(
            paths.PREDICTED_HEADING,
            rr.Arrows2D.from_fields(colors=PREDICTED_MAGENTA, radii=THIN_LINE, show_labels=True),
            static=True,
        )
        for name, label, colour in SERIES_STYLE:
            rec.log(
                paths.plot_path(name),
                rr.SeriesLines(colors=[colour], names=[label], widths=[1.5]),
                static=True,
            )
        for lane, styles in LANE_COLOURS.items():
            rec.log(
                paths.lane_path(lane),
                rr.StateConfiguration(values=[v for v, _ in styles], colors=[c for _, c in styles]),
                static=True,
            )

    def _log_robot_frame(self, rec: rr.RecordingStream, t: Telemetry) -> None:
        scene = robot_frame_scene(t)
        colour = _colour_array(scene.region_colour)
        rec.log(paths.SCAN, rr.Points2D(scene.scan_xy))
        if scene.footprint_outline is not None:  # a polygon or a disc, as given (DESIGN 14)
            rec.log(paths.FOOTPRINT, rr.LineStrips2D([scene.footprint_outline], colors=colour))
        else:
            half = [] if scene.footprint_half_size is None else [scene.footprint_half_size]
            rec.log(paths.FOOTPRINT, rr.Boxes2D(half_sizes=half, colors=colour))
        rec.log(
            paths.STATUS, rr.Points2D([scene.status_anchor], colors=colour, labels=[scene.status])
        )
        for name in CIRCLE_NAMES:
            circle = scene.circles[name]
            drawn = [] if circle is None else [circle]
            rec.log(
                paths.circle_path(name),
                rr.Ellipses2D(
                    centers=[c[:2] for c in drawn], half_sizes=[(c[2], c[2]) for c in drawn]
                ),
            )
        rec.log(paths.REFERENCE_ARROW, rr.Arrows2D(vectors=[scene.reference_vector]))
        rec.log(paths.SENT_ARROW, rr.Arrows2D(vectors=[scene.sent_vector]))
        # cbf (DESIGN 13): its margin and the points that changed the command, over the scan.
        margin = [] if scene.cbf_margin is None else [scene.cbf_margin]
        rec.log(paths.CBF_MARGIN, rr.LineStrips2D(margin, colors=CBF_TEAL, radii=THIN_LINE))
        rec.log(paths.CBF_POINTS, rr.Points2D(scene.cbf_xy, colors=SENT_RED, radii=0.04))
        suggested = suggested_vector(t)
        if suggested is not None:
            rec.log(paths.SUGGESTED_ARROW, rr.Arrows2D(vectors=[suggested]))
            self._suggested_drawn = True
        elif self._suggested_drawn:
            rec.log(paths.SUGGESTED_ARROW, rr.Arrows2D(vectors=[], origins=[], labels=[]))
            self._suggested_drawn = False

    def _log_via(self, rec: rr.RecordingStream, t: Telemetry) -> None:
        """The via points in the world frame, and the active one in {R}: redrawn when the
        route, the robot's echo or (while one is active) the robot's position changed."""
        pose_key = None
        if t.goal is not None and t.pose is not None:
            step = TRAJECTORY_STEP_M * 2.5
            pose_key = (round(t.pose[0] / step), round(t.pose[1] / step), round(t.pose[2], 1))
        key = (self._route, self._route_frame, t.goal, t.goal_frame, t.goals_left, pose_key)
        if key == self._via_key:
            return
        first = self._via_key is None
        self._via_key = key
        scene = via_scene(self._route, self._route_frame, t)
        if scene.empty and first:
            return  # nothing to draw, and nothing drawn to clear
        active = [] if scene.active is None else [scene.active]
        rec.log(
            paths.VIA_ACTIVE,
            rr.Points2D(
                active,
                radii=0.15,
                colors=VIA_ORANGE,
                labels=[scene.active_label] * len(active),
                draw_order=30.0,
            ),
        )
        rec.log(
            paths.VIA_POINTS,
            rr.Points2D(scene.others, radii=0.08, colors=scene.other_colours, draw_order=29.0),
        )
        strips = [scene.route] if len(scene.route) >= 2 else []
        rec.log(paths.VIA_ROUTE, rr.LineStrips2D(strips, colors=VIA_ORANGE, radii=THIN_LINE))
        seen = []
        if scene.active is not None and t.pose is not None and t.goal_frame in (None, "odom"):
            seen = [_to_robot_frame(scene.active, t.pose)]
        rec.log(paths.ROBOT_VIA, rr.Points2D(seen, radii=0.1, colors=VIA_ORANGE))

    def _log_pose(self, rec: rr.RecordingStream, t: Telemetry) -> None:
        assert t.pose is not None
        x, y, theta = t.pose
        rec.log(
            paths.ROBOT_POSE,
            rr.Transform3D(
                translation=(x, y, 0.0),
                rotation_axis_angle=rr.RotationAxisAngle(axis=(0.0, 0.0, 1.0), radians=theta),
            ),
        )
        profile = profile_named(t.profile)
        if profile is not None and t.profile != self._world_profile:
            shape: Any = (
                rr.Boxes2D(
                    half_sizes=[footprint_half_size(profile)], colors=SCAN_INK, radii=THICK_LINE
                )
                if footprint_is_box(profile)
                else rr.LineStrips2D(
                    [footprint_outline(profile)], colors=SCAN_INK, radii=THICK_LINE
                )
            )
            rec.log(
                paths.POSE_FOOTPRINT,
                shape,
                rr.Arrows2D(
                    origins=[(0.0, 0.0)], vectors=[(profile.length_m, 0.0)], colors=SCAN_INK
                ),
                static=True,
            )
            self._world_profile = t.profile
        if pose_moved(self._trajectory_end, t.pose, TRAJECTORY_STEP_M):
            if self._trajectory_end is not None:
                rec.log(paths.TRAJECTORY, rr.LineStrips2D([[self._trajectory_end, (x, y)]]))
            self._trajectory_end = (x, y)

    def _log_prediction(
        self, rec: rr.RecordingStream, t: Telemetry | None, prediction: Prediction | None
    ) -> None:
        """The ghost footprint, its heading (labelled) and the dashed path, in world coordinates;
        cleared (empty) when there is no prediction."""
        profile = None if t is None else profile_named(t.profile)
        if prediction is None or profile is None:
            if self._ghost_drawn:
                rec.log(paths.PREDICTED_FOOTPRINT, rr.LineStrips2D([]))
                rec.log(paths.PREDICTED_HEADING, rr.Arrows2D(vectors=[], origins=[], labels=[]))
                rec.log(paths.PREDICTED_PATH, rr.LineStrips2D([]))
                self._ghost_drawn = False
            return
        ghost = ghost_scene(prediction, profile)
        rec.log(paths.PREDICTED_FOOTPRINT, rr.LineStrips2D(ghost.footprint))
        rec.log(
            paths.PREDICTED_HEADING,
            rr.Arrows2D(
                origins=[ghost.heading_origin], vectors=[ghost.heading_vector], labels=[ghost.label]
            ),
        )
        rec.log(paths.PREDICTED_PATH, rr.LineStrips2D(ghost.path))
        self._ghost_drawn = True

    def _note_rejections(self, rec: rr.RecordingStream, total: int) -> None:
        """Text-log how many more commands the robot rejected since the last report."""
        if total > self._rejected_seen:
            new = total - self._rejected_seen
            text = f"robot rejected {new} more command(s) ({total} in total)"
            rec.log(paths.TEXT_LOG, rr.TextLog(text, level="WARN"))
        self._rejected_seen = max(self._rejected_seen, total)


def cut_short(path: Path, exc: BaseException) -> str:
    """What to say when writing the recording ``path`` failed with ``exc`` (Rerun says only
    that its file writer stopped; its own error line before this one says why)."""
    try:
        kept = f"{path.stat().st_size} bytes kept"
    except OSError as err:
        kept = f"its size is unknown ({err.strerror})"
    try:
        full = shutil.disk_usage(path.resolve().parent).free < FULL_DISK_BYTES
    except OSError:
        full = False
    why = "the disk is full" if full else "a write error"
    return f"the recording {path} was cut short ({why}; Rerun: {exc}); {kept} (driving went on)"


def _to_robot_frame(
    point: tuple[float, float], pose: tuple[float, float, float]
) -> tuple[float, float]:
    """A world point in {R} of a robot at ``pose`` (telemetry pose: the odom frame)."""
    dx, dy = point[0] - pose[0], point[1] - pose[1]
    c, s = np.cos(pose[2]), np.sin(pose[2])
    return float(c * dx + s * dy), float(-s * dx + c * dy)


def _set_time(rec: rr.RecordingStream, robot_ns: int, cycle: int) -> None:
    """Both timelines for the rows logged next on this thread (Rerun's time is per thread)."""
    rec.reset_time()
    rec.set_time(paths.ROBOT_TIME, duration=np.timedelta64(robot_ns, "ns"))
    rec.set_time(paths.CYCLE, sequence=cycle)


@functools.cache
def _colour_array(colour: tuple[int, int, int]) -> Any:  # a pyarrow.Array (pyarrow is untyped)
    """A colour converted to Arrow once (converting it on every log call costs ~0.1 ms)."""
    return rr.components.ColorBatch(colour).pa_array
