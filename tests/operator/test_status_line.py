"""The status line says why the robot holds or is slowed, and shows the link in numbers."""

from __future__ import annotations

import io
from dataclasses import replace

import pytest
from egc_common.messages import OperatorCommand, StateMessage, Telemetry
from egc_operator.status_line import (
    Status,
    StatusLine,
    format_status,
    link_figures,
    situation,
    status_of,
)

BASE = Status(
    rtt_ms=12.3,
    synchronised=True,
    robot_state="DRIVING",
    reason="fresh centred command",
    w_si=0.9,
    rejected=0,
    mode="shared",
    deadman=True,
    in_control=True,
)

# (state, reason, limiter, extra Status fields, expected situation)
CASES = [
    ("DRIVING", "fresh centred command", "none", {}, "DRIVING"),
    ("DRIVING", "fresh centred command", None, {}, "DRIVING"),
    (
        "DRIVING",
        "fresh centred command",
        "latency",
        {"loop_delay_ms": 1310.0, "v_lim_latency": 0.1},
        "SLOWED: link delay 1.3 s -> speed capped at 0.10 m/s",
    ),
    (
        "DRIVING",
        "fresh centred command",
        "latency",
        {"loop_delay_ms": 830.0, "v_lim_latency": 0.99, "w_lim_latency": 1.06},
        "SLOWED: link delay 0.8 s -> speed capped at 0.99 m/s, turn at 1.06 rad/s",
    ),
    ("DRIVING", "x", "latency", {}, "SLOWED: link delay -> speed capped"),
    ("DRIVING", "x", "egc", {"filter": "egc"}, "SLOWED: obstacle (filter egc)"),
    ("DRIVING", "x", "egc", {"filter": None}, "SLOWED: obstacle (filter egc)"),
    ("DRIVING", "x", "ek-egc", {"filter": "ek-egc"}, "SLOWED: obstacle (filter ek-egc)"),
    ("DRIVING", "x", "assist", {"filter": "assist"}, "SLOWED: obstacle (filter assist)"),
    ("DRIVING", "x", "dwa", {"filter": None}, "SLOWED: obstacle (filter dwa)"),
    ("DRIVING", "x", "sweep", {}, "SLOWED: obstacle next to the footprint (sweep check)"),
    (
        "DRIVING",
        "x",
        "egc",
        {"held_still": True},
        "STOPPED: obstacle too close for this command (filter egc) - ease off or steer away",
    ),
    (
        "DRIVING",
        "x",
        "sweep",
        {"held_still": True},
        "STOPPED: obstacle too close for this command (sweep check) - ease off or steer away",
    ),
    (
        "DRIVING",
        "x",
        "limits",
        {"held_still": True},
        "DRIVING (at the robot's speed/acceleration limits)",
    ),
    (
        "DRIVING",
        "fresh centred command",
        "limits",
        {},
        "DRIVING (at the robot's speed/acceleration limits)",
    ),
    (
        "DRIVING",
        "resumed after a link gap",
        "limits",
        {"episode_s": 0.4},
        "DRIVING: resumed after a link gap, ramping up",
    ),
    (
        "HOLD",
        "command timeout",
        "watchdog",
        {"cmd_gap_max_ms": 410.0},
        "HOLD: link gap (no command for 0.4 s) - keep the stick, it resumes",
    ),
    (
        "HOLD",
        "command timeout",
        "watchdog",
        # the command age counts the uplink delay too: not a gap figure
        {"cmd_gap_max_ms": None, "cmd_age_ms": 380.0},
        "HOLD: link gap - keep the stick, it resumes",
    ),
    (
        "HOLD",
        "command timeout",
        "watchdog",
        {"cmd_gap_max_ms": 2600.0},
        # whether it resumes is the robot's call: it says "waiting for a centred stick"
        "HOLD: link gap (no command for 2.6 s) - keep the stick; the robot says if it needs it"
        " centred",
    ),
    ("HOLD", "command timeout", "watchdog", {}, "HOLD: link gap - keep the stick, it resumes"),
    (
        "HOLD",
        "stale commands",
        "watchdog",
        {"cmd_age_p50_ms": 240.0},
        "HOLD: commands arrive too late (older than the limit, 1000 ms in shared mode)"
        " - keep the stick, it resumes",
    ),
    (
        "HOLD",
        "deadman released",
        "hold",
        {},
        "HOLD: deadman released - hold it and centre the stick to drive",
    ),
    (
        "HOLD",
        "sensor stale",
        "hold",
        {},
        "HOLD: robot's sensor is stale (no fresh scan) - wait, then centre the stick",
    ),
    ("HOLD", "waiting for a centred stick", "hold", {}, "HOLD: centre the stick to drive"),
    ("HOLD", "estop reset", "hold", {}, "HOLD: e-stop reset - centre the stick to drive"),
    (
        "HOLD",
        "resuming after a link gap",
        "limits",
        {},
        "HOLD: resuming after a link gap - keep the stick",
    ),
    (
        "HOLD",
        "operator alice lost",
        "hold",
        {},
        "HOLD: operator alice lost - stopping; hold the deadman, stick centred, to take control",
    ),
    ("HOLD", "something new", "hold", {}, "HOLD: something new"),
    ("HOLD", None, "hold", {}, "HOLD"),
    (
        "ESTOP",
        "estop",
        "estop",
        {},
        "ESTOP: latched - release the e-stop, centre the stick, hold the deadman, reset",
    ),
    (
        "IDLE",
        "no operator",
        "none",
        {},
        "IDLE: no operator - hold the deadman with the stick centred to take control",
    ),
    (
        "IDLE",
        "operator bob silent",
        "none",
        {},
        "IDLE: operator bob silent - hold the deadman with the stick centred to take control",
    ),
    (None, None, None, {}, "robot: no telemetry"),
]


