"""The operator's one-line terminal status: link round trip, robot state, w_SI, rejections.

On a terminal the line is redrawn in place a few times a second. When stdout is not a TTY
(a log file, a pipe, CI) the same text is printed as plain lines, only when the robot's state
or the control situation changes and otherwise at most every ``plain_period_s``, so logs stay
readable.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TextIO


@dataclass(frozen=True, slots=True)
class Status:
    rtt_ms: float | None
    synchronised: bool
    robot_state: str | None
    reason: str | None
    w_si: float | None
    rejected: int | None
    mode: str
    deadman: bool
    in_control: bool | None


def format_status(s: Status) -> str:
    link = "link --" if s.rtt_ms is None else f"rtt {s.rtt_ms:5.1f} ms"
    if not s.synchronised:
        link += " (clock not synced)"
    if s.robot_state is None:
        robot = "robot: no telemetry"
    else:
        robot = f"robot {s.robot_state}" + (f" ({s.reason})" if s.reason else "")
    w_si = "w_SI  --" if s.w_si is None else f"w_SI {s.w_si:4.2f}"
    rejected = "rejected --" if s.rejected is None else f"rejected {s.rejected}"
    control = {None: "", True: " | in control", False: " | NOT in control"}[s.in_control]
    deadman = "deadman ON" if s.deadman else "deadman off"
    return f"{link} | {robot} | {w_si} | {rejected} | {s.mode} | {deadman}{control}"


class StatusLine:
    def __init__(self, stream: TextIO, tty: bool | None = None, plain_period_s: float = 5.0):
        self._stream = stream
        self._tty = stream.isatty() if tty is None else tty
        self._plain_period_s = plain_period_s
        self._last_key: tuple[object, ...] | None = None
        self._last_plain_s = -1e9

    def show(self, status: Status, now_s: float) -> None:
        text = format_status(status)
        if self._tty:
            self._stream.write("\r\x1b[2K" + text)
            self._stream.flush()
            return
        key = (status.robot_state, status.reason, status.in_control, status.synchronised)
        if key != self._last_key or now_s - self._last_plain_s >= self._plain_period_s:
            self._stream.write(text + "\n")
            self._stream.flush()
            self._last_key = key
            self._last_plain_s = now_s

    def close(self) -> None:
        if self._tty:
            self._stream.write("\n")
            self._stream.flush()
