"""The fleet in the operator view (DESIGN 15), read back from the .rrd: the fleet table, the
robots sharing the driven robot's map drawn at their map poses, the other robots' camera
snapshots in a row, and per-robot views on one recording (closing one leaves it open)."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
from egc_common.messages import StateMessage
from egc_common.robot_info import RobotInfo
from egc_operator import view_blueprint as paths
from egc_operator.fleet_table import fleet_rows
from egc_operator.fleet_thumbnails import Thumbnail
from egc_operator.view import record_episode
from PIL import Image

from tests.view.conftest import telemetry
from tests.view.rrd import read_recording

S = 1_000_000_000


def info(robot: str, map_id: str) -> RobotInfo:
    return RobotInfo(robot, "IDLE", "sim", "pioneer3dx", "egc", "sim", "0.1", map=map_id)


def test_the_fleet_panel_map_and_snapshots(tmp_path: Path) -> None:
    path = tmp_path / "fleet.rrd"
    fleet = record_episode(path, "fleet")
    first = fleet.for_robot("ra")
    for i in range(5):
        first.on_telemetry(telemetry(i))
    first.clear_on_close = True  # switched away from it
    first.close()  # the recording stays open
    second = fleet.for_robot("rb")
    for i in range(5, 10):
        second.on_telemetry(telemetry(i))
    assert second.latest_telemetry() is not None
    now = telemetry(9).stamp_ns
    states = {
        "ra": (StateMessage(now, "HOLD", "deadman released", None, map_pose=(1.0, 2.0, 0.0)), 0),
        "rb": (StateMessage(now, "DRIVING", "fresh", "me", map_pose=(3.0, 4.0, 0.0)), 0),
        "rc": (StateMessage(now, "IDLE", "no operator", None, map_pose=(5.0, 6.0, 0.0)), 0),
    }
    infos = {"ra": info("ra", "grid:1"), "rb": info("rb", "grid:1"), "rc": info("rc", "grid:2")}
    rows = fleet_rows(["ra", "rb", "rc"], infos, states, {"ra": 1.5}, "rb", 0)
    fleet.on_fleet(rows, "me", now)
    fleet.on_fleet(rows, "me", None)  # the driven robot's clock unknown: nothing drawn
    picture = io.BytesIO()
    Image.fromarray(np.zeros((120, 160, 3), np.uint8), "RGB").save(picture, format="JPEG")
    fleet.on_thumbnail(Thumbnail("ra", picture.getvalue(), 160, 120, now, 0), 0, now)
    second.close()
    fleet.close()

    rec = read_recording(path)
    table = rec["/" + paths.FLEET_TABLE].column("TextDocument:text")
    assert len(table) == 1 and "**rb (driven)**" in table[0][0] and "1.5 ms" in table[0][0]
    poses = rec["/" + paths.FLEET_POSES]
    # ra shares rb's map frame; rc is in another one; rb itself is drawn from its telemetry
    assert poses.column("Points2D:labels") == [["ra HOLD"]]
    assert np.allclose(poses.column("Points2D:positions")[0], [[1.0, 2.0]])
    assert len(rec[f"/{paths.FLEET_CAMERAS}/ra/image"]) == 1
    # ra's drawings were cleared when the operator switched away from it, at its last time
    assert "Clear:is_recursive" in rec["/" + paths.TRAJECTORY].rows.column_names
    assert len(rec["/" + paths.SCAN]) >= 10  # both robots' scans, one recording
