"""The predictive display (DESIGN 9) in the operator view: drawn, styled and read back from .rrd."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest
from egc_common.profiles import PIONEER3DX
from egc_operator import view_blueprint as paths
from egc_operator.prediction import CommandHistory, Prediction, SentCommand
from egc_operator.view import PREDICTION_PERIOD_NS, OperatorView, record_episode
from egc_operator.view_scene import (
    PREDICTED_LABEL,
    PREDICTED_MAGENTA,
    dashed,
    footprint_corners,
    ghost_scene,
    link_text,
    status_text,
    time_series,
)

from tests.view.conftest import telemetry
from tests.view.rrd import read_recording

MS = 1_000_000
DELAY = 200 * MS  # one way, both ways
V = PIONEER3DX.v_max_mps
START = 10_000 * MS  # robot clock at the start of the run


def _e(path: str) -> str:
    return "/" + path


def _shown(k: int, **overrides: object):  # type: ignore[no-untyped-def]
    """Telemetry of cycle k: driving straight east at v_max, stamped at START + k * 50 ms."""
    stamp = START + k * 50 * MS
    values: dict[str, object] = {
        "stamp_ns": stamp,
        "state": "DRIVING",
        "v_ref": V,
        "w_ref": 0.0,
        "v_cmd": V,
        "w_cmd": 0.0,
        "pose": (V * (stamp - START) / 1e9, 0.0, 0.0),
        "cmd_age_p50_ms": 200.0,
        "cmd_age_p90_ms": 230.0,
        "cmd_gap_max_ms": 40.0,
        "link_loss": 0.0,
        "loop_delay_ms": 760.0,
        "view_age_ms": 210.0,
    }
    values.update(overrides)
    return telemetry(k, **values)


def _run(view: OperatorView, seconds: float, hold_after_s: float | None = None) -> list:  # type: ignore[type-arg]
    """A 200 ms each-way link in robot time: the operator sends full stick forward at 50 Hz and
    sees each cycle's telemetry 200 ms after its stamp. Returns (now, newest shown) per command."""
    history = CommandHistory()
    shown = []
    pending = []
    calls = []
    view.on_link(400.0, 0)
    for tick in range(round(seconds * 100)):  # 10 ms ticks of robot time
        now = START + tick * 10 * MS
        if tick % 5 == 0:
            k = tick // 5
            hold = hold_after_s is not None and now - START >= hold_after_s * 1e9
            pending.append(_shown(k, state="HOLD", reason="command timeout") if hold else _shown(k))
        while pending and pending[0].stamp_ns + DELAY <= now:
            t = pending.pop(0)
            view.on_telemetry(t, received_ns=t.stamp_ns + DELAY)
            shown.append(t)
        if tick % 2 == 0:
            history.add(SentCommand(now, 1.0, 0.0, "shared"))
            view.on_commands(history, now)
            calls.append((now, shown[-1] if shown else None))
    return calls


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory):  # type: ignore[no-untyped-def]
    path = tmp_path_factory.mktemp("predictive") / "run.rrd"
    view = record_episode(path, "sim")
    calls = _run(view, 3.0)
    view.close()
    return read_recording(path), calls


def test_the_recording_holds_the_ghost_its_path_and_the_link_figures(recorded) -> None:  # type: ignore[no-untyped-def]
    rec, calls = recorded
    for path in (
        paths.PREDICTED_FOOTPRINT,
        paths.PREDICTED_HEADING,
        paths.PREDICTED_PATH,
        paths.LINK_TEXT,
    ):
        assert _e(path) in rec, path
    # redrawn at most every 50 ms of robot time (every third 50 Hz command), not with each one
    drawn = len(rec[_e(paths.LINK_TEXT)])
    assert len(calls) == 150 and drawn == 50 and PREDICTION_PERIOD_NS == 50 * MS


def test_the_ghost_is_where_the_command_sent_now_takes_effect(recorded) -> None:  # type: ignore[no-untyped-def]
    rec, calls = recorded
    heading = rec[_e(paths.PREDICTED_HEADING)]
    # (now, newest telemetry shown) of each redraw; nothing before the first telemetry arrives
    drawn = [(now, shown) for now, shown in calls[::3] if shown is not None]
    origins = heading.column("Arrows2D:origins")
    labels = heading.column("Arrows2D:labels")
    stamps = heading.rows.column("robot_time").cast("int64").to_pylist()
    assert len(origins) == len(drawn) == 46
    for (now, shown), origin, label, stamp in zip(drawn, origins, labels, stamps, strict=True):
        # the robot at full speed is predicted at x = v (now + uplink - START)
        assert origin[0][0] == pytest.approx(V * (now + DELAY - START) / 1e9, abs=1e-6)
        assert origin[0][1] == pytest.approx(0.0, abs=1e-9)
        # labelled as a prediction, with how far it looks ahead: view age + uplink
        ahead = (now + DELAY - shown.stamp_ns) / 1e9
        assert label == [f"{PREDICTED_LABEL}, +{ahead:.2f} s"]
        assert 0.4 <= ahead < 0.45
        # logged at the stamp of the telemetry it starts from (a replay shows them together)
        assert stamp == shown.stamp_ns