@pytest.mark.parametrize(("state", "reason", "limiter", "extra", "expected"), CASES)
def test_situation_in_words(
    state: str | None,
    reason: str | None,
    limiter: str | None,
    extra: dict[str, object],
    expected: str,
) -> None:
    status = replace(BASE, robot_state=state, reason=reason, limiter=limiter, **extra)  # type: ignore[arg-type]
    assert situation(status) == expected
    assert format_status(status).startswith(expected + " | ")


def test_stale_commands_in_direct_mode_name_the_direct_limit() -> None:
    status = replace(BASE, robot_state="HOLD", reason="stale commands", mode="direct")
    assert "(older than the limit, 300 ms in direct mode)" in situation(status)


def test_link_figures_in_plain_numbers() -> None:
    full = replace(
        BASE,
        cmd_age_p50_ms=210.4,
        cmd_age_p90_ms=262.0,
        cmd_gap_max_ms=40.0,
        link_loss=0.012,
    )
    assert link_figures(full) == (
        "rtt  12.3 ms, cmd age p50/p90 210/262 ms, gap max 40 ms, loss 1.2 %"
    )
    assert link_figures(replace(full, cmd_age_p90_ms=None)).startswith(
        "rtt  12.3 ms, cmd age p50/p90 210/-- ms"
    )
    # an older robot reports none of them: only what the operator measures itself
    assert link_figures(BASE) == "rtt  12.3 ms"
    unknown = replace(BASE, rtt_ms=None, synchronised=False)
    assert link_figures(unknown) == "link -- (clock not synced)"


def test_the_whole_line_keeps_its_order() -> None:
    text = format_status(replace(BASE, link_loss=0.0, in_control=True, deadman=False))
    assert text == (
        "DRIVING | rtt  12.3 ms, loss 0.0 % | w_SI 0.90 | rejected 0 | shared | deadman off"
        " | in control"
    )


def test_a_terminal_line_is_cut_to_the_terminal_width() -> None:
    out = io.StringIO()
    StatusLine(out, tty=True, width=40).show(BASE, 0.0)
    shown = out.getvalue().removeprefix("\r\x1b[2K")
    assert len(shown) == 39 and shown.endswith("~")


