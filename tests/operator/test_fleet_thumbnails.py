"""Snapshots of the other robots' cameras (DESIGN 12, 15): when the budget allows, round robin,
one picture per grab, the subscription gone afterwards; a real in-process Zenoh session."""

from __future__ import annotations

import io
import threading
import time
from dataclasses import replace

import numpy as np
import pytest
import zenoh
from egc_common import keys
from egc_common.camera_msg import CameraFrame
from egc_common.messages import Telemetry
from egc_operator.camera_view import ShownFrame
from egc_operator.fleet_thumbnails import (
    SNAPSHOT_KBPS,
    FleetThumbnails,
    next_robot,
    shrink,
    snapshots_allowed,
)
from PIL import Image

T = Telemetry(1, 1, "DRIVING", "shared", 0.1, 0.0, 0.1, 0.0, 1.0)


def test_snapshots_only_when_the_driven_robot_s_budget_leaves_room() -> None:
    assert not snapshots_allowed(None)  # nothing known of the link yet
    assert snapshots_allowed(T)  # no queue ever stood on it: it carries what is sent
    assert snapshots_allowed(replace(T, link_kbps=500.0, view_kbps=300.0))
    tight = replace(T, link_kbps=300.0 + SNAPSHOT_KBPS - 1, view_kbps=300.0)
    assert not snapshots_allowed(tight)


def test_round_robin_over_the_candidates() -> None:
    assert next_robot([], None) is None
    assert next_robot(["rc", "ra"], None) == "ra"
    assert next_robot(["rc", "ra"], "ra") == "rc"
    assert next_robot(["rc", "ra"], "rc") == "ra"
    assert next_robot(["ra", "rc"], "rb") == "rc"  # rb left


def jpeg(width: int, height: int) -> bytes:
    out = io.BytesIO()
    Image.fromarray(np.full((height, width, 3), 90, np.uint8), "RGB").save(out, format="JPEG")
    return out.getvalue()


def test_shrink_scales_down_never_up() -> None:
    big = ShownFrame(1, 1, "h264", 320, 240, True, rgb=np.zeros((240, 320, 3), np.uint8))
    data, w, h = shrink(big)
    assert (w, h) == (160, 120) and Image.open(io.BytesIO(data)).size == (160, 120)
    small = ShownFrame(1, 1, "jpeg", 80, 60, True, _jpeg=jpeg(80, 60))
    assert shrink(small)[1:] == (80, 60)


def test_a_grab_takes_one_picture_and_leaves_the_stream(session: zenoh.Session) -> None:
    """A robot streaming JPEG frames at 20 Hz: the grab returns a 160-px snapshot of one of
    them, then its subscriber is gone (frames published afterwards reach nobody)."""
    publisher = session.declare_publisher(keys.camera("rb"))
    stop = threading.Event()
    payload = jpeg(320, 240)

    def stream() -> None:
        seq = 0
        while not stop.wait(0.05):
            seq += 1
            frame = CameraFrame(seq, time.monotonic_ns(), "jpeg", 320, 240, True, payload)
            publisher.put(frame.encode())

    streamer = threading.Thread(target=stream, daemon=True)
    streamer.start()
    got: list[object] = []
    grabber = FleetThumbnails(session, lambda: ["rb"], lambda: True, got.append, grab_s=10.0)
    try:
        thumb = grabber.grab("rb", threading.Event())
        assert (
            thumb is not None
            and thumb.robot == "rb"
            and (thumb.width, thumb.height)
            == (
                160,
                120,
            )
        )
        assert Image.open(io.BytesIO(thumb.jpeg)).size == (160, 120)
        seen = grabber.bytes_received
        assert seen >= len(payload)
        time.sleep(0.3)
        assert grabber.bytes_received == seen  # unsubscribed: nothing more counted
        # nothing streams: the grab gives up after grab_s
        quiet = FleetThumbnails(session, lambda: ["rz"], lambda: True, got.append, grab_s=0.2)
        assert quiet.grab("rz", threading.Event()) is None
    finally:
        stop.set()
        streamer.join()
        publisher.undeclare()


@pytest.mark.parametrize("allowed", [False, True])
def test_the_thread_grabs_only_when_allowed(session: zenoh.Session, allowed: bool) -> None:
    grabber = FleetThumbnails(
        session, lambda: ["rb"], lambda: allowed, lambda _: None, period_s=0.05, grab_s=0.05
    )
    stop = threading.Event()
    thread = threading.Thread(target=grabber.run, args=(stop,), daemon=True)
    thread.start()
    time.sleep(0.5)
    stop.set()
    thread.join(5)
    assert (grabber.grabs > 0) == allowed
