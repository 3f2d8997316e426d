"""The status line's numbers say what happened (outside check of the link-aware view).

- A HOLD's number contradicted its reason: 'commands arrive too late (193 ms old, limit 1000 ms)'
  (the p50 of the *accepted* commands, below the limit by definition) while the robot rejected
  ones 1081 ms old; 'link gap (no command for 0.1 s)' after a 1.2 s outage (the window's gap
  once the queued commands came in as a burst).
- 'DRIVING: resumed after a link gap, ramping up' stayed up to 10 s (the robot keeps the reason).
- A restarted robot's line showed the old robot's 'DRIVING ... in control' (the state message
  lags the telemetry by up to a second).
"""

from __future__ import annotations

import egc_operator.status_line as sl
from egc_common.messages import OperatorCommand, StateMessage, Telemetry
from egc_operator.status_line import format_status, situation, status_of

MS = 1_000_000
COMMAND = OperatorCommand(1, 1, 1.0, 0.0, "shared", True, False, False, "op", 0)


def _t(k: int, state: str, reason: str, v_cmd: float = 0.3, **extra: object) -> Telemetry:
    values: dict[str, object] = {"reason": reason, "operator": "op"}
    values.update(extra)
    return Telemetry(
        k, 10_000 * MS + k * 50 * MS, state, "shared", 0.3, 0.0, v_cmd, 0.0, 1.0, **values
    )  # type: ignore[arg-type]


def _line(t: Telemetry, episode: sl.Episode, state: StateMessage | None = None) -> str:
    return situation(status_of(COMMAND, t, state, 300.0, True, True, 0.05, episode))


def test_a_link_gap_hold_names_the_gap_that_tripped_it_not_the_burst_after_it() -> None:
    episode = sl.Episode()
    frames = [_t(0, "DRIVING", "fresh centred command", cmd_gap_max_ms=20.0)]
    # an outage: the open gap grows in the robot's figures ...
    frames += [
        _t(k, "HOLD", "command timeout", cmd_gap_max_ms=250.0 + 50 * k) for k in range(1, 20)
    ]
    # ... then the queued commands arrive as a burst: the window's gap is 0.1 s
    frames += [_t(20, "HOLD", "command timeout", cmd_gap_max_ms=100.0)]
    for t in frames:
        episode.update(t)
    assert _line(frames[-1], episode) == (
        "HOLD: link gap (no command for 1.2 s) - keep the stick, it resumes"
    )
    # a gap below the watchdog's 250 ms cannot have tripped it: no number rather than that one
    fresh = sl.Episode()
    fresh.update(frames[-1])
    assert _line(frames[-1], fresh) == "HOLD: link gap - keep the stick, it resumes"


def test_a_stale_commands_hold_shows_no_age_of_the_accepted_ones() -> None:
    episode = sl.Episode()
    t = _t(1, "HOLD", "stale commands", cmd_age_p50_ms=193.0, cmd_age_p90_ms=240.0)
    episode.update(t)
    text = _line(t, episode)
    assert text == (
        "HOLD: commands arrive too late (older than the limit, 1000 ms in shared mode)"
        " - keep the stick, it resumes"
    )
    assert "193" not in text and "240" not in text


def test_ramping_up_is_said_only_just_after_the_resume() -> None:
    episode = sl.Episode()
    seen = []
    for k in range(200):  # 10 s driving on with the reason kept, the base ramping up for 1 s
        v = min(0.3, 0.015 * k)
        t = _t(k, "DRIVING", "resumed after a link gap", limiter="none", v_cmd=v)
        episode.update(t)
        seen.append(_line(t, episode))
    assert seen[0] == "DRIVING: resumed after a link gap, ramping up"
    assert seen[int(0.9 / 0.05)] == "DRIVING: resumed after a link gap, ramping up"
    # the speed reached its reference at 1 s: the ramp is over
    assert set(seen[int(1.0 / 0.05) :]) == {"DRIVING"}