def test_plain_lines_follow_the_latency_cap_but_not_a_flickering_filter() -> None:
    out = io.StringIO()
    line = StatusLine(out, tty=False, plain_period_s=5.0)
    line.show(BASE, 0.0)
    line.show(replace(BASE, limiter="egc"), 0.2)  # the filter acts on and off: no new line
    line.show(replace(BASE, limiter="none"), 0.4)
    line.show(replace(BASE, limiter="latency", v_lim_latency=0.1), 0.6)
    lines = out.getvalue().splitlines()
    assert len(lines) == 2 and lines[1].startswith("SLOWED: link delay")


def test_the_line_shows_the_filter_that_runs_and_the_active_via_point() -> None:
    text = format_status(replace(BASE, filter="ek-egc", goal=(2.0, -1.25), goals_left=2))
    assert "| shared (ek-egc) | via 2.0,-1.2 +2 | deadman ON" in text
    assert "| shared | deadman ON" in format_status(replace(BASE, filter="none"))
    last = format_status(replace(BASE, filter="assist", goal=(3.0, 1.0)))
    assert "| shared (assist) | via 3.0,1.0 | deadman ON" in last


def test_plain_lines_follow_a_new_filter_pick_and_via_point() -> None:
    out = io.StringIO()
    line = StatusLine(out, tty=False, plain_period_s=5.0)
    line.show(replace(BASE, filter="egc"), 0.0)
    line.show(replace(BASE, filter="egc"), 0.1)
    line.show(replace(BASE, filter="dwa"), 0.2)
    line.show(replace(BASE, filter="dwa", goal=(1.0, 1.0)), 0.3)
    assert len(out.getvalue().splitlines()) == 3


@pytest.mark.parametrize(
    ("v_ref", "w_ref", "v_cmd", "w_cmd", "held"),
    [
        (2.0, 0.0, 0.0, 0.0, True),  # full stick, nothing sent: the filter holds it still
        (0.0, 0.5, 0.0, 0.0, True),
        (2.0, 0.0, 0.1, 0.2, False),  # slowed, still moving
        (0.0, 0.0, 0.0, 0.0, False),  # centred stick: nothing asked
    ],
)
def test_status_of_knows_when_the_filter_holds_the_robot_still(v_ref, w_ref, v_cmd, w_cmd, held):
    command = OperatorCommand(1, 1, 1.0, 0.0, "shared", True, False, False, "op", 0)
    t = Telemetry(1, 1, "DRIVING", "shared", v_ref, w_ref, v_cmd, w_cmd, 0.0, limiter="egc")
    status = status_of(command, t, None, None, True)
    assert status.held_still is held
    assert situation(replace(status, robot_state="DRIVING")).startswith(
        "STOPPED" if held else "SLOWED"
    )


def test_another_operator_in_control_is_named_instead_of_a_hold_reason():
    """It used to say 'HOLD: centre the stick to drive', which does not help a watcher."""
    watching = replace(BASE, robot_state="HOLD", reason="waiting for a centred stick")
    text = situation(replace(watching, in_control=False, controller="op-2"))
    assert text == "WATCHING: op-2 is in control - you can take over once it quits or is lost"
    assert situation(replace(watching, in_control=True)) == "HOLD: centre the stick to drive"
    # Nobody in control (IDLE): how to take control, not "watching".
    idle = replace(BASE, robot_state="IDLE", reason="", in_control=False, controller=None)
    assert situation(idle).startswith("IDLE: no operator - hold the deadman")


