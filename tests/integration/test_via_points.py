"""Via points over Zenoh (issue 11): real robot (``--driver sim``) and operator processes.

- The operator process sends two via points (``--goal``, repeatable) with ``--filter assist``
  and a stick held forward; the robot's assistant steers to each in turn: the telemetry echoes
  the active via point, moves on to the second when the robot is within the tolerance of the
  first, and ends with none active.
- A goal from an operator that is not in control is rejected and counted (robot summary and
  log); malformed goal payloads sent with a raw Zenoh session do not crash the robot.

The world is an empty 8 m x 5 m room; the via points lie within 45 degrees of the robot's
heading, where the assistant follows the via point rather than the operator's steady stick.
"""

from __future__ import annotations

import itertools
import json
import math
import time
from pathlib import Path

import msgpack
import pytest
import zenoh
from egc_common import keys
from egc_common.messages import GoalMessage
from egc_common.transport import loopback_endpoint

from tests.integration.harness import ROBOT, forward_file, operator_args

pytestmark = [pytest.mark.integration, pytest.mark.timeout(150)]

START = (1.5, 2.5, 0.0)
# 34 and 11 degrees off the heading at 1.1 m and 1.0 m: the drive through both took 15 s here
# (the robot's highest y 2.99 m; 23 s with the earlier (3.0, 3.0), (4.5, 2.8)).
VIA = ((2.4, 3.1), (3.4, 2.9))
TOLERANCE_M = 0.3  # the robot's default via_tolerance_m
ROOM = """\
name = "via-room"
resolution_m = 0.05
bounds_m = [-0.2, -0.2, 8.2, 5.2]
start = { x_m = 1.5, y_m = 2.5, yaw_rad = 0.0 }
goal = { x_m = 6.5, y_m = 2.5 }
"""
WALLS = (
    (-0.1, -0.1, 8.1, -0.1),
    (-0.1, 5.1, 8.1, 5.1),
    (-0.1, -0.1, -0.1, 5.1),
    (8.1, -0.1, 8.1, 5.1),
)


def room(tmp_path: Path) -> Path:
    text = ROOM + "".join(
        f"\n[[segments]]\nfrom_m = [{a}, {b}]\nto_m = [{c}, {d}]\nthickness_m = 0.2\n"
        for a, b, c, d in WALLS
    )
    path = tmp_path / "room.toml"
    path.write_text(text)
    return path


def start_robot(procs, port: int, tmp_path: Path, summary: Path) -> None:
    procs.start(
        "robot",
        "robot",
        "--robot",
        ROBOT,
        "--driver",
        "sim",
        "--map",
        str(room(tmp_path)),
        "--start",
        ",".join(str(v) for v in START),
        "--filter",
        "assist",
        "--listen",
        loopback_endpoint(port),
        "--summary",
        str(summary),
    )


def goal_args() -> list[str]:
    args = ["--filter", "assist"]
    for x, y in VIA:
        args += ["--goal", f"{x},{y}"]
    return args


def test_the_robot_drives_to_each_via_point_in_turn(port, procs, observer, tmp_path):
    summary_path = tmp_path / "robot.json"
    start_robot(procs, port, tmp_path, summary_path)
    observer.wait_for("robot telemetry", observer.last_telemetry, 20)
    procs.start("op", *operator_args(port, "alice", forward_file(tmp_path, 90), *goal_args()))

    def done() -> bool:
        ts = observer.telemetry()
        return any(t.goal == VIA[1] for t in ts) and ts[-1].goal is None

    observer.wait_for("the robot through both via points", done, 90)
    time.sleep(0.3)
    assert procs.stop("op") == 0, procs.log("op")
    assert procs.stop("robot") == 0, procs.log("robot")
    ts = [t for t in observer.telemetry() if t.operator == "alice" and t.pose is not None]
    # The echo: the first via point with one after it, then the second alone, then none.
    echoes = [(t.goal, t.goal_frame, t.goals_left) for t in ts]
    phases = [e for i, e in enumerate(echoes) if i == 0 or e != echoes[i - 1]]
    first_active = phases.index((VIA[0], "odom", 1))
    assert phases[first_active:] == [
        (VIA[0], "odom", 1),
        (VIA[1], "odom", 0),
        (None, None, 0),
    ], phases
    # Each hand-over happens where the robot is within the tolerance of the point it leaves.
    for i, (a, b) in enumerate(itertools.pairwise(ts)):
        if a.goal != b.goal and a.goal is not None:
            x, y, _ = b.pose
            assert math.hypot(x - a.goal[0], y - a.goal[1]) <= TOLERANCE_M + 0.05, (i, b.pose)
    # The assistant steered: the robot left its start line towards the first via point.
    assert max(t.pose[1] for t in ts) > START[1] + 0.3
    assert all(t.filter == "assist" for t in ts if t.state == "DRIVING")
    assert any(t.suggested_rad is not None for t in ts if t.goal is not None)
    summary = json.loads(summary_path.read_text())
    assert summary["collisions"] == 0
    assert not any(k.startswith("goal_") for k in summary["rejected"]), summary["rejected"]
    op_log = procs.log("op")
    assert "via points sent: 2 in odom (seq 1)" in op_log
    assert "via points from alice: 2 in odom, active 2.40,3.10" in procs.log("robot")


