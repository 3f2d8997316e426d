"""The Rerun recording of ``egc-teleop replay --record FILE.rrd`` (DESIGN 11).

Opened with ``rerun FILE.rrd``, it shows, on the log's own timeline, where the filter would have
stepped in. Timelines: ``bag_time`` (the recorder's receive time of each scan, as a timestamp),
``stamp`` (the scan's header stamp, when set) and ``scan`` (the scan's index). Entities:

- ``robot/scan``: the scan's points in {R} (forward up on screen), ``robot/footprint`` the
  profile's footprint, ``robot/recorded`` (blue) and ``robot/filtered`` (red) arrows to where
  the recorded and the filtered command lead over the horizon kT (paper eq. 6);
- ``robot/circles/{reachable,igc,agc,egc}``: the guide circles of ``egc`` (other filters have
  none in {R}; ``ek-egc``'s live in the ego-kinematic space);
- ``velocity/v/{recorded,filtered}`` (m/s) and ``velocity/w/{recorded,filtered}`` (rad/s);
- ``filter``: a state lane, ``pass`` / ``changed`` / ``hold`` / ``no command``;
- ``events``: one text line where the filter starts and stops holding a moving command.
"""

from __future__ import annotations

import uuid
from datetime import timedelta
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
from egc_common.scan import ObstaclePoints
from egc_operator.view_scene import (
    AGC_VIOLET,
    REACHABLE_GREY,
    REFERENCE_BLUE,
    ROBOT_TO_SCREEN,
    SCAN_INK,
    SENT_RED,
    command_vector,
    footprint_half_size,
    footprint_is_box,
    footprint_outline,
)
from egc_robot.pipeline import PipelineResult
from egc_robot.replay_core import Replayer, ScanVerdict

# Not "log_time": Rerun fills that timeline itself with the wall clock of the logging call.
BAG_TIME = "bag_time"
STAMP = "stamp"
SCAN_INDEX = "scan"
ROBOT = "robot"
SCAN = "robot/scan"
FOOTPRINT = "robot/footprint"
RECORDED_ARROW = "robot/recorded"
FILTERED_ARROW = "robot/filtered"
CIRCLES = ("reachable", "igc", "agc", "egc")
CIRCLE_COLOURS = {
    "reachable": REACHABLE_GREY,
    "igc": REFERENCE_BLUE,
    "agc": AGC_VIOLET,
    "egc": SENT_RED,
}
SERIES = {
    "velocity/v/recorded": ("v recorded (m/s)", REFERENCE_BLUE),
    "velocity/v/filtered": ("v filtered (m/s)", SENT_RED),
    "velocity/w/recorded": ("w recorded (rad/s)", REFERENCE_BLUE),
    "velocity/w/filtered": ("w filtered (rad/s)", SENT_RED),
}
FILTER_LANE = "filter"
EVENTS = "events"
LANE_STATES = {
    "pass": (40, 170, 70),
    "changed": (235, 150, 0),
    "hold": (220, 30, 30),
    "no command": (190, 190, 190),
}
# One chunk per second of logging, as the operator view's saved files do.
FILE_BATCHER = rr.ChunkBatcherConfig(flush_tick=timedelta(seconds=1))


def circle_path(name: str) -> str:
    return f"{ROBOT}/circles/{name}"


def _blueprint(title: str) -> rrb.Blueprint:
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial2DView(
                name=f"{title}: scan, forward up", origin="/", contents=f"{ROBOT}/**"
            ),
            rrb.Vertical(
                rrb.TimeSeriesView(
                    name="v (m/s): recorded blue, filtered red", origin="velocity/v"
                ),
                rrb.TimeSeriesView(
                    name="w (rad/s): recorded blue, filtered red", origin="velocity/w"
                ),
                rrb.StateTimelineView(name="filter: pass / changed / hold", origin=FILTER_LANE),
                rrb.TextLogView(name="where the filter held", origin=EVENTS),
                row_shares=[3, 3, 1, 2],
            ),
            column_shares=[3, 2],
        ),
        rrb.TimePanel(timeline=BAG_TIME, state="expanded"),
        collapse_panels=True,
    )


