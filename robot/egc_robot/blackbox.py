"""The robot's black box: a Rerun recording of everything that reached or left the robot.

``egc-teleop robot --record FILE.rrd`` keeps one. Logged, each as one row:

- ``commands``: every command received, accepted or rejected (``accepted``, ``bytes``, the
  ``reason`` of a rejection, and the decoded fields when the payload decodes); rejections also
  go to ``log``;
- ``base/cmd``: every velocity command sent to the base, as the scalars (v, w);
- ``robot/scan``: every Nth scan (``scan_decimation``): valid points in {R} plus the raw
  ranges and angles;
- ``state``: every state message (also a line in ``log``).

Timelines: ``robot_time`` (a duration, the robot's monotonic clock, the same clock as
``Telemetry.stamp_ns``) on every row, and ``cycle`` (a sequence, ``BaseCommand.seq``, the same
counter as ``Telemetry.cycle``) on base commands, so the black box lines up with the operator's
recording. ``counts()`` says how many rows each stream got; the file holds exactly those once
``close()`` returns (Rerun's file sink does not drop).
"""

from __future__ import annotations

import threading
import uuid
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa  # type: ignore[import-untyped]
import rerun as rr
import rerun.blueprint as rrb
from egc_common.messages import (
    BaseCommand,
    OperatorCommand,
    Rejection,
    StateMessage,
    decode_command,
)
from egc_common.scan import Scan

ROBOT_TIME = "robot_time"
CYCLE = "cycle"
COMMANDS = "commands"
BASE_CMD = "base/cmd"
ROBOT = "robot"
SCAN = "robot/scan"
STATE = "state"
LOG = "log"
# Rerun's 2D views put +y down: show {R} with forward up, left to the left (screen = (-y, -x)).
ROBOT_TO_SCREEN = ((0.0, -1.0, 0.0), (-1.0, 0.0, 0.0), (0.0, 0.0, 1.0))
STATE_LEVELS = {"IDLE": "INFO", "DRIVING": "INFO", "HOLD": "WARN", "ESTOP": "ERROR"}
# The same lane colours as the operator view's state lane.
STATE_COLOURS = {
    "IDLE": (190, 190, 190),
    "DRIVING": (40, 170, 70),
    "HOLD": (235, 150, 0),
    "ESTOP": (220, 30, 30),
}


def _blueprint(robot_id: str) -> rrb.Blueprint:
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Spatial2DView(
                    name=f"{robot_id}: scans (forward up)", origin="/", contents=f"{ROBOT}/**"
                ),
                rrb.StateTimelineView(name="state", origin=STATE),
                row_shares=[3, 1],
            ),
            rrb.Vertical(
                rrb.TimeSeriesView(name="sent to the base: v (m/s), w (rad/s)", origin=BASE_CMD),
                rrb.TextLogView(name="rejections and state changes", origin=LOG),
                rrb.DataframeView(name="commands received", origin=COMMANDS),
            ),
        ),
        rrb.TimePanel(timeline=ROBOT_TIME, state="collapsed"),
        collapse_panels=True,
    )


