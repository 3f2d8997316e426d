"""The operator view's recording, read back: entity paths, one row per message, values."""

from __future__ import annotations

import threading
from pathlib import Path

import numpy as np
import pytest
from egc_common.messages import StateMessage, Telemetry
from egc_operator import view_blueprint as paths
from egc_operator.view import OperatorView, record_episode
from egc_operator.view_scene import command_vector, status_text
from rerun.chunk import RrdReader

from tests.view.conftest import telemetry
from tests.view.rrd import read_recording

N = 60
PER_CYCLE = [
    paths.SCAN,
    paths.FOOTPRINT,
    paths.STATUS,
    *(paths.circle_path(c) for c in ("reachable", "igc", "agc", "egc")),
    paths.REFERENCE_ARROW,
    paths.SENT_ARROW,
    *(paths.plot_path(p) for p in ("v/ref", "v/cmd", "w/ref", "w/cmd", "w_si")),
]


def _entity(path: str) -> str:
    return "/" + path


def _run(path: Path) -> list:  # type: ignore[type-arg]
    """A 60-cycle run: cycle 10 without circles, 20-29 without pose, 30 on in HOLD."""
    view = record_episode(path, "sim", recording_name="test run")
    view.set_world(np.eye(8, dtype=bool), 0.5, (-1.0, -2.0), goal_xy_m=(3.0, 1.0))
    view.on_state(StateMessage(1_000_000_000, "IDLE", "no operator"))
    sent = []
    for i in range(N):
        overrides: dict[str, object] = {}
        if i == 10:
            overrides.update(igc=None, agc=None, egc=None, r_rc=0.0)
        if 20 <= i < 30:
            overrides["pose"] = None
        if i >= 30:
            overrides.update(state="HOLD", limiter="watchdog", cmd_age_ms=None, rejected=3)
        t = telemetry(i, **overrides)
        view.on_telemetry(t)
        sent.append(t)
        if i % 10 == 0:
            view.on_link(5.0 + i, t.stamp_ns - 1_000)  # offset: robot clock - our clock
    view.on_state(StateMessage(sent[30].stamp_ns, "HOLD", "command timeout", "op1", rejected=3))
    view.on_state(StateMessage(sent[31].stamp_ns, "HOLD", "command timeout", "op1", rejected=3))
    view.on_text("warning", "telemetry rejected: not_msgpack")
    view.close()
    return sent


@pytest.fixture(scope="module")
def recording_path(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list]:  # type: ignore[type-arg]
    path = tmp_path_factory.mktemp("view") / "run.rrd"
    return path, _run(path)


@pytest.fixture(scope="module")
def recorded(recording_path) -> tuple[dict, list]:  # type: ignore[no-untyped-def, type-arg]
    path, sent = recording_path
    return read_recording(path), sent


def test_the_file_carries_the_default_layout(recording_path) -> None:  # type: ignore[no-untyped-def]
    """Opening the .rrd shows the operator console, not Rerun's automatic layout."""
    reader = RrdReader(recording_path[0])
    (blueprint,) = reader.blueprints()
    assert blueprint.application_id == "egc-teleop"
    views = {}
    for chunk in reader.stream(store=blueprint).to_chunks():
        batch = chunk.to_record_batch()
        if "ViewBlueprint:class_identifier" in batch.schema.names:
            kind = batch.column("ViewBlueprint:class_identifier").to_pylist()[0][0]
            origin = batch.column("ViewBlueprint:space_origin").to_pylist()[0][0]
            views.setdefault(kind, set()).add(origin)
    assert views == {
        # robot frame and world frame (each selects its subtree), the camera (DESIGN 12)
        "2D": {"/", paths.CAMERA},
        "StateTimeline": {paths.LANES},
        "TextLog": {paths.TEXT_LOG},
        "TextDocument": {paths.LINK_TEXT},  # the link figures in plain numbers
        "TimeSeries": {"plots/v", "plots/w", "plots/w_si", "plots/latency"},
    }


def test_every_view_entity_is_in_the_recording(recorded) -> None:  # type: ignore[no-untyped-def]
    rec, _ = recorded
    expected = {
        *PER_CYCLE,
        paths.ROBOT,
        paths.WORLD,
        paths.MAP,
        paths.GOAL,
        paths.TRAJECTORY,
        paths.ROBOT_POSE,
        paths.POSE_FOOTPRINT,
        paths.LINK_RTT,
        paths.TEXT_LOG,
        paths.plot_path("latency/cmd_age_ms"),
        paths.plot_path("latency/scan_age_ms"),
        *(paths.lane_path(lane) for lane in ("state", "mode", "limiter", "region")),
    }
    assert {_entity(p) for p in expected} <= set(rec)


