"""``egc-teleop replay``: which command a scan is replayed with (an outside check).

A Twist is in effect for ``--cmd-timeout-s`` (default 0.5 s) after it was received, as a base
stops when ``cmd_vel`` falls silent (DESIGN 11's simulated base after 0.5 s); before, a log
whose commands stopped at 1 s replayed five more seconds of scans with that last command, and
counted the filter stopping it as hold time. Damaged command records are skipped and counted.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from egc_robot.replay_core import (
    COMMAND_MAX_AGE_S,
    CommandTrack,
    Pose2D,
    VelocitySample,
    pose_fault,
    velocity_fault,
)

from tests.cli_worker import main
from tests.replay.logs import TS, T, corridor_log

S = 1_000_000_000
SCANS = 60
WALLS = tuple(np.linspace(2.5, 0.3, SCANS))
UNTIL = 10  # commands with scans 0-9 only (t = 0.0-0.9 s), scans until t = 5.9 s

# Command lines run in one long-lived CLI process (``tests.cli_worker``): these tests are about
# what ``egc-teleop replay`` prints, writes and returns; the ones about a process of its own
# start ``python -m egc_app.cli`` (``test_a_real_process_*``, ``*_in_a_real_process_*``).


def replay(capsys, *args: str) -> tuple[int, dict | None, str]:
    code = main(["replay", *args])
    out, err = capsys.readouterr()
    return code, (json.loads(out) if code == 0 else None), err


def silent_after(i: int) -> dict[int, bytes | None]:
    return {k: None for k in range(i, SCANS)}


def test_track_max_age_boundary():
    track = CommandTrack.of([VelocitySample(S, 0.3, 0.1)], COMMAND_MAX_AGE_S)
    assert track.at(S - 1) is None and not track.stale_at(S - 1)  # before any command
    assert track.at(S) is not None and track.at(S + S // 2) is not None  # 0.5 s old: in effect
    assert track.at(S + S // 2 + 1) is None and track.stale_at(S + S // 2 + 1)
    assert track.latest(10 * S) == VelocitySample(S, 0.3, 0.1)
    forever = CommandTrack.of([VelocitySample(S, 0.3, 0.1)], math.inf)
    assert forever.max_age_ns is None and forever.at(1000 * S) is not None
    assert not forever.stale_at(1000 * S)


def test_velocity_and_pose_faults():
    assert velocity_fault(0.5, -1.2) is None and velocity_fault(-3.0, 0.0) is None
    assert velocity_fault(math.nan, 0.0) == "linear.x nan"
    assert velocity_fault(0.0, math.inf) == "angular.z inf"
    assert velocity_fault(3e38, 0.0) == "linear.x 3e+38"
    assert pose_fault(Pose2D(0, 0, 12.0, -400.0, 3.0)) is None
    assert pose_fault(Pose2D(0, 0, math.nan, 0.0, 0.0)) == "pose x nan"
    assert pose_fault(Pose2D(0, 0, 0.0, 2e30, 0.0)) == "pose y 2e+30"
    assert pose_fault(Pose2D(0, 0, 0.0, 0.0, math.inf)) == "pose yaw inf"


@pytest.mark.parametrize("command", ["twist", "twist-stamped"])
def test_a_command_older_than_the_timeout_is_not_paired(tmp_path, capsys, command):
    log = corridor_log(
        tmp_path / "log", "mcap", WALLS, command=command, command_at=silent_after(UNTIL)
    )
    code, s, err = replay(capsys, str(log))
    assert code == 0
    # the last command came 1 us before scan 9; scans 10-13 are up to 0.4 s after it, scan 14
    # 0.5 s + 1 us: from there on the base would have stopped
    assert s["commands"] == 14 and s["command_messages"] == UNTIL
    assert s["scans_without_command"] == s["scans_command_stale"] == SCANS - 14
    assert s["command_max_age_s"] == 0.5
    assert s["moving_s"] == pytest.approx(1.4)
    assert err.splitlines() == [
        f"egc-teleop replay: 46 of {SCANS} scans came over 0.5 s after the latest message on "
        "'/cmd_vel' (the first at t = 1.4 s): replayed without a command, as a base stops "
        "when cmd_vel falls silent (--cmd-timeout-s sets how long)"
    ]
    # the limit is the user's: 2 s pairs scans up to 2 s after the last command, inf all
    code, s2, _ = replay(capsys, str(log), "--cmd-timeout-s", "2")
    assert code == 0 and s2["commands"] == 29 and s2["scans_command_stale"] == SCANS - 29
    code, held, err = replay(capsys, str(log), "--cmd-timeout-s", "inf")
    assert code == 0 and held["commands"] == SCANS and held["scans_command_stale"] == 0
    assert held["command_max_age_s"] is None and err == ""
    # the wall comes close only after the commands stopped: every hold came from a command
    # held for seconds after it was sent
    assert s["hold_s"] == 0.0 < held["hold_s"]


def test_a_steady_command_stream_is_unchanged(tmp_path, capsys):
    log = corridor_log(tmp_path / "log", "sqlite3", WALLS)
    code, s, err = replay(capsys, str(log))
    code_inf, ref, _ = replay(capsys, str(log), "--cmd-timeout-s", "inf")
    assert code == code_inf == 0 and err == ""
    assert s["commands"] == SCANS and s["scans_command_stale"] == 0
    for key in ("commands", "changed", "hold_s", "holds", "max_cut_mps", "limiters"):
        assert s[key] == ref[key], key


def test_odometry_keeps_its_own_limit(tmp_path, capsys):
    """Pose-derived velocities hold for 1 s (the gap rule of ``velocities_from_poses``); the
    option is about command topics."""
    log = corridor_log(tmp_path / "log", "mcap", WALLS, command="odometry")
    code, s, err = replay(capsys, str(log), "--cmd-timeout-s", "0.01")
    assert code == 0 and s["commands"] == SCANS - 1 and s["command_max_age_s"] == 1.0
    assert s["scans_command_stale"] == 0 and err == ""


@pytest.mark.parametrize("value", ["0", "-1", "nan", "abc", "-inf"])
def test_bad_timeouts(tmp_path, capsys, value):
    log = corridor_log(tmp_path / "log", "mcap", WALLS[:5])
    code = main(["replay", str(log), f"--cmd-timeout-s={value}"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "--cmd-timeout-s" in err, err


def twist(v: float, w: float = 0.0) -> bytes:
    vec = T["geometry_msgs/msg/Vector3"]
    msg = T["geometry_msgs/msg/Twist"](vec(v, 0.0, 0.0), vec(0.0, 0.0, w))
    return TS.serialize_cdr(msg, "geometry_msgs/msg/Twist")


def test_damaged_command_records_are_skipped_and_counted(tmp_path, capsys):
    damaged = {4: twist(math.nan), 7: twist(0.12, 3e38), 9: twist(0.12)[:10]}
    log = corridor_log(tmp_path / "log", "mcap", WALLS, command_at=damaged)
    code, s, err = replay(capsys, str(log))
    assert code == 0
    assert s["command_messages_corrupt"] == 3 and s["command_messages"] == SCANS - 3
    # the scans of the damaged ones keep the command before (0.1 s old)
    assert s["commands"] == SCANS and s["max_cut_mps"] == pytest.approx(0.12)
    assert err.splitlines() == [
        f"egc-teleop replay: skipped 3 of {SCANS} messages on '/cmd_vel' as corrupt "
        "(undecodable, or no velocity or pose a robot has; first, index 4: linear.x nan)"
    ]