def test_a_silent_robot_is_said_so_and_its_old_figures_are_left_out():
    """A frozen robot process: the line said DRIVING for 2.3 s on stale telemetry, then
    'robot: no telemetry' with the old link figures and 'in control'."""
    command = OperatorCommand(1, 1, 1.0, 0.0, "shared", True, False, False, "op", 0)
    t = Telemetry(1, 1, "DRIVING", "shared", 0.1, 0.0, 0.1, 0.0, 1.0, cmd_age_p50_ms=5.0)
    state = StateMessage(1, "DRIVING", "fresh centred command", "op", 0)
    fresh = status_of(command, t, state, 2.0, True, telemetry_age_s=0.05)
    assert situation(fresh) == "DRIVING" and fresh.in_control is True
    silent = status_of(command, t, state, 2.0, True, telemetry_age_s=1.34)
    assert situation(silent).startswith("NO TELEMETRY for 1.3 s (robot or link silent)")
    line = format_status(silent)
    assert "cmd age" not in line and "in control" not in line
    # the round trip is as old as the silence (the robot answers no clock query): left out
    assert "rtt" not in line and "link --" in line
    gone = status_of(command, t, state, 2.0, True, robot_alive=False, telemetry_age_s=3.0)
    assert situation(gone).startswith(
        "NO TELEMETRY for 3.0 s (robot gone: its session ended or the link dropped)"
    )
    assert status_of(command, None, None, None, False).robot_state is None  # before any contact


def test_via_points_the_robot_did_not_take_are_said_so():
    line = format_status(replace(BASE, via_untaken=True))
    assert "| via points NOT taken by the robot (does the router pass egc/<robot>/goal?) |" in line
    assert "NOT taken" not in format_status(replace(BASE, via_untaken=True, goal=(1.0, 2.0)))


# -- command sources and operator priorities (DESIGN 14) --------------------------------------


def test_a_source_that_drives_and_a_lock_that_holds_are_named():
    nav = replace(BASE, reason="source nav", source="nav", in_control=False, controller=None)
    assert situation(nav) == "DRIVING - source nav drives"
    assert (
        situation(replace(nav, limiter="egc"))
        == "SLOWED: obstacle (filter egc) - source nav drives"
    )
    line = format_status(replace(nav, lock="pause"))
    assert "| source nav | lock pause |" in line
    locked = replace(BASE, robot_state="HOLD", reason="lock hb: silent for 0.62 s", lock="hb")
    assert (
        situation(locked) == "LOCKED by hb (silent for 0.62 s) - nothing drives until it releases"
    )


def test_an_operator_whose_control_a_supervisor_took_is_told_who():
    from egc_operator.status_line import Episode

    command = OperatorCommand(5, 1, 0.0, 0.0, "shared", True, False, False, "alice", 0)
    episode = Episode()
    mine = Telemetry(1, 10, "DRIVING", "shared", 0.0, 0.0, 0.0, 0.0, 1.0, operator="alice")
    taken = Telemetry(1, 20, "HOLD", "shared", 0.0, 0.0, 0.0, 0.0, 1.0, operator="sup")
    episode.update(mine)
    episode.update(taken)
    status = status_of(command, taken, None, 1.0, True, episode=episode)
    assert status.taken_by == "sup"
    assert situation(status) == (
        "TAKEN OVER: sup took control - you can take over once it quits or is lost"
    )
    # Another operator that was merely watching is not told it was taken over.
    bob = OperatorCommand(5, 1, 0.0, 0.0, "shared", True, False, False, "bob", 0)
    assert situation(status_of(bob, taken, None, 1.0, True, episode=episode)).startswith(
        "WATCHING: sup"
    )


def test_a_fleet_operator_s_line_names_the_driven_robot_and_the_others() -> None:
    from egc_operator.status_line import FleetLine

    out = io.StringIO()
    fleet = [FleetLine("rb", "ra HOLD, rc IDLE")]
    line = StatusLine(out, tty=False, fleet=lambda: fleet[0])
    line.show(BASE, 0.0)
    text = out.getvalue()
    assert text.startswith("[rb] DRIVING") and text.rstrip().endswith("| fleet: ra HOLD, rc IDLE")
    line.show(BASE, 0.1)
    assert out.getvalue() == text  # nothing changed: no new plain line
    fleet[0] = FleetLine("rc", "ra HOLD, rb HOLD")  # a switch prints at once
    line.show(BASE, 0.2)
    assert out.getvalue().count("\n") == 2 and "[rc]" in out.getvalue()
    line.say("robots (3; * driven):")
    assert out.getvalue().endswith("robots (3; * driven):\n")
