"""Command sources (joystick file, built-in scripts) and the status line."""

from __future__ import annotations

import io

import pytest
from egc_common.joystick_file import JoystickTrack, parse_joystick_csv
from egc_operator.command_source import TrackSource, load_script, script_names
from egc_operator.status_line import Status, StatusLine, format_status

TRACK = JoystickTrack(parse_joystick_csv("t_s,x,y,deadman\n0,0,0,1\n1,1,0.5,1\n2,1,0.5,1\n"))


def test_track_source_holds_then_releases_at_the_end():
    src = TrackSource(TRACK)
    assert src.sample(0.5).x == 0.0
    assert src.sample(1.5).y == 0.5
    end = src.sample(2.5)
    assert (end.x, end.deadman, src.finished) == (0.0, False, True)


def test_track_source_loops():
    src = TrackSource(TRACK, loop=True)
    assert src.sample(4.5).x == 0.0 and src.sample(5.5).x == 1.0
    assert not src.finished


def test_builtin_demo_script_starts_centred_with_the_deadman_and_ends_released():
    assert "demo" in script_names()
    track = load_script("demo")
    first, last = track.samples[0], track.samples[-1]
    assert (first.x, first.y, first.deadman) == (0.0, 0.0, True)
    assert not last.deadman
    with pytest.raises(ValueError, match="known: demo"):
        load_script("nope")


STATUS = Status(0.42, True, "DRIVING", "fresh centred command", 0.83, 2, "shared", True, True)


def test_status_text():
    text = format_status(STATUS)
    for part in ("DRIVING |", "rtt   0.4 ms", "w_SI 0.83", "rejected 2", "in control"):
        assert part in text


def test_tty_redraws_in_place():
    out = io.StringIO()
    line = StatusLine(out, tty=True)
    line.show(STATUS, 0.0)
    line.show(STATUS, 0.2)
    assert out.getvalue().count("\r\x1b[2K") == 2 and "\n" not in out.getvalue()


def test_not_a_tty_prints_plain_lines_on_change_or_every_few_seconds():
    out = io.StringIO()
    line = StatusLine(out, tty=False, plain_period_s=5.0)
    line.show(STATUS, 0.0)
    line.show(STATUS, 1.0)  # unchanged, too soon: nothing
    held = Status(0.4, True, "HOLD", "command timeout", 0.0, 2, "shared", True, True)
    line.show(held, 1.2)
    line.show(held, 7.0)
    lines = out.getvalue().splitlines()
    assert len(lines) == 3 and "\r" not in out.getvalue()
    assert lines[1].startswith("HOLD: link gap - keep the stick, it resumes")
