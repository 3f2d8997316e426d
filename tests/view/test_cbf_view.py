"""cbf in the operator view (DESIGN 13): the points that constrain and the margin over the scan.

From the robot's controller (the telemetry keys it fills), over the wire (strict decoding), to
the scene and a recording read back from the .rrd.
"""

from __future__ import annotations

import math
from pathlib import Path

import msgpack
import numpy as np
import pytest
from egc_common.messages import MAX_CBF_POINTS, RejectReason, Telemetry, decode_telemetry
from egc_common.profiles import JACKAL
from egc_common.scan import Scan
from egc_operator import view_blueprint as paths
from egc_operator.view import record_episode
from egc_operator.view_scene import cbf_margin_outline, robot_frame_scene
from egc_robot.controller import ControllerConfig, RobotController
from egc_robot.pipeline import PipelineConfig

from tests.robot.test_controller import MS, T0, raw
from tests.view.conftest import telemetry
from tests.view.rrd import read_recording


def wall_scan(distance_m: float, n: int = 360) -> Scan:
    """A wall across the path ``distance_m`` ahead of {R}'s origin, free (+inf) elsewhere."""
    a = -math.pi + 2 * math.pi * np.arange(n) / n
    r = np.full(n, np.inf)
    ahead = np.abs(a) < math.radians(60)
    r[ahead] = distance_m / np.cos(a[ahead])
    return Scan(a, r, 0.05, 10.0, no_return_is_free=True)


def test_the_controller_reports_what_cbf_did():
    c = RobotController(ControllerConfig(PipelineConfig(JACKAL, filter="cbf")), T0)
    now, seq = T0, 0
    out = None
    for x, wall in ((0.0, 5.0), (0.4, 5.0), (0.4, 0.55)):
        for _ in range(5):
            seq += 1
            c.on_command(raw(seq=seq, stamp_ns=now - MS, x=x, y=0.0), now)
            now += 20 * MS
            c.on_scan(wall_scan(wall), now)
            out = c.step(now)
    assert out is not None
    t = out.telemetry
    assert t.filter == "cbf" and t.limiter == "cbf"
    assert t.cbf_margin_m == pytest.approx(0.12) and t.cbf_ahead_m >= t.cbf_margin_m
    assert 0 < len(t.cbf_xy) <= MAX_CBF_POINTS
    assert (t.cbf_xy[:, 0] > 0.5).all()  # the wall's points, ahead
    back = decode_telemetry(t.encode())
    assert isinstance(back, Telemetry)
    np.testing.assert_array_equal(back.cbf_xy, t.cbf_xy)
    assert back.cbf_ahead_m == pytest.approx(t.cbf_ahead_m)


def test_without_cbf_the_keys_stay_off_the_wire():
    t = telemetry(1)
    assert not {"cbf_xy", "cbf_margin_m", "cbf_ahead_m"} & set(msgpack.unpackb(t.encode()))
    back = decode_telemetry(t.encode())
    assert isinstance(back, Telemetry) and back.cbf_margin_m is None and len(back.cbf_xy) == 0


@pytest.mark.parametrize(
    ("key", "value", "reason"),
    [
        ("cbf_xy", np.zeros((MAX_CBF_POINTS + 1, 2), "<f4").tobytes(), RejectReason.TOO_LARGE),
        ("cbf_xy", np.array([[np.nan, 0.0]], "<f4").tobytes(), RejectReason.NOT_FINITE),
        ("cbf_xy", b"\x00" * 12, RejectReason.OUT_OF_RANGE),
        ("cbf_margin_m", -0.1, RejectReason.OUT_OF_RANGE),
        ("cbf_ahead_m", "far", RejectReason.WRONG_TYPE),
    ],
)
def test_bad_cbf_keys_are_rejected(key, value, reason):
    wire = msgpack.unpackb(telemetry(1).encode())
    wire[key] = value
    assert decode_telemetry(msgpack.packb(wire)).reason is reason


def test_the_margin_is_drawn_around_the_footprint_and_out_ahead():
    hl, hw = JACKAL.half_size_m
    outline = cbf_margin_outline(JACKAL, 0.12, 0.5, reversing=False)
    xs, ys = [p[0] for p in outline], [p[1] for p in outline]
    assert outline[0] == outline[-1]
    assert max(xs) == pytest.approx(hl + 0.5) and min(xs) == pytest.approx(-hl - 0.12)
    assert max(ys) == pytest.approx(hw + 0.12)
    back = cbf_margin_outline(JACKAL, 0.12, 0.5, reversing=True)
    assert min(p[0] for p in back) == pytest.approx(-hl - 0.5)
    t = telemetry(1, profile="jackal", cbf_xy=np.array([[0.9, 0.1]], np.float32),
                  cbf_margin_m=0.12, cbf_ahead_m=0.5)  # fmt: skip
    scene = robot_frame_scene(t)
    assert scene.cbf_margin == outline and scene.cbf_xy.tolist() == [
        [pytest.approx(0.9), pytest.approx(0.1)]
    ]
    assert robot_frame_scene(telemetry(1, profile="jackal")).cbf_margin is None


def test_a_recording_shows_the_constraining_points_and_the_margin(tmp_path: Path):
    path = tmp_path / "cbf.rrd"
    view = record_episode(path, "sim")
    for i in range(6):
        pts = np.array([[0.9, 0.1 * i]], np.float32) if i % 2 else np.zeros((0, 2), np.float32)
        view.on_telemetry(
            telemetry(
                i,
                profile="jackal",
                filter="cbf",
                limiter="cbf" if i % 2 else "none",
                cbf_xy=pts,
                cbf_margin_m=0.12,
                cbf_ahead_m=0.3 + 0.01 * i,
            )
        )
    view.close()
    rec = read_recording(path)
    points = rec["/" + paths.CBF_POINTS].column("Points2D:positions")
    assert [len(p) for p in points] == [0, 1, 0, 1, 0, 1]
    assert points[3][0] == pytest.approx([0.9, 0.3])
    strips = rec["/" + paths.CBF_MARGIN].column("LineStrips2D:strips")
    assert len(strips) == 6 and all(len(s) == 1 for s in strips)
    assert max(p[0] for p in strips[5][0]) == pytest.approx(JACKAL.half_size_m[0] + 0.35)