def test_one_row_per_telemetry_message_for_every_per_cycle_entity(recorded) -> None:  # type: ignore[no-untyped-def]
    rec, sent = recorded
    for path in PER_CYCLE:
        assert len(rec[_entity(path)]) == N, path
    with_age = sum(t.cmd_age_ms is not None for t in sent)
    assert len(rec[_entity(paths.plot_path("latency/cmd_age_ms"))]) == with_age == 30
    with_pose = sum(t.pose is not None for t in sent)
    assert len(rec[_entity(paths.ROBOT_POSE)]) == with_pose == N - 10
    assert len(rec[_entity(paths.LINK_RTT)]) == N // 10


def test_both_timelines_carry_the_robots_clock_and_cycle(recorded) -> None:  # type: ignore[no-untyped-def]
    rec, sent = recorded
    for path in (paths.SCAN, paths.plot_path("v/cmd")):
        entity = rec[_entity(path)]
        assert entity.column("cycle") == [t.cycle for t in sent]
        stamps = entity.rows.column("robot_time").cast("int64").to_pylist()
        assert stamps == [t.stamp_ns for t in sent]


def test_time_series_values(recorded) -> None:  # type: ignore[no-untyped-def]
    rec, sent = recorded
    for name, attr in (
        ("v/ref", "v_ref"),
        ("v/cmd", "v_cmd"),
        ("w/ref", "w_ref"),
        ("w/cmd", "w_cmd"),
    ):
        values = [row[0] for row in rec[_entity(paths.plot_path(name))].column("Scalars:scalars")]
        assert values == pytest.approx([getattr(t, attr) for t in sent])
    rtts = [r[0] for r in rec[_entity(paths.LINK_RTT)].column("Scalars:scalars")]
    assert rtts == pytest.approx([5.0 + i for i in range(0, N, 10)])


def test_robot_frame_values(recorded) -> None:  # type: ignore[no-untyped-def]
    rec, sent = recorded
    scans = rec[_entity(paths.SCAN)].column("Points2D:positions")
    assert np.allclose(scans[7], sent[7].scan_xy)
    igc = rec[_entity(paths.circle_path("igc"))]
    centres, half_sizes = igc.column("Ellipses2D:centers"), igc.column("Ellipses2D:half_sizes")
    assert centres[10] == [] and half_sizes[10] == []  # cycle 10 had no circles: cleared
    cx, cy, r = sent[0].igc
    assert np.allclose(centres[0], [[cx, cy]]) and np.allclose(half_sizes[0], [[r, r]])
    footprint = rec[_entity(paths.FOOTPRINT)].column("Boxes2D:half_sizes")
    assert np.allclose(footprint[0], [[0.455 / 2, 0.381 / 2]])
    arrows = rec[_entity(paths.SENT_ARROW)].column("Arrows2D:vectors")
    assert arrows[5][0] == pytest.approx(
        command_vector(sent[5].v_cmd, sent[5].w_cmd, 4.25), rel=1e-5
    )
    labels = rec[_entity(paths.STATUS)].column("Points2D:labels")
    assert labels[40] == [status_text(sent[40])]
    assert "limit: watchdog" in labels[40][0]


def test_status_lanes_log_changes_only(recorded) -> None:  # type: ignore[no-untyped-def]
    rec, _ = recorded
    state = rec[_entity(paths.lane_path("state"))]
    assert state.column("StateChange:state") == [["DRIVING"], ["HOLD"]]
    assert state.column("cycle") == [0, 30]
    assert rec[_entity(paths.lane_path("limiter"))].column("StateChange:state") == [
        ["egc"],
        ["watchdog"],
    ]
    assert rec[_entity(paths.lane_path("mode"))].column("StateChange:state") == [["shared"]]


def test_text_log_has_state_changes_rejections_and_operator_events(recorded) -> None:  # type: ignore[no-untyped-def]
    rec, _ = recorded
    log = rec[_entity(paths.TEXT_LOG)]
    texts = [row[0] for row in log.column("TextLog:text")]
    assert texts == [
        "robot state IDLE: no operator",
        "robot rejected 3 more command(s) (3 in total)",
        "robot state HOLD: command timeout (operator op1)",  # the repeat is not logged again
        "telemetry rejected: not_msgpack",
    ]
    assert [row[0] for row in log.column("TextLog:level")] == ["INFO", "WARN", "WARN", "WARN"]


def test_world_frame(recorded) -> None:  # type: ignore[no-untyped-def]
    rec, sent = recorded
    poses = rec[_entity(paths.ROBOT_POSE)].column("Transform3D:translation")
    with_pose = [t for t in sent if t.pose is not None]
    expected = [[t.pose[0], t.pose[1], 0.0] for t in with_pose]
    assert np.allclose(np.reshape(poses, (-1, 3)), expected, atol=1e-6)
    segments = rec[_entity(paths.TRAJECTORY)].column("LineStrips2D:strips")
    assert len(segments) == len(with_pose) - 1  # every pose moved >= 2 cm
    assert np.allclose(segments[0][0], [[0.0, 0.0], [0.05, 0.0]])
    goal = rec[_entity(paths.GOAL)]
    assert goal.static_column("Points2D:positions") == [[[3.0, 1.0]]]
    map_ = rec[_entity(paths.MAP)]
    assert map_.static_column("Transform3D:translation") == [[[-1.0, 2.0, 0.0]]]  # top-left corner


