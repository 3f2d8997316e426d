"""No prediction and no link figures drawn from stale telemetry (DESIGN 9: never a prediction as
if it were a measurement).

Found by an outside check: with the robot killed (liveliness withdrawn) or frozen, the view kept
redrawing the ghost every 60 ms at the dead robot's last stamp, labelled as where the command
takes effect, and the link panel kept the last uplink/gap/loss figures and 'DRIVING ... safe'.
"""

from __future__ import annotations

from pathlib import Path

from egc_operator import view_blueprint as paths
from egc_operator.prediction import CommandHistory, SentCommand
from egc_operator.view import OperatorView, record_episode

from tests.view.conftest import telemetry
from tests.view.rrd import Entity, read_recording

MS = 1_000_000
START = 10_000 * MS


class FakeClock:
    def __init__(self) -> None:
        self.ns = 5_000 * MS

    def __call__(self) -> int:
        return self.ns


def _drive(view: OperatorView, clock: FakeClock, history: CommandHistory, k: int) -> int:
    """Cycle k's telemetry arrives, then the operator sends a command 40 ms later."""
    stamp = START + k * 50 * MS
    view.on_telemetry(
        telemetry(
            k,
            stamp_ns=stamp,
            state="DRIVING",
            v_ref=0.5,
            v_cmd=0.5,
            pose=(0.025 * k, 0.0, 0.0),
            cmd_age_p50_ms=200.0,
            cmd_gap_max_ms=40.0,
            link_loss=0.0,
        )
    )
    clock.ns += 50 * MS
    now = stamp + 40 * MS
    history.add(SentCommand(now, 1.0, 0.0, "shared"))
    view.on_commands(history, now)
    return now


def _last_text(entity: Entity) -> str:
    value = entity.column("TextDocument:text")[-1]
    return str(value[0] if isinstance(value, list) else value)


def _last_label(entity: Entity) -> str:
    return str(entity.column("Points2D:labels")[-1][0])


def _ghost_cleared(rec: dict[str, Entity]) -> bool:
    return rec["/" + paths.PREDICTED_FOOTPRINT].column("LineStrips2D:strips")[-1] in (None, [])


def _open(tmp_path: Path) -> tuple[OperatorView, FakeClock, Path]:
    path = tmp_path / "view.rrd"
    view = record_episode(path, "sim")
    clock = FakeClock()
    view.clock = clock
    view.on_link(400.0, 0)
    return view, clock, path


def test_a_silent_robot_gets_no_ghost_and_its_figures_are_marked_stale(tmp_path: Path) -> None:
    view, clock, path = _open(tmp_path)
    history = CommandHistory()
    now = 0
    for k in range(20):
        now = _drive(view, clock, history, k)
    view.flush()
    live = read_recording(path)
    assert not _ghost_cleared(live)  # driving: the ghost is drawn
    assert _last_text(live["/" + paths.LINK_TEXT]).startswith("uplink 200 ms")
    # The robot freezes: the operator keeps sending for a second, nothing arrives.
    for _ in range(20):
        clock.ns += 50 * MS
        now += 50 * MS
        history.add(SentCommand(now, 1.0, 0.0, "shared"))
        view.on_commands(history, now)
    view.close()
    rec = read_recording(path)
    assert _ghost_cleared(rec)
    panel = _last_text(rec["/" + paths.LINK_TEXT])
    assert panel.startswith("NO TELEMETRY for 1.1 s (robot or link silent)")
    assert "uplink" not in panel and "takes effect" not in panel
    status = _last_label(rec["/" + paths.STATUS])
    assert status.startswith("NO TELEMETRY for 1.1 s") and "DRIVING" not in status
    # ... logged after the last telemetry, at the robot's time now
    stamps = rec["/" + paths.STATUS].rows.column("robot_time").cast("int64").to_pylist()
    assert stamps[-1] > START + 19 * 50 * MS


def test_a_robot_gone_is_said_at_once_and_a_new_one_starts_afresh(tmp_path: Path) -> None:
    view, clock, path = _open(tmp_path)
    history = CommandHistory()
    for k in range(10):
        _drive(view, clock, history, k)
    view.on_robot_presence(False)  # its liveliness token withdrawn: no command needed
    view.flush()
    rec = read_recording(path)
    assert _ghost_cleared(rec)
    assert "robot gone" in _last_text(rec["/" + paths.LINK_TEXT])
    assert "robot gone" in _last_label(rec["/" + paths.STATUS])
    # a restarted robot: nothing predicted from the old one's telemetry until its own arrives
    view.on_robot_presence(True)
    history.add(SentCommand(START + 2000 * MS, 1.0, 0.0, "shared"))
    view.on_commands(history, START + 2000 * MS)
    view.flush()
    assert _ghost_cleared(read_recording(path))
    for k in range(40, 45):
        _drive(view, clock, history, k)
    view.close()
    rec = read_recording(path)
    assert not _ghost_cleared(rec)
    assert _last_label(rec["/" + paths.STATUS]).startswith("DRIVING")


def test_a_robot_gone_or_back_leaves_no_round_trip_behind(tmp_path: Path) -> None:
    """Outside check: after a restart the old robot's rtt stayed in use (the uplink's
    '~ (rtt/2)' estimate) until the new robot's first clock reply."""
    view = _open(tmp_path)[0]
    view.on_link(400.0, 0)
    assert view._rtt_ms == 400.0
    view.on_robot_presence(False)
    assert view._rtt_ms is None
    view.on_link(400.0, 0)  # a reply that was under way
    view.on_robot_presence(True)
    assert view._rtt_ms is None
    view.close()
