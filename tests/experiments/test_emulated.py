"""The pure parts of the emulated mode and of its helper processes (no processes started).

- ``Judge`` ends a run as the simulated mode does: reached, collided (footprint clearance at
  the reported pose), stalled, timeout; nothing before the operator's t = 0 counts.
- ``summarise``: path, clearance, time-weighted hold (only while the operator wants to move,
  after the robot first drove), interventions in 50 ms cycles.
- ``Tail`` reads only complete lines of a file being appended to.
- ``expand_endpoint`` (egc_common.transport): plain ``udp/`` becomes a TCP + best-effort UDP pair.
- ``operator_model.ModelDriver`` centres until the view shows the robot driving, then steers.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from egc_common.messages import Telemetry
from egc_common.profiles import get_profile
from egc_common.transport import expand_endpoint
from egc_experiments.emulated import Judge, Tail, intent_at, summarise
from egc_experiments.operator_model import ModelDriver
from egc_experiments.simulated import OperatorSide
from egc_experiments.watch import telemetry_line
from egc_sim.collision import FootprintChecker
from egc_sim.operators import ForwardOperator
from egc_sim.worlds import load_world

S = 1_000_000_000


@pytest.fixture(scope="module")
def checker():
    profile = get_profile("pioneer3dx")
    return FootprintChecker(load_world("hallway"), profile.footprint)


def line(t_s, x, y=0.6, state="DRIVING", lim="none", v=0.1):
    return {"t": int(t_s * S), "pose": [x, y, 0.0], "state": state, "lim": lim, "v": v}


def judge(checker, **kw):
    j = Judge(goal=(5.0, 0.6), tolerance_m=0.3, checker=checker, max_time_s=10, stall_time_s=3)
    for k, v in kw.items():
        setattr(j, k, v)
    j.start(1 * S, (0.6, 0.6, 0.0))
    return j


def test_judge_reached_timeout_stalled_and_nothing_before_t0(checker):
    j = judge(checker)
    j.feed(line(0.5, 4.9))  # before t0: ignored, even at the goal
    assert j.outcome is None
    j.feed(line(2.0, 1.0))
    j.feed(line(3.0, 4.8))
    assert (j.outcome, j.end_ns) == ("reached", 3 * S)
    j = judge(checker)
    j.feed(line(2.0, 1.0))
    j.feed(line(4.9, 1.05))
    assert j.outcome is None
    j.feed(line(5.1, 1.05))  # no 0.1 m of progress for 3 s since 2.0
    assert j.outcome == "stalled"
    j = judge(checker, stall_time_s=100)
    for t in range(2, 12):
        j.feed(line(t, 0.6 + 0.2 * t))
    assert (j.outcome, j.end_ns) == ("timeout", 11 * S)


def test_judge_collided_at_a_pose_touching_a_wall(checker):
    j = judge(checker)
    j.feed(line(2.0, 1.0, y=0.2))  # the footprint's side is in the wall at y = 0
    assert j.outcome == "collided"


def test_summarise_weighs_by_time_and_counts_hold_only_when_the_operator_wants_to_move(checker):
    lines = [
        line(1.0, 0.6, state="IDLE"),  # before the robot first drove: not a hold
        line(1.5, 0.6, state="DRIVING"),
        line(2.0, 0.7, state="DRIVING", lim="egc"),
        line(2.5, 0.8, state="HOLD"),
        line(3.5, 0.8, state="HOLD"),  # operator no longer wants to move from 3.0
        line(4.0, 0.9, state="DRIVING"),
    ]
    intents = [(int(1.0 * S), True), (int(3.0 * S), False), (int(3.9 * S), True)]
    assert intent_at(intents, int(0.5 * S)) is False and intent_at(intents, 2 * S) is True
    f = summarise(lines, intents, 1 * S, 5 * S, checker)
    assert f["path_m"] == pytest.approx(0.3)
    assert f["hold_s"] == pytest.approx(1.0) and f["hold_events"] == 1
    assert f["interventions"] == 10  # 0.5 s limited by egc = 10 cycles of 50 ms
    assert f["final_pose"] == [0.9, 0.6, 0.0]
    assert 0 < f["min_clearance_m"] <= 1.0


def test_tail_reads_complete_lines_only(tmp_path):
    path = tmp_path / "x.jsonl"
    tail = Tail(path)
    assert tail.read() == []
    with path.open("w") as f:
        f.write('{"a": 1}\n{"b"')
        f.flush()
        assert tail.read() == [{"a": 1}]
        f.write(": 2}\n")
        f.flush()
        assert tail.read() == [{"b": 2}]
    tail.close()


@pytest.mark.parametrize(
    ("given", "expected"),
    [
        ("udp/10.0.0.2:7447", ("tcp/10.0.0.2:7447", "udp/10.0.0.2:7447?rel=0")),
        ("udp/[::1]:7447?iface=lo", ("tcp/[::1]:7447?iface=lo", "udp/[::1]:7447?iface=lo;rel=0")),
        ("udp/h:1#x=1", ("tcp/h:1#x=1", "udp/h:1?rel=0#x=1")),
        ("udp/h:1?rel=0", ("udp/h:1?rel=0",)),
        ("udp/h:1?rel=1;mixed_rel=1", ("udp/h:1?rel=1;mixed_rel=1",)),
        ("tcp/h:1", ("tcp/h:1",)),
        ("tls/h:1", ("tls/h:1",)),
    ],
)
def test_udp_endpoints_become_a_reliable_tcp_and_a_best_effort_udp_link(given, expected):
    assert expand_endpoint(given) == expected


def telemetry(state, pose=(0.6, 0.6, 0.0), stamp_ns=1):
    return Telemetry(
        seq=1, stamp_ns=stamp_ns, state=state, mode="shared", v_ref=0.0, w_ref=0.0,
        v_cmd=0.0, w_cmd=0.0, w_si=1.0, pose=pose, scan_xy=np.zeros((3, 2), np.float32),
        reason="",
    )  # fmt: skip


def test_model_driver_centres_until_the_view_shows_driving_then_steers(tmp_path):
    intent = (tmp_path / "intent.jsonl").open("w")
    driver = ModelDriver(OperatorSide(ForwardOperator("shared"), "shared", (0.6, 0.6, 0.0)), intent)
    first = driver.sample(0.0)
    assert (first.x, first.y, first.deadman) == (0.0, 0.0, True)  # nothing seen yet
    driver.on_telemetry(telemetry("IDLE"))
    assert driver.sample(0.02).x == 0.0
    driver.on_telemetry(telemetry("DRIVING", stamp_ns=2))
    stick = driver.sample(0.04)
    assert stick.x == 1.0 and stick.deadman and stick.mode == "shared"
    intent.close()
    rows = [json.loads(x) for x in (tmp_path / "intent.jsonl").read_text().splitlines()]
    assert "t0" in rows[0] and rows[1]["move"] is True


def test_watch_line_keys():
    d = telemetry_line(5, telemetry("HOLD"))
    assert d["rx"] == 5 and d["state"] == "HOLD" and d["pose"] == [0.6, 0.6, 0.0]
    assert {"t", "v", "w", "vr", "wr", "lim", "age", "gap", "loss", "tau", "rej", "op"} <= set(d)