def test_concurrent_callers_lose_nothing(tmp_path: Path) -> None:
    """Zenoh calls from its own threads: telemetry and link samples interleave safely."""
    view = record_episode(tmp_path / "threads.rrd", "sim")

    def telemetry_thread() -> None:
        for i in range(200):
            view.on_telemetry(telemetry(i))

    def link_thread() -> None:
        for i in range(200):
            view.on_link(float(i), 0)

    threads = [threading.Thread(target=telemetry_thread), threading.Thread(target=link_thread)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    view.close()
    rec = read_recording(tmp_path / "threads.rrd")
    assert len(rec[_entity(paths.SCAN)]) == 200
    assert len(rec[_entity(paths.LINK_RTT)]) == 200
    assert rec[_entity(paths.SCAN)].column("cycle") == list(range(200))


def test_after_close_and_disabled_views_drop_messages(tmp_path: Path) -> None:
    view = record_episode(tmp_path / "closed.rrd", "sim")
    view.on_telemetry(telemetry(0))
    view.close()
    view.on_telemetry(telemetry(1))  # ignored, no error
    view.close()  # idempotent
    assert len(read_recording(tmp_path / "closed.rrd")[_entity(paths.SCAN)]) == 1
    disabled = OperatorView(None, "sim")
    disabled.on_telemetry(telemetry(0))
    disabled.on_state(StateMessage(0, "IDLE", "x"))
    disabled.on_text("info", "x")
    disabled.on_link(1.0, 0)
    disabled.set_world(np.zeros((2, 2), bool), 0.1, (0.0, 0.0))
    disabled.close()


def test_text_before_the_robots_clock_is_known_waits_for_it(tmp_path: Path) -> None:
    """An event logged at robot time 0 would stretch the timeline from 0 to the robot's uptime."""
    view = record_episode(tmp_path / "early.rrd", "sim")
    view.on_text("info", "robot present")
    view.on_text("warn", "telemetry rejected: too_large")
    first = telemetry(5)
    view.on_telemetry(first)
    view.close()
    log = read_recording(tmp_path / "early.rrd")[_entity(paths.TEXT_LOG)]
    assert [r[0] for r in log.column("TextLog:text")] == [
        "robot present",
        "telemetry rejected: too_large",
    ]
    assert log.rows.column("robot_time").cast("int64").to_pylist() == [first.stamp_ns] * 2
    assert log.column("cycle") == [first.cycle] * 2


def test_text_without_any_robot_is_kept_at_time_zero(tmp_path: Path) -> None:
    view = record_episode(tmp_path / "alone.rrd", "sim")
    view.on_text("warn", "no robot answers")
    view.close()
    log = read_recording(tmp_path / "alone.rrd")[_entity(paths.TEXT_LOG)]
    assert [r[0] for r in log.column("TextLog:text")] == ["no robot answers"]
    assert log.rows.column("robot_time").cast("int64").to_pylist() == [0]


def test_a_round_robot_is_drawn_round(tmp_path: Path) -> None:
    """DESIGN 14: a footprint that is not a centred rectangle is drawn as its outline, in the
    robot frame and on the map (a TurtleBot 4: a circle of radius 0.171 m)."""
    path = tmp_path / "round.rrd"
    view = record_episode(path, "sim", recording_name="round")
    for i in range(3):
        view.on_telemetry(telemetry(i, profile="turtlebot4"))
    view.close()
    rec = read_recording(path)
    strips = rec[_entity(paths.FOOTPRINT)].column("LineStrips2D:strips")
    outline = np.array(strips[0][0])
    assert len(outline) == 33 and np.allclose(np.hypot(*outline.T), 0.171)
    world = rec[_entity(paths.POSE_FOOTPRINT)].static_column("LineStrips2D:strips")
    assert np.allclose(np.hypot(*np.array(world[0][0]).T), 0.171)


def test_the_status_text_names_the_source_and_the_lock():
    """DESIGN 14: which source drives and which lock holds, in the robot-frame view."""
    t = Telemetry(1, 1, "DRIVING", "shared", 0.1, 0.0, 0.1, 0.0, 1.0, source="nav", lock="pause")
    assert status_text(t).endswith(" · source nav · lock pause")
    assert "source" not in status_text(Telemetry(1, 1, "IDLE", "shared", 0, 0, 0, 0, 1.0))