def test_a_later_acceleration_limit_is_not_called_the_resume_s_ramp() -> None:
    """Outside check: 'resumed after a link gap, ramping up' stayed up to 3 s while the limiter
    was ``limits``, which may be an acceleration after an EGC slowdown, not the resume."""
    limited = sl.Episode()
    texts = []
    for k in range(100):  # never at its reference: still at most RAMP_SHOWN_S
        t = _t(k, "DRIVING", "resumed after a link gap", limiter="limits", v_cmd=0.1)
        limited.update(t)
        texts.append(_line(t, limited))
    assert texts[int(1.4 / 0.05)] == "DRIVING: resumed after a link gap, ramping up"
    assert texts[int(1.6 / 0.05)] == "DRIVING (at the robot's speed/acceleration limits)"
    assert texts[int(2.5 / 0.05)] == "DRIVING (at the robot's speed/acceleration limits)"
    # ramped up, slowed by the filter, then accelerating at the limit again: not the resume
    again = sl.Episode()
    frames = [_t(0, "DRIVING", "resumed after a link gap", v_cmd=0.0, limiter="limits")]
    frames += [_t(4, "DRIVING", "resumed after a link gap", v_cmd=0.3, limiter="none")]
    frames += [_t(8, "DRIVING", "resumed after a link gap", v_cmd=0.05, limiter="egc")]
    frames += [_t(12, "DRIVING", "resumed after a link gap", v_cmd=0.1, limiter="limits")]
    for t in frames:
        again.update(t)
    assert _line(frames[-1], again) == "DRIVING (at the robot's speed/acceleration limits)"


def test_a_link_gap_hold_names_no_command_age_and_never_says_centre_on_its_own() -> None:
    """Outside check at 800 ms one way: a 1.5 s outage showed 'link gap (no command for 2.1 s) -
    centre the stick to drive again | ... gap max 1307 ms' (the command age, which counts the
    uplink delay) while the robot resumed on its own."""
    episode = sl.Episode()
    t = _t(1, "HOLD", "command timeout", cmd_gap_max_ms=1307.0, cmd_age_ms=2107.0)
    episode.update(t)
    text = _line(t, episode)
    assert text == "HOLD: link gap (no command for 1.3 s) - keep the stick, it resumes"
    assert "2.1" not in text
    # a gap longer than the resume window: the robot decides, and says so in its reason
    long = _t(2, "HOLD", "command timeout", cmd_gap_max_ms=2600.0, cmd_age_ms=3400.0)
    episode.update(long)
    assert "centre the stick" not in _line(long, episode)
    wants = _t(3, "HOLD", "waiting for a centred stick")
    episode.update(wants)
    assert _line(wants, episode) == "HOLD: centre the stick to drive"


def test_the_rejected_count_is_the_newest_one() -> None:
    """Outside check: a stale-commands HOLD taken from newer telemetry showed 'rejected 0' from
    the older state message while the robot had rejected commands."""
    older = StateMessage(9_000 * MS, "DRIVING", "fresh centred command", "op", 0)
    t = _t(1, "HOLD", "stale commands", rejected=12)
    status = status_of(COMMAND, t, older, 300.0, True, True, 0.05)
    assert status.reason == "stale commands" and status.rejected == 12
    assert "rejected 12" in format_status(status)
    # a state message newer than the telemetry: its own (newer) count
    newer = StateMessage(20_000 * MS, "HOLD", "stale commands", "op", 15)
    assert status_of(COMMAND, t, newer, 300.0, True, True, 0.05).rejected == 15


def test_newer_telemetry_says_the_state_when_the_state_message_lags() -> None:
    """A restarted robot: IDLE in its telemetry, the old robot's DRIVING in the last state."""
    old = StateMessage(9_000 * MS, "DRIVING", "fresh centred command", "op", 0)
    t = _t(1, "IDLE", "no operator", operator=None)
    status = status_of(COMMAND, t, old, 300.0, True, True, 0.05)
    assert status.robot_state == "IDLE" and status.in_control is False
    assert "in control" not in format_status(status).replace("NOT in control", "")
    # no state message at all (cleared when the robot came back): the telemetry says it
    status = status_of(COMMAND, _t(2, "HOLD", "waiting for a centred stick"), None, 300.0, True)
    assert status.robot_state == "HOLD" and status.in_control is True


def test_a_robot_gone_shows_none_of_its_figures_at_once() -> None:
    """Its liveliness token withdrawn: the rtt and command ages were shown another 0.6 s."""
    t = _t(1, "DRIVING", "fresh centred command", cmd_age_p50_ms=150.0, cmd_gap_max_ms=30.0)
    state = StateMessage(t.stamp_ns, "DRIVING", "fresh centred command", "op", 0)
    gone = status_of(COMMAND, t, state, 300.0, True, robot_alive=False, telemetry_age_s=0.05)
    assert situation(gone).startswith(
        "NO TELEMETRY for 0.1 s (robot gone: its session ended or the link dropped)"
    )
    line = format_status(gone)
    assert "rtt" not in line and "cmd age" not in line and "gap max" not in line
    assert "in control" not in line


def test_a_robot_not_seen_yet_is_not_called_gone() -> None:
    waiting = status_of(COMMAND, None, None, None, False, robot_alive=False)
    assert situation(waiting) == "robot: not seen yet (waiting for its liveliness token)"
