"""The operator's camera (DESIGN 12): real H.264 and JPEG frames from the robot's encoder; every
bad one refused with a counted reason and no exception; never an old frame shown as current."""

from __future__ import annotations

import math
import threading
import time

import msgpack
import pytest
from egc_common.camera_msg import CameraFrame
from egc_common.messages import Rejection, RejectReason
from egc_common.transport import ZenohOptions, open_session
from egc_operator.camera_view import (
    CameraFeed,
    CameraReceiver,
    RobotClock,
    ShownFrame,
    camera_text,
)
from egc_robot.camera_encoder import CameraEncoder, StreamPlan
from egc_sim.camera import CameraModel, CameraRenderer
from egc_sim.worlds import load_world

MS = 1_000_000
S = 1_000_000_000
T0 = 50 * S  # the robot's clock at the first frame


@pytest.fixture(scope="module")
def renderer() -> CameraRenderer:
    return CameraRenderer(load_world("hallway"), CameraModel(320, 240))


def stream(renderer, n: int, codec: str = "h264", fps: float = 10.0, kbps: float = 300.0):
    """n camera frames of a robot driving down the hallway, as the robot sends them."""
    encoder = CameraEncoder()
    encoder.set_plan(StreamPlan(codec, 320, 240, fps, kbps))
    frames = []
    for k in range(n):
        stamp = T0 + int(k * S / fps)
        pose = (0.6 + 0.03 * k, 1.4 + 0.2 * math.sin(0.1 * k), 0.3 * math.sin(0.13 * k))
        out = encoder.encode(renderer.render(pose), stamp)
        assert out is not None
        frames.append(
            CameraFrame(k, stamp, out.codec, out.width_px, out.height_px, out.key, out.data)
        )
    return frames


def at(frame: CameraFrame, delay_ms: float = 20.0, rtt_ms: float = 10.0) -> RobotClock:
    """The clock sync's estimate when ``frame`` arrives after ``delay_ms``."""
    return RobotClock(frame.stamp_ns + int(delay_ms * MS), int(rtt_ms / 2 * MS))


def feed(receiver: CameraReceiver, frames, **clock) -> list:
    return [receiver.receive(f.encode(), f.stamp_ns, at(f, **clock)) for f in frames]


def test_an_h264_stream_is_shown_frame_by_frame_with_its_age(renderer):
    frames = stream(renderer, 25)
    assert [f.key for f in frames].count(True) == 3  # at 0, 1 and 2 s
    receiver = CameraReceiver()
    results = feed(receiver, frames)
    assert all(isinstance(r, ShownFrame) for r in results)
    assert receiver.frames_shown == 25 and not receiver.refused and receiver.skipped == 0
    shown = receiver.shown
    assert shown is not None and shown.seq == 24 and shown.rgb.shape == (240, 320, 3)
    assert receiver.age_ms(at(frames[-1], delay_ms=35.0)) == 35
    assert not receiver.stale(35)
    jpeg = shown.jpeg()
    assert jpeg[:2] == b"\xff\xd8" and shown.jpeg() is jpeg  # encoded once


def test_jpeg_frames_are_shown_as_they_came(renderer):
    frames = stream(renderer, 5, codec="jpeg", fps=5.0)
    receiver = CameraReceiver()
    results = feed(receiver, frames)
    assert all(isinstance(r, ShownFrame) and r.codec == "jpeg" for r in results)
    assert results[-1].jpeg() == frames[-1].data and results[-1].rgb is None


def cut(frame: CameraFrame, keep: float = 0.5, key: bool | None = None) -> CameraFrame:
    data = frame.data[: max(8, int(len(frame.data) * keep))]
    return CameraFrame(
        frame.seq,
        frame.stamp_ns,
        frame.codec,
        frame.width,
        frame.height,
        frame.key if key is None else key,
        data,
    )


def wire(frame: CameraFrame, **changes) -> bytes:
    m = msgpack.unpackb(frame.encode())
    m.update(changes)
    return msgpack.packb(m, use_bin_type=True)


def test_every_bad_input_is_refused_with_a_counted_reason(renderer):
    frames = stream(renderer, 40)
    receiver = CameraReceiver()
    feed(receiver, frames[:5])  # frames 0-4 shown
    good = receiver.shown
    bad = [
        (wire(frames[5], codec="vp9"), "unknown_codec"),
        (wire(frames[5], width=100_000), "out_of_range"),
        (wire(frames[5], width=4096, height=4096), "too_large"),
        (b"\x00" * (50 * 1024 * 1024), "too_large"),
        (wire(frames[5], stamp_ns=frames[4].stamp_ns + 10 * S), "future"),
        (wire(frames[3]), "out_of_order"),  # older than the newest shown
        (wire(frames[4]), "out_of_order"),  # the same frame again
        (b"garbage", "not_msgpack"),
    ]
    for payload, reason in bad:
        result = receiver.receive(payload, 0, at(frames[4]))
        assert isinstance(result, Rejection) and result.reason.value == reason, (reason, result)
        assert receiver.shown is good  # nothing replaced the frame shown
    assert receiver.refused == {
        "unknown_codec": 1,
        "out_of_range": 1,
        "too_large": 2,
        "future": 1,
        "out_of_order": 2,
        "not_msgpack": 1,
    }
    # The stream goes on as if nothing happened: frame 5 decodes against frame 4.
    assert isinstance(receiver.receive(frames[5].encode(), 0, at(frames[5])), ShownFrame)