class ReplayRecording:
    """Logs each replayed scan to a .rrd file; ``close`` leaves the file complete."""

    def __init__(
        self, path: str | Path, title: str, replayer: Replayer, scan_topic: str, cmd_topic: str
    ) -> None:
        self.path = Path(path)
        self._horizon_s = replayer.config.egc_params.horizon_s
        self._filter = replayer.config.filter
        self._index = 0
        self._lane: str | None = None
        rec = rr.RecordingStream(
            "egc-replay", recording_id=uuid.uuid4(), batcher_config=FILE_BATCHER
        )
        rec.save(self.path, default_blueprint=_blueprint(title))
        rec.send_recording_name(
            f"replay of {title}: {self._filter}, {replayer.config.profile.name}"
        )
        rec.send_property(
            "replay",
            rr.AnyValues(
                log=title,
                filter=self._filter,
                profile=replayer.config.profile.name,
                scan_topic=scan_topic,
                command_topic=cmd_topic,
            ),
        )
        rec.log(ROBOT, rr.Transform3D(mat3x3=ROBOT_TO_SCREEN), static=True)
        rec.log(SCAN, rr.Points2D.from_fields(radii=0.02, colors=SCAN_INK), static=True)
        profile = replayer.config.profile
        rec.log(
            FOOTPRINT,
            rr.Boxes2D(half_sizes=[footprint_half_size(profile)], colors=(120, 120, 120))
            if footprint_is_box(profile)
            else rr.LineStrips2D([footprint_outline(profile)], colors=(120, 120, 120)),
            static=True,
        )
        for name in CIRCLES:
            rec.log(
                circle_path(name),
                rr.Ellipses2D.from_fields(colors=CIRCLE_COLOURS[name]),
                static=True,
            )
        for path, colour in ((RECORDED_ARROW, REFERENCE_BLUE), (FILTERED_ARROW, SENT_RED)):
            rec.log(path, rr.Arrows2D.from_fields(origins=[(0.0, 0.0)], colors=colour), static=True)
        for path, (label, colour) in SERIES.items():
            rec.log(path, rr.SeriesLines(names=[label], colors=[colour], widths=[1.5]), static=True)
        rec.log(
            FILTER_LANE,
            rr.StateConfiguration(values=list(LANE_STATES), colors=list(LANE_STATES.values())),
            static=True,
        )
        self._rec: rr.RecordingStream | None = rec

    def on_scan(
        self, verdict: ScanVerdict, result: PipelineResult | None, obstacles: ObstaclePoints
    ) -> None:
        """One scan: its points, circles, arrows, both velocities and the lane."""
        rec = self._rec
        if rec is None:
            return
        rec.reset_time()
        rec.set_time(BAG_TIME, timestamp=np.datetime64(verdict.log_ns, "ns"))
        if verdict.stamp_ns > 0:
            rec.set_time(STAMP, timestamp=np.datetime64(verdict.stamp_ns, "ns"))
        rec.set_time(SCAN_INDEX, sequence=self._index)
        self._index += 1
        rec.log(SCAN, rr.Points2D(obstacles.xy.astype(np.float32)))
        self._log_circles(rec, result)
        if verdict.has_command:
            ref = command_vector(verdict.v_ref_mps, verdict.w_ref_radps, self._horizon_s)
            cmd = command_vector(verdict.v_cmd_mps, verdict.w_cmd_radps, self._horizon_s)
            rec.log(RECORDED_ARROW, rr.Arrows2D(vectors=[ref]))
            rec.log(FILTERED_ARROW, rr.Arrows2D(vectors=[cmd]))
            for path, value in (
                ("velocity/v/recorded", verdict.v_ref_mps),
                ("velocity/v/filtered", verdict.v_cmd_mps),
                ("velocity/w/recorded", verdict.w_ref_radps),
                ("velocity/w/filtered", verdict.w_cmd_radps),
            ):
                rec.log(path, rr.Scalars(value))
        else:
            rec.log(RECORDED_ARROW, rr.Arrows2D(vectors=[]))
            rec.log(FILTERED_ARROW, rr.Arrows2D(vectors=[]))
        lane = _lane(verdict)
        if lane != self._lane:
            rec.log(FILTER_LANE, rr.StateChange(state=lane))
            if lane == "hold":
                near = (
                    ""
                    if verdict.closest_m is None
                    else f", nearest reading {verdict.closest_m:.2f} m"
                )
                text = (
                    f"{self._filter} holds: recorded v {verdict.v_ref_mps:.2f} m/s, "
                    f"w {verdict.w_ref_radps:.2f} rad/s -> v {verdict.v_cmd_mps:.2f}, "
                    f"w {verdict.w_cmd_radps:.2f} (limited by {verdict.limiter}){near}"
                )
                rec.log(EVENTS, rr.TextLog(text, level="WARN"))
            elif self._lane == "hold":
                rec.log(
                    EVENTS, rr.TextLog(f"{self._filter} lets the command move again", level="INFO")
                )
            self._lane = lane

    def _log_circles(self, rec: rr.RecordingStream, result: PipelineResult | None) -> None:
        circles = _egc_circles(result) if self._filter == "egc" else {}
        for name in CIRCLES:
            c = circles.get(name)
            drawn = [] if c is None else [c]
            rec.log(
                circle_path(name),
                rr.Ellipses2D(
                    centers=[x[:2] for x in drawn], half_sizes=[(x[2], x[2]) for x in drawn]
                ),
            )

    def close(self) -> None:
        """Flush and close the file."""
        rec, self._rec = self._rec, None
        if rec is not None:
            rec.flush()
            rec.disconnect()


def _lane(verdict: ScanVerdict) -> str:
    if not verdict.has_command:
        return "no command"
    if verdict.held:
        return "hold"
    return "changed" if verdict.changed else "pass"


def _egc_circles(result: PipelineResult | None) -> dict[str, tuple[float, float, float]]:
    """The EGC intermediates of a pipeline result that has them, as drawable (x, y, r)."""
    if result is None or result.filtered is None:
        return {}
    egc = result.filtered
    if not hasattr(egc, "igc"):  # the family's FilterResult carries them under .egc
        egc = getattr(egc, "egc", None)
        if egc is None:
            return {}
    out: dict[str, tuple[float, float, float]] = {}
    candidates = {
        "reachable": (0.0, 0.0, egc.r_rc_m),
        "igc": egc.igc,
        "agc": egc.agc,
        "egc": egc.egc,
    }
    for name, c in candidates.items():
        if c is not None and all(np.isfinite(c)) and c[2] > 0.0:
            out[name] = (float(c[0]), float(c[1]), float(c[2]))
    return out
