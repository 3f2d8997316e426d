"""Via points and the filter in the operator view (issues 10, 11): the pure scene, then a
recording with goal telemetry read back from the .rrd."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from egc_operator import view_blueprint as paths
from egc_operator.view import record_episode
from egc_operator.view_scene import (
    NO_VIA,
    VIA_ORANGE,
    VIA_PASSED_GREY,
    status_text,
    suggested_vector,
    via_scene,
)

from tests.view.conftest import telemetry
from tests.view.rrd import read_recording

ROUTE = ((1.0, 0.0), (2.0, 0.0), (2.0, 2.0))


def test_scene_splits_the_route_at_the_robots_active_point():
    t = telemetry(1, pose=(0.5, 0.0, 0.0), goal=(2.0, 0.0), goal_frame="odom", goals_left=1)
    scene = via_scene(ROUTE, "odom", t)
    assert scene.active == (2.0, 0.0) and scene.active_label == "via 2/3 (active)"
    assert scene.others == [(1.0, 0.0), (2.0, 2.0)]
    assert scene.other_colours == [VIA_PASSED_GREY, VIA_ORANGE]
    assert scene.route == [(0.5, 0.0), (2.0, 0.0), (2.0, 2.0)]  # robot -> active -> ahead


def test_scene_without_the_route_or_without_an_active_point():
    t = telemetry(1, pose=(0.5, 0.0, 0.0), goal=(2.0, 0.0), goal_frame="map", goals_left=4)
    alone = via_scene((), None, t)  # e.g. a headless episode: the robot's echo only
    assert alone.active == (2.0, 0.0) and alone.others == []
    assert alone.active_label == "via point (active, map), 4 more"
    assert alone.route == [(0.5, 0.0), (2.0, 0.0)]
    done = via_scene(ROUTE, "odom", telemetry(1))  # no active point: the route as it is
    assert done.active is None and done.others == list(ROUTE) and done.route == list(ROUTE)
    assert via_scene((), None, telemetry(1)) == NO_VIA and NO_VIA.empty


def test_suggested_direction_and_filter_in_the_text():
    assert suggested_vector(telemetry(1)) is None
    x, y = suggested_vector(telemetry(1, suggested_rad=math.pi / 2)) or (0.0, 0.0)
    assert x == pytest.approx(0.0, abs=1e-12) and y == pytest.approx(1.0)
    text = status_text(
        telemetry(1, filter="assist", limiter="assist", goal=(2.0, 0.0), goals_left=1)
    )
    assert text.startswith("DRIVING · shared (assist) · limit: assist")
    assert text.endswith("· via 2.0,0.0 +1 more")
    assert "shared ·" in status_text(telemetry(1, filter="none"))


def _entity(path: str) -> str:
    return "/" + path


def test_a_recording_with_goal_telemetry_has_the_via_point_entities(tmp_path: Path):
    path = tmp_path / "via.rrd"
    view = record_episode(path, "sim")
    view.on_route(ROUTE, "odom")
    sent = []
    for i in range(40):
        # 0-9 first point active, 10-19 the second, 20-29 the third, then the route is done
        index = i // 10
        goal = ROUTE[index] if index < len(ROUTE) else None
        t = telemetry(
            i,
            pose=(0.05 * i, 0.0, 0.0),
            filter="assist",
            limiter="assist",
            goal=goal,
            goal_frame=None if goal is None else "odom",
            goals_left=0 if goal is None else len(ROUTE) - 1 - index,
            suggested_rad=None if goal is None else 0.1 * index,
        )
        view.on_telemetry(t)
        sent.append(t)
    view.close()
    rec = read_recording(path)
    for entity in (
        paths.VIA_ACTIVE,
        paths.VIA_POINTS,
        paths.VIA_ROUTE,
        paths.SUGGESTED_ARROW,
        paths.ROBOT_VIA,
        paths.lane_path("filter"),
    ):
        assert _entity(entity) in rec, entity
    active = rec[_entity(paths.VIA_ACTIVE)]
    positions = active.column("Points2D:positions")
    labels = active.column("Points2D:labels")
    # every active point in turn, highlighted and labelled; empty once the route is done
    shown = [tuple(p[0]) if p else None for p in positions]
    firsts = list(dict.fromkeys(shown))
    assert firsts == [(1.0, 0.0), (2.0, 0.0), (2.0, 2.0), None]
    assert "via 1/3 (active)" in [row[0] for row in labels if row]
    assert "via 3/3 (active)" in [row[0] for row in labels if row]
    others = rec[_entity(paths.VIA_POINTS)].column("Points2D:positions")
    assert [tuple(p) for p in others[0]] == [(2.0, 0.0), (2.0, 2.0)]
    assert [tuple(p) for p in others[-1]] == list(ROUTE)  # done: the route as it was
    strips = rec[_entity(paths.VIA_ROUTE)].column("LineStrips2D:strips")
    assert [tuple(p) for p in strips[0][0]] == [(0.0, 0.0), *ROUTE]  # from the robot
    arrows = rec[_entity(paths.SUGGESTED_ARROW)].column("Arrows2D:vectors")
    assert len(arrows) == 31 and arrows[-1] == []  # drawn while assist suggests, then cleared
    assert arrows[15][0] == pytest.approx([math.cos(0.1), math.sin(0.1)])
    filter_lane = rec[_entity(paths.lane_path("filter"))].column("StateChange:state")
    assert filter_lane == [["assist"]]
    seen = rec[_entity(paths.ROBOT_VIA)].column("Points2D:positions")
    assert seen[0][0] == pytest.approx([1.0, 0.0])  # in {R}: 1 m straight ahead at the start