def test_a_cut_p_frame_is_corrupt_and_the_view_waits_for_the_next_keyframe(renderer):
    frames = stream(renderer, 25)
    receiver = CameraReceiver()
    feed(receiver, frames[:4])
    result = receiver.receive(cut(frames[4]).encode(), 0, at(frames[4]))
    assert isinstance(result, Rejection) and result.reason is RejectReason.CORRUPT
    # Frames 5-9 would decode on a broken reference: skipped, not shown as garbage.
    later = feed(receiver, frames[5:10])
    assert later == [None] * 5 and receiver.skipped == 5
    assert receiver.shown is not None and receiver.shown.seq == 3  # the last good one
    # Its age keeps growing on the robot's clock, and it is marked stale after a second.
    age = receiver.age_ms(at(frames[9]))
    assert age == (frames[9].stamp_ns - frames[3].stamp_ns) // MS + 20
    assert receiver.stale(receiver.age_ms(at(frames[9], delay_ms=600.0)))
    assert frames[10].key
    assert isinstance(receiver.receive(frames[10].encode(), 0, at(frames[10])), ShownFrame)
    assert receiver.shown.seq == 10


def test_a_cut_keyframe_raises_in_pyav_and_is_counted_corrupt(renderer):
    frames = stream(renderer, 15)
    receiver = CameraReceiver()
    result = receiver.receive(cut(frames[0], keep=0.3).encode(), 0, at(frames[0]))
    assert isinstance(result, Rejection) and result.reason is RejectReason.CORRUPT
    assert feed(receiver, frames[1:10]) == [None] * 9
    assert isinstance(receiver.receive(frames[10].encode(), 0, at(frames[10])), ShownFrame)
    assert receiver.refused == {"corrupt": 1}


@pytest.mark.parametrize(
    "tamper",
    [
        lambda f: CameraFrame(
            f.seq, f.stamp_ns, "h264", 320, 240, f.key, b"\x00\x00\x00\x01" + bytes(200)
        ),
        lambda f: CameraFrame(f.seq, f.stamp_ns, "h264", 640, 480, f.key, f.data),  # size lie
        lambda f: CameraFrame(f.seq, f.stamp_ns, "jpeg", 320, 240, True, f.data),  # H.264 as JPEG
        lambda f: CameraFrame(
            f.seq, f.stamp_ns, "h264", 320, 240, True, b"\xff\xd8\xff" + bytes(99)
        ),
    ],
)
def test_pictures_that_do_not_decode_are_corrupt(renderer, tamper):
    frames = stream(renderer, 3)
    receiver = CameraReceiver()
    result = receiver.receive(tamper(frames[0]).encode(), 0, at(frames[0]))
    assert isinstance(result, Rejection) and result.reason is RejectReason.CORRUPT, result
    assert receiver.shown is None


def test_a_p_frame_claiming_to_be_a_keyframe_is_corrupt(renderer):
    frames = stream(renderer, 5)
    receiver = CameraReceiver()
    lie = CameraFrame(1, frames[1].stamp_ns, "h264", 320, 240, True, frames[1].data)
    result = receiver.receive(lie.encode(), 0, at(frames[1]))
    assert isinstance(result, Rejection) and result.reason is RejectReason.CORRUPT


def test_a_gap_in_seq_waits_for_a_keyframe(renderer):
    frames = stream(renderer, 15)
    receiver = CameraReceiver()
    feed(receiver, frames[:3])
    assert feed(receiver, frames[5:10]) == [None] * 5  # 3 and 4 were lost on the way
    assert isinstance(receiver.receive(frames[10].encode(), 0, at(frames[10])), ShownFrame)
    assert not receiver.refused


def test_the_stream_switching_size_and_codec_is_shown_throughout(renderer):
    # What a budget does to the stream: 320x240 H.264, then 160x120, then JPEG at 1 frame/s,
    # then back: every frame decodes, nothing is refused or skipped.
    encoder = CameraEncoder()
    receiver = CameraReceiver()
    plans = {
        0: StreamPlan("h264", 320, 240, 10.0, 300.0),
        10: StreamPlan("h264", 160, 120, 10.0, 50.0),
        20: StreamPlan("jpeg", 320, 240, 1.0, 50.0),
        25: StreamPlan("h264", 320, 240, 10.0, 300.0),
    }
    for k in range(30):
        if k in plans:
            encoder.set_plan(plans[k])
        stamp = T0 + k * 100 * MS
        out = encoder.encode(renderer.render((0.6 + 0.05 * k, 1.4, 0.0)), stamp)
        assert out is not None
        frame = CameraFrame(k, stamp, out.codec, out.width_px, out.height_px, out.key, out.data)
        shown = receiver.receive(frame.encode(), 0, at(frame))
        assert isinstance(shown, ShownFrame) and (shown.width, shown.codec) == (
            out.width_px,
            out.codec,
        )
    assert not receiver.refused and receiver.skipped == 0


