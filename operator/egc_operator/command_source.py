"""Where the operator's stick samples come from: a joystick file, a built-in script, or evdev.

Every source answers ``sample(t_s)`` with an ``egc_common.joystick_file.JoystickSample``
(x forward and y left in [-1, 1], deadman, mode, estop, reset) for the time since the operator
started, and says when it is ``finished``.

The joystick file format is ``egc_common.joystick_file`` (shared with sim_robot's replay
operator): a CSV with a header, required columns ``t_s,x,y`` and optional ``deadman`` (default
1), ``mode`` (``direct``|``shared``, default shared), ``estop`` and ``reset`` (default 0);
``#`` comments; zero-order hold between rows; after the last row the stick is centred with the
deadman released. Built-in scripts are such files shipped in ``egc_operator/scripts/``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Protocol

from egc_common.joystick_file import (
    RELEASED,
    JoystickSample,
    JoystickTrack,
    load_joystick_file,
    parse_joystick_csv,
)


class CommandSource(Protocol):
    def sample(self, t_s: float) -> JoystickSample: ...

    @property
    def finished(self) -> bool: ...

    def close(self) -> None: ...


class TrackSource:
    """Replays a recorded track; with ``loop`` it starts over at the end, forever.

    A looped track of duration 0 (one row, or all rows at the same ``t_s``) holds its last
    sample until the operator stops: there is nothing to start over, and ``--loop`` promises
    to repeat, not to release the deadman after one sample.
    """

    def __init__(self, track: JoystickTrack, loop: bool = False) -> None:
        self._track = track
        self._loop = loop
        self._finished = False

    def sample(self, t_s: float) -> JoystickSample:
        duration = self._track.duration_s
        if self._loop:
            if duration > 0:
                t_s %= duration
            else:
                t_s = min(t_s, duration)  # hold the one instant there is
        elif t_s > duration:
            self._finished = True
            return RELEASED
        return self._track.at(t_s)

    @property
    def finished(self) -> bool:
        return self._finished

    def close(self) -> None:
        pass


SCRIPTS_DIR = Path(__file__).resolve().parent / "scripts"  # package data (pyproject)


def script_names() -> list[str]:
    """Names of the built-in scripts (``scripts/<name>.csv``)."""
    return sorted(p.stem for p in SCRIPTS_DIR.glob("*.csv"))


def load_script(name: str) -> JoystickTrack:
    """A built-in script by name; ValueError names the known ones."""
    if name not in script_names():
        raise ValueError(f"unknown script {name!r} (known: {', '.join(script_names())})")
    text = (SCRIPTS_DIR / f"{name}.csv").read_text(encoding="utf-8")
    return JoystickTrack(parse_joystick_csv(text, f"script {name}"))


def load_file(path: str | Path) -> JoystickTrack:
    return JoystickTrack(load_joystick_file(path))
