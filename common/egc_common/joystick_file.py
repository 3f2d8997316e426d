"""The recorded-joystick file format, read by the operator and by sim_robot's replay operator.

A CSV file with a header row. Required columns: ``t_s`` (seconds from the start, non-decreasing),
``x`` (forward deflection) and ``y`` (left deflection), both in [-1, 1]. Optional columns, with
their defaults: ``deadman`` (0/1, default 1), ``mode`` (``direct`` | ``shared``, default
``shared``), ``estop`` (0/1, default 0), ``reset`` (0/1, default 0), ``filter`` (the
operator's pick of shared-mode filter, one of ``egc``, ``ek-egc``, ``assist``, ``dwa``; empty or
absent: no pick, the robot runs its default), ``via_next`` and ``via_clear`` (0/1, default 0:
"button held"; the operator acts on the press, skipping the active via point or clearing them
all), ``robot_next`` and ``robot_prev`` (0/1, default 0: "button held"; an operator driving a
fleet switches to the next or previous robot on the press, DESIGN 15). Blank lines and lines starting with ``#`` are ignored. Between rows the last row holds (zero-order hold); after the
last row the stick is centred with the deadman released.

Any other column, or a column twice, is an error naming it and the accepted columns: a
misspelled ``dead_man`` must not leave the deadman at its default, held. Numbers are plain
ASCII decimals (``egc_common.cli_args.plain_float``); a UTF-8 byte-order mark is accepted; a
file is read with a bound (``MAX_FILE_BYTES``).

    t_s,x,y,deadman,mode,estop
    0.0,0.0,0.0,1,shared,0
    0.5,1.0,0.0,1,shared,0
    4.0,0.6,0.4,1,shared,0
"""

from __future__ import annotations

import bisect
import csv
import io
import math
from dataclasses import dataclass
from pathlib import Path

from egc_common.cli_args import MiB, plain_float, read_input_file
from egc_common.messages import FILTER_NAMES

REQUIRED = ("t_s", "x", "y")
OPTIONAL = {
    "deadman": "1",
    "mode": "shared",
    "estop": "0",
    "reset": "0",
    "filter": "",
    "via_next": "0",
    "via_clear": "0",
    "robot_next": "0",
    "robot_prev": "0",
}
COLUMNS = (*REQUIRED, *OPTIONAL)
# More than any recording needs (about an hour at 50 Hz; parsed, the worst case of short rows
# takes about 160 MB), and a bound on what a device or a wrong file can cost.
MAX_FILE_BYTES = 4 * MiB
# The filters an operator may pick for shared mode ("none" is direct mode: the mode column).
SHARED_FILTERS = tuple(name for name in FILTER_NAMES if name != "none")
_TRUE = {"1", "true", "yes", "on"}
_FALSE = {"0", "false", "no", "off"}


class JoystickFileError(ValueError):
    pass


@dataclass(frozen=True, slots=True)
class JoystickSample:
    t_s: float
    x: float
    y: float
    deadman: bool = True
    mode: str = "shared"
    estop: bool = False
    reset: bool = False
    # The operator's pick of shared-mode filter (DESIGN 6); None: the robot's default.
    filter: str | None = None
    # Via-point buttons, true while held (the operator node acts on the press edge).
    via_next: bool = False
    via_clear: bool = False
    # Fleet buttons (DESIGN 15), true while held: switch to the next / previous robot on the press.
    robot_next: bool = False
    robot_prev: bool = False


RELEASED = JoystickSample(0.0, 0.0, 0.0, deadman=False)


def _flag(text: str, where: str) -> bool:
    t = text.strip().lower()
    if t in _TRUE:
        return True
    if t in _FALSE:
        return False
    raise JoystickFileError(f"{where}: expected 0 or 1, got {text!r}")


def _float(text: str, where: str, lo: float, hi: float) -> float:
    try:
        value = plain_float(text)
    except ValueError:
        raise JoystickFileError(
            f"{where}: expected a number (plain ASCII decimal), got {text!r}"
        ) from None
    if not math.isfinite(value) or not lo <= value <= hi:
        raise JoystickFileError(f"{where}: {value} outside [{lo}, {hi}]")
    return value