def test_the_path_runs_from_the_measured_pose_and_the_footprint_is_the_profiles(recorded) -> None:  # type: ignore[no-untyped-def]
    rec, calls = recorded
    path = rec[_e(paths.PREDICTED_PATH)]
    strips = path.column("LineStrips2D:strips")[-1]
    measured = calls[::3][-1][1].pose
    heading = rec[_e(paths.PREDICTED_HEADING)].column("Arrows2D:origins")[-1][0]
    xs = [p[0] for strip in strips for p in strip]
    assert min(xs) == pytest.approx(measured[0], abs=1e-6)  # starts at the newest measured pose
    assert max(xs) <= heading[0] + 1e-9
    assert strips  # 6 cm at a Pioneer's 0.14 m/s: one dash (the dashes: test_dashes_...)
    footprint = rec[_e(paths.PREDICTED_FOOTPRINT)].column("LineStrips2D:strips")[-1]
    points = np.array([p for strip in footprint for p in strip])
    length = points[:, 0].max() - points[:, 0].min()
    width = points[:, 1].max() - points[:, 1].min()
    assert (length, width) == pytest.approx((PIONEER3DX.length_m, PIONEER3DX.width_m), abs=1e-5)


def test_the_ghost_is_styled_as_a_prediction(recorded) -> None:  # type: ignore[no-untyped-def]
    rec, _ = recorded
    for path in (paths.PREDICTED_FOOTPRINT, paths.PREDICTED_PATH):
        (colours,) = rec[_e(path)].static_column("LineStrips2D:colors")
        r, g, b, a = PREDICTED_MAGENTA
        assert colours == [(r << 24) | (g << 16) | (b << 8) | a]
        assert a < 255  # translucent
    assert rec[_e(paths.PREDICTED_HEADING)].static_column("Arrows2D:show_labels") == [[True]]


def test_the_link_figures_in_plain_numbers(recorded) -> None:  # type: ignore[no-untyped-def]
    rec, _ = recorded
    texts = [row[0] for row in rec[_e(paths.LINK_TEXT)].column("TextDocument:text")]
    assert texts[0].startswith("uplink -- (rtt/2)") or texts[0].startswith("uplink --")
    last = texts[-1]
    first_line, second, ghost, hint = last.splitlines()
    assert first_line == (
        "uplink 200 ms, downlink ~200 ms, view age 240 ms, loop delay 0.76 s, gap max 40 ms,"
        " loss 0.0 %"
    )
    assert second == "command age on arrival p50 200 ms, p90 230 ms"
    assert ghost == (
        "ghost (dashed magenta): predicted (not measured), +0.44 s: where the command sent now"
        " takes effect"
    )
    assert hint == "the robot drawn solid is 0.4 s behind: steer by the ghost"


def test_a_holding_robot_is_predicted_to_stop(tmp_path: Path) -> None:
    view = record_episode(tmp_path / "hold.rrd", "sim")
    _run(view, 2.0, hold_after_s=1.0)
    view.close()
    rec = read_recording(tmp_path / "hold.rrd")
    texts = [row[0] for row in rec[_e(paths.LINK_TEXT)].column("TextDocument:text")]
    assert "where the command sent now takes effect, the robot stops" in texts[-1]
    origin = rec[_e(paths.PREDICTED_HEADING)].column("Arrows2D:origins")[-1][0]
    newest_x = V * (2.0 - 0.2 - 0.01) // (V * 0.05) * (V * 0.05)  # last shown cycle's pose
    braking = V * V / (2 * PIONEER3DX.decel_max_mps2)
    assert newest_x < origin[0] <= newest_x + braking + 1e-6


def test_without_pose_the_ghost_is_cleared_and_says_why(tmp_path: Path) -> None:
    view = record_episode(tmp_path / "nopose.rrd", "sim")
    history = CommandHistory()
    t = _shown(0)
    view.on_telemetry(t)
    history.add(SentCommand(t.stamp_ns + 20 * MS, 1.0, 0.0))
    view.on_commands(history, t.stamp_ns + 20 * MS)
    view.on_telemetry(_shown(1, pose=None))
    history.add(SentCommand(t.stamp_ns + 80 * MS, 1.0, 0.0))
    view.on_commands(history, t.stamp_ns + 80 * MS)
    view.on_commands(history, 0)  # unsynchronised: ignored
    view.close()
    rec = read_recording(tmp_path / "nopose.rrd")
    strips = rec[_e(paths.PREDICTED_FOOTPRINT)].column("LineStrips2D:strips")
    assert len(strips) == 2 and strips[0] and not strips[1]
    text = rec[_e(paths.LINK_TEXT)].column("TextDocument:text")[-1][0]
    assert "ghost: no prediction" in text and "downlink --" in text


def test_a_disabled_or_closed_view_ignores_commands(tmp_path: Path) -> None:
    history = CommandHistory()
    history.add(SentCommand(START, 1.0, 0.0))
    OperatorView(None, "sim").on_commands(history, START)
    view = record_episode(tmp_path / "closed.rrd", "sim")
    view.close()
    view.on_commands(history, START)


