"""The camera panel of the operator view (DESIGN 12), read back from a real .rrd: each shown
frame a JPEG on ``camera/image`` with its age line, dimmed and labelled stale when no new frame
came for a second, and lit again by the next frame; rows never go back in time."""

from __future__ import annotations

import io
import itertools
import math

import numpy as np
from egc_common.camera_msg import CameraFrame
from egc_operator import view_blueprint as paths
from egc_operator.camera_view import CameraReceiver, RobotClock, ShownFrame, camera_text
from egc_operator.view import CAMERA_STALE_OPACITY, record_episode
from egc_robot.camera_encoder import CameraEncoder, StreamPlan
from egc_sim.camera import CameraModel, CameraRenderer
from egc_sim.worlds import load_world
from PIL import Image

from tests.view.rrd import read_recording

MS = 1_000_000
S = 1_000_000_000
T0 = 20 * S


def test_frames_age_and_stale_mark_in_a_recording(tmp_path):
    renderer = CameraRenderer(load_world("hallway"), CameraModel(320, 240))
    encoder = CameraEncoder()
    encoder.set_plan(StreamPlan("h264", 320, 240, 10.0, 300.0))
    receiver = CameraReceiver()
    path = tmp_path / "camera.rrd"
    view = record_episode(path, "sim")
    shown: list[ShownFrame] = []
    for k in range(12):
        stamp = T0 + k * 100 * MS
        out = encoder.encode(renderer.render((0.6 + 0.05 * k, 1.4, 0.1 * math.sin(k))), stamp)
        assert out is not None
        frame = CameraFrame(k, stamp, out.codec, out.width_px, out.height_px, out.key, out.data)
        clock = RobotClock(stamp + 30 * MS, 2 * MS)
        result = receiver.receive(frame.encode(), stamp, clock)
        assert isinstance(result, ShownFrame)
        shown.append(result)
        text = camera_text(receiver.stats(stamp, clock), "h264", (320, 240))
        view.on_camera(result, text, clock.now_ns)
    last = shown[-1].stamp_ns
    # No frame for 1.5 s: the age line goes stale, the picture is dimmed.
    later = RobotClock(last + 1500 * MS, 2 * MS)
    stats = receiver.stats(last - T0 + 1500 * MS, later)
    assert stats.stale
    view.on_camera_text(camera_text(stats, "h264", (320, 240)), True, later.now_ns)
    # A frame captured before the stale mark but shown after it still comes out on top.
    out = encoder.encode(renderer.render((1.3, 1.4, 0.0)), last + 1400 * MS)
    assert out is not None
    fresh = ShownFrame(12, last + 1400 * MS, "h264", 320, 240, out.key, rgb=shown[-1].rgb)
    view.on_camera(fresh, "camera 150 ms old", last + 1450 * MS)
    view.close()

    rec = read_recording(path)
    image = rec[f"/{paths.CAMERA_IMAGE}"]
    blobs = [b for b in image.column("EncodedImage:blob") if b is not None]
    assert len(blobs) == 13
    first = Image.open(io.BytesIO(bytes(blobs[0][0])))
    assert first.format == "JPEG" and first.size == (320, 240)
    assert image.column("EncodedImage:media_type")[0] == ["image/jpeg"]
    opacities = [o[0] for o in image.column("EncodedImage:opacity") if o is not None]
    assert opacities[-2] == np.float32(CAMERA_STALE_OPACITY) and opacities[-1] == 1.0
    times = image.column(paths.ROBOT_TIME)
    assert all(b >= a for a, b in itertools.pairwise(times))
    labels = [row[0] for row in rec[f"/{paths.CAMERA_AGE}"].column("Points2D:labels")]
    assert labels[0].startswith("camera ") and "ms old" in labels[0]
    assert "STALE" in labels[-2] and labels[-1] == "camera 150 ms old"