def parse_joystick_csv(text: str, name: str = "<joystick file>") -> tuple[JoystickSample, ...]:
    text = text.removeprefix("\ufeff")  # a byte-order mark some editors write
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise JoystickFileError(f"{name}: empty joystick file")
    reader = csv.DictReader(io.StringIO("\n".join(lines)))
    header = [h.strip() for h in (reader.fieldnames or [])]
    reader.fieldnames = header
    accepted = f"(accepted: {', '.join(COLUMNS)})"
    for i, column in enumerate(header):
        if column not in COLUMNS:
            raise JoystickFileError(f"{name}: unknown column {column!r} {accepted}")
        if column in header[:i]:
            raise JoystickFileError(f"{name}: column {column!r} appears twice {accepted}")
    missing = [c for c in REQUIRED if c not in header]
    if missing:
        raise JoystickFileError(f"{name}: header lacks column(s) {', '.join(missing)}")
    samples: list[JoystickSample] = []
    for row_no, row in enumerate(reader, start=2):
        where = f"{name}: row {row_no}"
        if None in row or any(row.get(c) is None for c in header):
            raise JoystickFileError(f"{where}: wrong number of fields")
        values = {
            k: (row.get(k) if row.get(k) not in (None, "") else OPTIONAL.get(k)) for k in header
        }
        for k, default in OPTIONAL.items():
            values.setdefault(k, default)
        t = _float(str(values["t_s"]), f"{where} t_s", 0.0, 1e7)
        if samples and t < samples[-1].t_s:
            raise JoystickFileError(f"{where}: t_s goes backwards")
        mode = str(values["mode"]).strip()
        if mode not in ("direct", "shared"):
            raise JoystickFileError(f"{where}: mode must be direct or shared, got {mode!r}")
        picked = str(values["filter"]).strip()
        if picked and picked not in SHARED_FILTERS:
            hint = " (direct mode is the mode column)" if picked == "none" else ""
            raise JoystickFileError(
                f"{where}: filter must be one of {', '.join(SHARED_FILTERS)} or empty, "
                f"got {picked!r}{hint}"
            )
        samples.append(
            JoystickSample(
                t_s=t,
                x=_float(str(values["x"]), f"{where} x", -1.0, 1.0),
                y=_float(str(values["y"]), f"{where} y", -1.0, 1.0),
                deadman=_flag(str(values["deadman"]), f"{where} deadman"),
                mode=mode,
                estop=_flag(str(values["estop"]), f"{where} estop"),
                reset=_flag(str(values["reset"]), f"{where} reset"),
                filter=picked or None,
                via_next=_flag(str(values["via_next"]), f"{where} via_next"),
                via_clear=_flag(str(values["via_clear"]), f"{where} via_clear"),
                robot_next=_flag(str(values["robot_next"]), f"{where} robot_next"),
                robot_prev=_flag(str(values["robot_prev"]), f"{where} robot_prev"),
            )
        )
    if not samples:
        raise JoystickFileError(f"{name}: no samples after the header")
    return tuple(samples)


def load_joystick_file(path: str | Path) -> tuple[JoystickSample, ...]:
    try:
        text = read_input_file(path, "joystick file", MAX_FILE_BYTES)
    except ValueError as exc:
        raise JoystickFileError(str(exc)) from None
    return parse_joystick_csv(text, str(path))


class JoystickTrack:
    """Zero-order-hold lookup into a parsed file; centred and released after the end."""

    def __init__(self, samples: tuple[JoystickSample, ...]) -> None:
        if not samples:
            raise JoystickFileError("a joystick track needs at least one sample")
        self.samples = samples
        self._times = [s.t_s for s in samples]

    @property
    def duration_s(self) -> float:
        return self._times[-1]

    def at(self, t_s: float) -> JoystickSample:
        if t_s < self._times[0]:
            return RELEASED
        if t_s > self._times[-1]:
            return RELEASED
        return self.samples[bisect.bisect_right(self._times, t_s) - 1]