# -- the pure parts ------------------------------------------------------------------------------


def test_dashes_follow_the_polyline_and_keep_their_rhythm_across_vertices() -> None:
    dashes = dashed([(0.0, 0.0), (1.0, 0.0)], dash_m=0.1, gap_m=0.1)
    assert len(dashes) == 5
    assert dashes[0] == [(0.0, 0.0), (0.1, 0.0)]
    assert dashes[-1][0] == pytest.approx((0.8, 0.0))
    bent = dashed([(0.0, 0.0), (0.05, 0.0), (0.05, 0.5)], dash_m=0.1, gap_m=0.1)
    assert np.allclose(bent[0], [(0.0, 0.0), (0.05, 0.0), (0.05, 0.05)])  # round the corner
    total = sum(math.dist(a, b) for dash in bent for a, b in itertools.pairwise(dash))
    assert total == pytest.approx(0.3)  # dashes 0-0.1, 0.2-0.3, 0.4-0.5 of 0.55 m
    assert dashed([(1.0, 1.0)]) == [] and dashed([(1.0, 1.0), (1.0, 1.0)]) == []
    with pytest.raises(ValueError):
        dashed([(0.0, 0.0), (1.0, 0.0)], dash_m=0.0)


def test_footprint_corners_at_a_pose() -> None:
    corners = footprint_corners((1.0, 2.0, math.pi / 2), PIONEER3DX)
    hl, hw = PIONEER3DX.length_m / 2, PIONEER3DX.width_m / 2
    assert corners[0] == pytest.approx((1.0 - hw, 2.0 + hl))  # front left, facing north
    assert corners[-1] == corners[0] and len(corners) == 5


def test_ghost_scene_label_says_prediction_and_how_far_ahead() -> None:
    from egc_operator.prediction import predict

    pred = predict(
        (0.0, 0.0, 0.0),
        START,
        "DRIVING",
        (V, 0.0),
        (V, 0.0),
        [],
        START + 300 * MS,
        300 * MS,
        PIONEER3DX,
    )
    ghost = ghost_scene(pred, PIONEER3DX)
    assert ghost.label == "predicted (not measured), +0.60 s"
    assert ghost.heading_origin == pytest.approx((V * 0.6, 0.0))
    assert ghost.heading_vector == pytest.approx((PIONEER3DX.length_m / 2, 0.0))


def test_link_text_with_nothing_known() -> None:
    assert link_text(None, False, None, None, None, None) == (
        "uplink --, downlink --, view age --, loop delay --, gap max --, loss --\n"
        "ghost: no prediction (no pose, unknown profile or clock not synced)"
    )
    assert link_text(300.0, True, None, None, None, None).startswith("uplink ~300 ms (rtt/2),")


def test_latency_limiter_is_shown_with_its_cap() -> None:
    t = telemetry(1, limiter="latency", v_lim_latency=0.1, loop_delay_ms=1310.0)
    assert "limit: latency <= 0.10 m/s" in status_text(t)
    assert "limit: latency - speed capped at 0.10 m/s" in link_text(
        None, False, None, None, t, None
    )
    assert time_series(t)["v/lim_latency"] == 0.1
    assert time_series(t)["latency/loop_delay_ms"] == 1310.0
    assert "v/lim_latency" not in time_series(telemetry(1))
    turn = telemetry(1, limiter="latency", v_lim_latency=0.1, w_lim_latency=0.27)
    assert "limit: latency <= 0.10 m/s, 0.27 rad/s" in status_text(turn)
    assert "speed capped at 0.10 m/s, turn at 0.27 rad/s" in link_text(
        None, False, None, None, turn, None
    )
    assert time_series(turn)["w/lim_latency"] == 0.27


def test_status_text_says_why_the_robot_is_not_driving() -> None:
    t = telemetry(1, state="HOLD", reason="command timeout", limiter="watchdog")
    assert status_text(t).startswith("HOLD (command timeout) · shared · limit: watchdog")
    assert status_text(telemetry(1, reason="fresh centred command")).startswith("DRIVING · ")


def test_link_text_tells_the_operator_to_steer_by_a_ghost_far_ahead() -> None:
    t = telemetry(1)
    near = _prediction_ahead(0.1)
    far = _prediction_ahead(0.6)
    assert "steer by the ghost" not in link_text(50.0, False, 50.0, 50.0, t, near)
    text = link_text(250.0, False, 250.0, 350.0, t, far)
    assert text.endswith("the robot drawn solid is 0.6 s behind: steer by the ghost")


def _prediction_ahead(seconds: float) -> Prediction:
    start = 1_000_000_000
    return Prediction(
        pose=(0.0, 0.0, 0.0),
        path=((0.0, 0.0, 0.0),),
        start_ns=start,
        end_ns=start + round(seconds * 1e9),
        uplink_ns=0,
        velocity=(0.0, 0.0),
        stopping=False,
        clamped=False,
    )