def test_a_future_frame_within_the_clock_error_is_taken():
    # The clock sync's error is half its round trip: a stamp within it is not "the future".
    receiver = CameraReceiver()
    frame = CameraFrame(0, 10 * S, "jpeg", 16, 16, True, _tiny_jpeg())
    late_clock = RobotClock(10 * S - 100 * MS, 120 * MS)  # 100 ms behind, error 120 ms
    assert isinstance(receiver.receive(frame.encode(), 0, late_clock), ShownFrame)
    assert receiver.age_ms(late_clock) == 0  # never negative


def _tiny_jpeg() -> bytes:
    import io

    from PIL import Image

    buffer = io.BytesIO()
    Image.new("RGB", (16, 16), (10, 200, 30)).save(buffer, format="JPEG")
    return buffer.getvalue()


def test_without_a_clock_the_age_is_unknown_and_the_frame_counts_as_stale(renderer):
    frames = stream(renderer, 2)
    receiver = CameraReceiver()
    assert isinstance(receiver.receive(frames[0].encode(), 0, None), ShownFrame)
    stats = receiver.stats(0, None)
    assert stats.age_ms is None and stats.stale
    assert "age unknown" in camera_text(stats, "h264", (320, 240))


def test_a_new_robot_forgets_the_old_frames(renderer):
    frames = stream(renderer, 3)
    receiver = CameraReceiver()
    feed(receiver, frames)
    receiver.reset()
    assert receiver.shown is None
    # The new robot's stream starts again at seq 0 on another clock: taken.
    restarted = stream(renderer, 1)[0]
    older = CameraFrame(0, 5 * S, "h264", 320, 240, True, restarted.data)
    assert isinstance(receiver.receive(older.encode(), 0, RobotClock(5 * S, MS)), ShownFrame)


def test_rates_over_the_last_second(renderer):
    frames = stream(renderer, 30)
    receiver = CameraReceiver()
    for f in frames:
        receiver.receive(f.encode(), f.stamp_ns - T0, at(f))
    stats = receiver.stats(frames[-1].stamp_ns - T0, at(frames[-1]))
    assert stats.fps == pytest.approx(10.0, abs=1.0)
    sent = sum(len(f.encode()) for f in frames[-10:])
    assert stats.kbps == pytest.approx(sent * 8 / 1000, rel=0.25)
    assert "ms old, 10 fps" in camera_text(stats, "h264", (320, 240))


class RecordingView:
    def __init__(self) -> None:
        self.frames: list[tuple[ShownFrame, str]] = []
        self.texts: list[tuple[str, bool]] = []
        self.lock = threading.Lock()

    def on_camera(self, frame: ShownFrame, text: str, robot_now_ns: int | None) -> None:
        with self.lock:
            self.frames.append((frame, text))

    def on_camera_text(self, text: str, stale: bool, robot_now_ns: int | None) -> None:
        with self.lock:
            self.texts.append((text, stale))


def test_the_feed_over_a_real_zenoh_session(renderer):
    """Frames published on egc/<robot>/camera reach the view in order; refusals go to the
    operator's counter; the age line turns stale when frames stop."""
    frames = stream(renderer, 12)
    offset = T0 - time.monotonic_ns()  # the robot's clock is ours shifted

    def robot_clock(local_ns: int) -> RobotClock:
        return RobotClock(local_ns + offset, MS)

    session = open_session(ZenohOptions())
    view = RecordingView()
    refused: list[tuple[str, Rejection]] = []
    camera = CameraFeed(
        session, "cam", robot_clock, view, on_reject=lambda k, r: refused.append((k, r))
    )
    try:
        publisher = session.declare_publisher("egc/cam/camera")
        for f in frames:
            restamped = CameraFrame(
                f.seq, time.monotonic_ns() + offset, f.codec, f.width, f.height, f.key, f.data
            )
            publisher.put(restamped.encode())
        publisher.put(b"\x93not a camera frame")
        end = time.monotonic() + 30.0
        while (len(view.frames) < 12 or not refused) and time.monotonic() < end:
            time.sleep(0.02)
        assert [f.seq for f, _ in view.frames] == list(range(12))
        assert refused and refused[0][0] == "camera"
        age = camera.camera_age_ms()
        assert age is not None and age >= 0
        time.sleep(1.2)  # no new frame for over a second
        camera.tick()
        assert view.texts and view.texts[-1][1] is True and "STALE" in view.texts[-1][0]
    finally:
        camera.close()
        session.close()