MALFORMED = [
    b"\xc1 not msgpack",
    msgpack.packb([1, 2, 3]),
    msgpack.packb({"v": 1, "seq": 1}),
    msgpack.packb({"v": 2, "seq": 1, "stamp_ns": 0, "op": "alice", "frame": "odom", "points": []}),
    msgpack.packb(
        {"v": 1, "seq": 9, "stamp_ns": 0, "op": "alice", "frame": "base", "points": [[1, 1]]}
    ),
    msgpack.packb(
        {"v": 1, "seq": 10, "stamp_ns": 0, "op": "alice", "frame": "odom", "points": "1,1"}
    ),
    msgpack.packb(
        {"v": 1, "seq": 11, "stamp_ns": 0, "op": "alice", "frame": "odom", "points": [[1, "x"]]}
    ),
    msgpack.packb(
        {
            "v": 1,
            "seq": 12,
            "stamp_ns": 0,
            "op": "alice",
            "frame": "odom",
            "points": [[float("nan"), 0.0]],
        }
    ),
    msgpack.packb(
        {
            "v": 1,
            "seq": 13,
            "stamp_ns": 0,
            "op": "alice",
            "frame": "odom",
            "points": [[0.0, 0.0]] * 65,
        }
    ),
    b"\x00" * 100_000,
]


def test_goals_from_an_operator_not_in_control_and_malformed_ones_are_rejected(
    port, procs, observer, tmp_path
):
    summary_path = tmp_path / "robot.json"
    start_robot(procs, port, tmp_path, summary_path)
    observer.wait_for("robot telemetry", observer.last_telemetry, 20)
    procs.start("op", *operator_args(port, "alice", forward_file(tmp_path, 90), *goal_args()))
    observer.wait_for(
        "alice's via points", lambda: (t := observer.last_telemetry()) and t.goal == VIA[0], 20
    )
    # BLOCK, and a pause between payloads: every payload must arrive to be counted (a burst
    # with a 100 kB one in it can be dropped by a default DROP publisher on a busy machine).
    publisher = observer.session.declare_publisher(
        keys.goal(ROBOT), congestion_control=zenoh.CongestionControl.BLOCK
    )
    try:
        # Mallory is not in control: her route is refused, alice's stays.
        for seq in range(1, 4):
            intruder = GoalMessage(seq, 0, "mallory", "odom", ((0.0, 0.0),))
            publisher.put(intruder.encode())
            time.sleep(0.4)
        for payload in MALFORMED:
            publisher.put(payload)
            time.sleep(0.05)
        time.sleep(1.0)
    finally:
        publisher.undeclare()
    assert procs.alive("robot"), procs.log("robot")
    last = observer.last_telemetry()
    assert last is not None and last.state == "DRIVING" and last.goal in VIA
    # Still publishing: five more telemetry messages arrive (20 Hz: 0.25 s on an idle machine;
    # the deadline is for a busy one, where a cycle of the assist planner can run late).
    since = time.monotonic_ns()
    observer.wait_for("telemetry after the goals", lambda: len(observer.telemetry(since)) >= 5, 10)
    assert procs.stop("op") == 0, procs.log("op")
    assert procs.stop("robot") == 0, procs.log("robot")
    rejected = json.loads(summary_path.read_text())["rejected"]
    assert rejected.get("goal_not_in_control", 0) == 3, rejected
    # one count per malformed payload, by reason (the decoder's, as for commands)
    goal_rejections = sum(v for k, v in rejected.items() if k.startswith("goal_"))
    assert goal_rejections == 3 + len(MALFORMED), rejected
    for reason in ("goal_not_msgpack", "goal_not_a_map", "goal_missing_key", "goal_too_large"):
        assert rejected.get(reason, 0) >= 1, (reason, rejected)
    robot_log = procs.log("robot")
    assert "rejected goal (not_in_control): goal from mallory: control held by alice" in robot_log
    assert "Traceback" not in robot_log


def test_next_and_clear_from_the_joystick_file_reach_the_robot(port, procs, observer, tmp_path):
    """The file's via_next / via_clear columns act on their press: one skip, then a clear."""
    summary_path = tmp_path / "robot.json"
    start_robot(procs, port, tmp_path, summary_path)
    observer.wait_for("robot telemetry", observer.last_telemetry, 20)
    buttons = tmp_path / "buttons.csv"
    buttons.write_text(
        "t_s,x,y,deadman,mode,via_next,via_clear\n"
        "0,0,0,1,shared,0,0\n"
        "3.0,0,0,1,shared,1,0\n"  # next, held for 0.5 s: one skip
        "3.5,0,0,1,shared,0,0\n"
        "6.0,0,0,1,shared,0,1\n"  # clear
        "6.5,0,0,1,shared,0,0\n"
        "30,0,0,1,shared,0,0\n"
    )
    procs.start("op", *operator_args(port, "alice", buttons, *goal_args()))

    def echoes() -> list[tuple[object, int]]:
        ts = [t for t in observer.telemetry() if t.operator == "alice"]
        seq = [(t.goal, t.goals_left) for t in ts]
        return [e for i, e in enumerate(seq) if i == 0 or e != seq[i - 1]]

    observer.wait_for("the clear", lambda: (VIA[1], 0) in echoes() and echoes()[-1][0] is None, 20)
    time.sleep(1.5)  # the cleared route is republished: nothing comes back
    assert procs.stop("op") == 0, procs.log("op")
    assert procs.stop("robot") == 0, procs.log("robot")
    phases = echoes()
    start = phases.index((VIA[0], 1))
    assert phases[start:] == [(VIA[0], 1), (VIA[1], 0), (None, 0)], phases
    op_log = procs.log("op")
    assert op_log.count("via point skipped: 1 left") == 1 and "via points cleared" in op_log
    rejected = json.loads(summary_path.read_text())["rejected"]
    assert not any(k.startswith("goal_") for k in rejected), rejected