class BlackBox:
    """Thread-safe recorder; every ``on_*`` call is one row of its stream (scans: every Nth)."""

    def __init__(self, path: str | Path, robot_id: str, scan_decimation: int = 1) -> None:
        if scan_decimation < 1:
            raise ValueError("scan decimation must be >= 1 (1 keeps every scan)")
        self.path = Path(path)
        self.scan_decimation = scan_decimation
        self._lock = threading.Lock()
        self._counts: Counter[str] = Counter()
        self._scans_seen = 0
        self.path.parent.mkdir(parents=True, exist_ok=True)
        rec = rr.RecordingStream("egc-robot-blackbox", recording_id=uuid.uuid4())
        rec.save(self.path, default_blueprint=_blueprint(robot_id))
        rec.send_recording_name(f"{robot_id}: black box")
        rec.send_property("robot", rr.AnyValues(robot_id=robot_id, scan_decimation=scan_decimation))
        rec.log(ROBOT, rr.Transform3D(mat3x3=ROBOT_TO_SCREEN), static=True)
        rec.log(
            STATE,
            rr.StateConfiguration(values=list(STATE_COLOURS), colors=list(STATE_COLOURS.values())),
            static=True,
        )
        rec.log(
            BASE_CMD,
            rr.SeriesLines(names=["v (m/s)", "w (rad/s)"], colors=[(220, 40, 40), (40, 40, 200)]),
            static=True,
        )
        self._rec: rr.RecordingStream | None = rec

    def on_command(
        self, raw_payload: bytes, accepted: bool, reason: str | None, now_ns: int
    ) -> None:
        """A command as received (``now_ns`` on the robot's clock), with the robot's verdict."""
        decoded = decode_command(raw_payload)
        fields = _command_fields(decoded) if isinstance(decoded, OperatorCommand) else {}
        values: dict[str, Any] = {"accepted": accepted, "bytes": len(raw_payload), **fields}
        if not accepted:  # without a reason from the caller: the decoder's, or a generic one
            fallback = str(decoded) if isinstance(decoded, Rejection) else "rejected"
            values["reason"] = reason or fallback
        with self._lock:
            if self._rec is None:
                return
            self._set_time(now_ns)
            # Arrow arrays built here halve the cost of letting AnyValues infer each type.
            self._rec.log(COMMANDS, rr.AnyValues(**{k: pa.array([v]) for k, v in values.items()}))
            self._counts["commands"] += 1
            if not accepted:
                who = f" from {fields['op']} seq {fields['seq']}" if fields else ""
                text = f"command rejected{who}: {values['reason']}"
                self._rec.log(LOG, rr.TextLog(text, level="WARN"))
                self._counts["commands_rejected"] += 1
                self._counts["log"] += 1

    def on_base_command(self, cmd: BaseCommand) -> None:
        """A velocity command sent to the base; ``cmd.seq`` is the control cycle."""
        with self._lock:
            if self._rec is None:
                return
            self._set_time(cmd.stamp_ns, cycle=cmd.seq)
            self._rec.log(BASE_CMD, rr.Scalars([cmd.linear_mps, cmd.angular_radps]))
            self._counts["base_commands"] += 1

    def on_scan(self, scan: Scan, now_ns: int) -> None:
        """A scan as it reached the robot; every ``scan_decimation``-th one is logged."""
        with self._lock:
            if self._rec is None:
                return
            self._scans_seen += 1
            self._counts["scans_received"] += 1
            if (self._scans_seen - 1) % self.scan_decimation:
                return
            self._set_time(now_ns)
            self._rec.log(
                SCAN,
                rr.Points2D(scan.points().astype(np.float32), radii=0.02, colors=(40, 40, 60)),
                rr.AnyValues(
                    ranges_m=scan.ranges_m.astype(np.float32),
                    angles_rad=scan.angles_rad.astype(np.float32),
                    range_min_m=scan.range_min_m,
                    range_max_m=scan.range_max_m,
                    stamp_ns=scan.stamp_ns,
                ),
            )
            self._counts["scans"] += 1

    def on_state(self, s: StateMessage) -> None:
        """A state message: the state lane and a line in the log."""
        with self._lock:
            if self._rec is None:
                return
            self._set_time(s.stamp_ns)
            self._rec.log(STATE, rr.StateChange(state=s.state))
            who = f" (operator {s.operator})" if s.operator else ""
            text = f"state {s.state}: {s.reason}{who}; {s.rejected} rejected so far"
            self._rec.log(LOG, rr.TextLog(text, level=STATE_LEVELS.get(s.state, "INFO")))
            self._counts["states"] += 1
            self._counts["log"] += 1

    def counts(self) -> dict[str, int]:
        """Rows logged per stream: commands, commands_rejected, base_commands, scans_received,
        scans, states, log."""
        with self._lock:
            keys = (
                "commands",
                "commands_rejected",
                "base_commands",
                "scans_received",
                "scans",
                "states",
                "log",
            )
            return {k: self._counts[k] for k in keys}

    def close(self) -> None:
        """Flush and close the file; it is complete and readable afterwards."""
        with self._lock:
            rec, self._rec = self._rec, None
        if rec is not None:
            rec.flush()
            rec.disconnect()

    def _set_time(self, robot_ns: int, cycle: int | None = None) -> None:
        assert self._rec is not None
        self._rec.reset_time()
        self._rec.set_time(ROBOT_TIME, duration=np.timedelta64(robot_ns, "ns"))
        if cycle is not None:
            self._rec.set_time(CYCLE, sequence=cycle)


def _command_fields(cmd: OperatorCommand) -> dict[str, Any]:
    return {
        "seq": cmd.seq,
        "stamp_ns": cmd.stamp_ns,
        "x": cmd.x,
        "y": cmd.y,
        "mode": cmd.mode,
        "deadman": cmd.deadman,
        "estop": cmd.estop,
        "reset": cmd.reset,
        "op": cmd.op,
    }
