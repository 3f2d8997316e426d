"""The robot's black box: nothing dropped (rows read back = messages sent = counts()), values."""

from __future__ import annotations

import math
import threading
from pathlib import Path

import numpy as np
import pytest
from egc_common.messages import BaseCommand, OperatorCommand, StateMessage
from egc_common.scan import Scan
from egc_robot.blackbox import BASE_CMD, COMMANDS, LOG, SCAN, STATE, BlackBox

from tests.view.rrd import read_recording

N_COMMANDS, N_BASE, N_SCANS, DECIMATION = 300, 250, 100, 3


def _command(seq: int) -> bytes:
    return OperatorCommand(
        seq=seq,
        stamp_ns=seq * 50_000_000,
        x=0.5,
        y=-0.25,
        mode="shared",
        deadman=True,
        estop=False,
        reset=False,
        op="op1",
    ).encode()


def _scan(i: int) -> Scan:
    ranges = np.full(720, 2.0 + 0.01 * i)
    ranges[::90] = math.inf  # no return: dropped from the points, kept in the raw ranges
    return Scan.uniform(ranges, -math.pi, 2 * math.pi / 720, 0.05, 10.0, stamp_ns=i)


@pytest.fixture(scope="module")
def box(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict, dict[str, int]]:  # type: ignore[type-arg]
    """Commands, base commands, scans and states from three threads, as in the robot process."""
    path = tmp_path_factory.mktemp("blackbox") / "robot.rrd"
    bb = BlackBox(path, "sim", scan_decimation=DECIMATION)

    def commands() -> None:
        for i in range(N_COMMANDS):
            now = 1_000_000_000 + i * 10_000_000
            if i % 10 == 3:
                bb.on_command(b"\x93garbage", False, None, now)  # undecodable, no reason given
            elif i % 10 == 7:
                bb.on_command(_command(i), False, "stale: 412 ms old", now)
            else:
                bb.on_command(_command(i), True, None, now)

    def control() -> None:
        for i in range(N_BASE):
            bb.on_base_command(BaseCommand(2_000_000_000 + i * 50_000_000, i, 0.1, -0.2 * (i % 2)))
            if i % 100 == 0:
                bb.on_state(
                    StateMessage(2_000_000_000 + i * 50_000_000, "DRIVING", "op1 in control", "op1")
                )

    def scans() -> None:
        for i in range(N_SCANS):
            bb.on_scan(_scan(i), 3_000_000_000 + i * 50_000_000)

    threads = [threading.Thread(target=f) for f in (commands, control, scans)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    bb.on_state(StateMessage(9_000_000_000, "ESTOP", "operator pressed e-stop", "op1", rejected=60))
    counts = bb.counts()
    bb.close()
    return read_recording(path), counts


def test_counts_match_what_was_sent(box) -> None:  # type: ignore[no-untyped-def]
    _, counts = box
    rejected = N_COMMANDS // 10 * 2
    states = N_BASE // 100 + 1 + 1
    assert counts == {
        "commands": N_COMMANDS,
        "commands_rejected": rejected,
        "base_commands": N_BASE,
        "scans_received": N_SCANS,
        "scans": math.ceil(N_SCANS / DECIMATION),
        "states": states,
        "log": rejected + states,
    }


def test_nothing_dropped_rows_in_the_file_equal_counts(box) -> None:  # type: ignore[no-untyped-def]
    rec, counts = box
    assert len(rec["/" + COMMANDS]) == counts["commands"]
    assert len(rec["/" + BASE_CMD]) == counts["base_commands"]
    assert len(rec["/" + SCAN]) == counts["scans"]
    assert len(rec["/" + STATE]) == counts["states"]
    assert len(rec["/" + LOG]) == counts["log"]


def test_commands_keep_verdict_reason_and_decoded_fields(box) -> None:  # type: ignore[no-untyped-def]
    rec, _ = box
    cmds = rec["/" + COMMANDS]
    accepted = [row[0] for row in cmds.column("accepted")]
    reasons = [row and row[0] for row in cmds.column("reason")]
    seqs = cmds.column("seq")
    assert accepted == [i % 10 not in (3, 7) for i in range(N_COMMANDS)]
    assert reasons[0] is None and reasons[7] == "stale: 412 ms old"
    assert reasons[3].startswith("not_msgpack") or reasons[3].startswith("not_a_map")
    assert seqs[3] is None  # undecodable: no fields
    assert seqs[7] == [7] and cmds.column("op")[7] == ["op1"] and cmds.column("x")[7] == [0.5]
    assert cmds.column("bytes")[3] == [len(b"\x93garbage")]
    stamps = cmds.rows.column("robot_time").cast("int64").to_pylist()
    assert stamps == [1_000_000_000 + i * 10_000_000 for i in range(N_COMMANDS)]
    log = [row[0] for row in rec["/" + LOG].column("TextLog:text")]
    assert "command rejected from op1 seq 7: stale: 412 ms old" in log


def test_base_commands_are_on_the_control_cycle_timeline(box) -> None:  # type: ignore[no-untyped-def]
    rec, _ = box
    base = rec["/" + BASE_CMD]
    assert base.column("cycle") == list(range(N_BASE))
    values = base.column("Scalars:scalars")
    assert values[1] == pytest.approx([0.1, -0.2]) and values[2] == pytest.approx([0.1, 0.0])


def test_scans_are_decimated_and_keep_raw_ranges(box) -> None:  # type: ignore[no-untyped-def]
    rec, _ = box
    scans = rec["/" + SCAN]
    times = scans.rows.column("robot_time").cast("int64").to_pylist()
    assert times == [3_000_000_000 + i * 50_000_000 for i in range(0, N_SCANS, DECIMATION)]
    points = np.array(scans.column("Points2D:positions")[1])
    assert points.shape == (720 - 8, 2)  # the 8 no-return beams are not points
    np.testing.assert_allclose(
        np.hypot(points[:, 0], points[:, 1]), 2.0 + 0.01 * DECIMATION, rtol=1e-5
    )
    ranges = np.array(scans.column("ranges_m")[1])
    assert ranges.shape == (720,) and np.isinf(ranges[::90]).all()


def test_states_go_to_the_lane_and_the_log(box) -> None:  # type: ignore[no-untyped-def]
    rec, _ = box
    assert rec["/" + STATE].column("StateChange:state")[-1] == ["ESTOP"]
    log = rec["/" + LOG]
    last = log.column("TextLog:text")[-1][0]
    assert last == "state ESTOP: operator pressed e-stop (operator op1); 60 rejected so far"
    assert log.column("TextLog:level")[-1] == ["ERROR"]


def test_decimation_must_be_positive(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="decimation"):
        BlackBox(tmp_path / "x.rrd", "sim", scan_decimation=0)


def test_close_is_idempotent_and_later_messages_are_ignored(tmp_path: Path) -> None:
    bb = BlackBox(tmp_path / "closed.rrd", "sim")
    bb.on_base_command(BaseCommand(1, 1, 0.0, 0.0))
    bb.close()
    bb.on_base_command(BaseCommand(2, 2, 0.0, 0.0))
    bb.close()
    assert bb.counts()["base_commands"] == 1
    assert len(read_recording(tmp_path / "closed.rrd")["/" + BASE_CMD]) == 1
