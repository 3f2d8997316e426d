"""The robot's camera streamer (DESIGN 12): allotted rate as a ceiling, off at 0, latest-only
(a slow link never builds a queue), every payload a valid camera message, the summary's pinned
keys. Real encoder and threads; the publisher is a list (the Zenoh side is in the integration
test). Timing is checked only where the machine's load cannot make it fail: never faster than
allotted; "fast enough" waits on a condition with a generous deadline."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
from egc_common.camera_msg import CameraFrame, decode_camera
from egc_robot.camera_config import CameraConfig
from egc_robot.camera_stream import CameraStreamer

DEADLINE_S = 30.0


class Source:
    """A picture whose content and stamp change on every call (a moving camera)."""

    def __init__(self, size=(240, 320)) -> None:
        self.calls = 0
        self.size = size
        self.lock = threading.Lock()

    def __call__(self):
        with self.lock:
            self.calls += 1
            k = self.calls
        image = np.zeros((*self.size, 3), np.uint8)
        image[:, (k * 7) % self.size[1] :] = (200, 120, 40)
        return image, time.monotonic_ns()


class Sink:
    def __init__(self, delay_s: float = 0.0) -> None:
        self.payloads: list[bytes] = []
        self.at: list[int] = []
        self.delay_s = delay_s
        self.lock = threading.Lock()

    def __call__(self, payload: bytes) -> None:
        if self.delay_s:
            time.sleep(self.delay_s)  # a publisher that blocks (it never does on DROP; worst case)
        with self.lock:
            self.payloads.append(payload)
            self.at.append(time.monotonic_ns())

    def frames(self) -> list[CameraFrame]:
        with self.lock:
            decoded = [decode_camera(p) for p in self.payloads]
        assert all(isinstance(f, CameraFrame) for f in decoded), decoded
        return decoded  # type: ignore[return-value]


def wait_for(predicate, what: str) -> None:
    end = time.monotonic() + DEADLINE_S
    while not predicate():
        assert time.monotonic() < end, f"timed out waiting for {what}"
        time.sleep(0.02)


@pytest.fixture
def streamer_factory():
    made: list[CameraStreamer] = []

    def make(source, sink, **config):
        streamer = CameraStreamer(source, sink, CameraConfig("sim", **config))
        made.append(streamer)
        streamer.start()
        return streamer

    yield make
    for s in made:
        s.close()


def test_frames_are_valid_messages_in_order_never_faster_than_allotted(streamer_factory):
    sink = Sink()
    streamer = streamer_factory(Source(), sink, max_fps=10.0)
    wait_for(lambda: len(sink.payloads) >= 15, "15 frames")
    frames = sink.frames()
    assert [f.seq for f in frames] == list(range(len(frames)))
    assert all(np.diff([f.stamp_ns for f in frames]) > 0)
    assert frames[0].key and {f.codec for f in frames} == {"h264"}
    assert (frames[0].width, frames[0].height) == (320, 240)
    # Never faster than 10 frames/s: the mean interval is at least ~100 ms.
    intervals = np.diff(sink.at[:15])
    assert intervals.mean() >= 0.09e9
    summary = streamer.summary()
    assert set(summary) == {"codec", "width", "height", "frames_sent", "fps", "kbps"}
    assert summary["codec"] == "h264" and summary["frames_sent"] >= 15


def test_allotment_zero_turns_it_off_and_a_new_one_on_again(streamer_factory):
    sink = Sink()
    streamer = streamer_factory(Source(), sink, max_fps=10.0)
    wait_for(lambda: len(sink.payloads) >= 3, "3 frames")
    streamer.set_allotment(0.0, 100.0)
    time.sleep(0.3)  # a frame in flight may still land
    before = len(sink.payloads)
    time.sleep(1.0)
    assert len(sink.payloads) == before
    streamer.set_allotment(2.0, 50.0)
    wait_for(lambda: len(sink.payloads) >= before + 3, "frames after turning it on")
    # 2 frames/s: never faster; and at <= 1 s between keyframes every H.264 frame here is
    # within a second of one.
    assert np.diff(sink.at[before:]).mean() >= 0.45e9


def test_the_configured_rate_stays_the_ceiling(streamer_factory):
    sink = Sink()
    streamer = streamer_factory(Source(), sink, max_fps=5.0)
    streamer.set_allotment(30.0, 300.0)
    assert streamer.allotment == (5.0, 300.0)
    wait_for(lambda: len(sink.payloads) >= 8, "8 frames")
    assert np.diff(sink.at[:8]).mean() >= 0.18e9


def test_a_blocked_link_never_builds_a_queue(streamer_factory):
    # Each publish takes 0.4 s; the camera is allotted 10 frames/s. Nothing may queue: every
    # frame sent is the source's picture of when it was taken, not one waiting behind others.
    source = Source()
    sink = Sink(delay_s=0.4)
    streamer_factory(source, sink, max_fps=10.0)
    wait_for(lambda: len(sink.payloads) >= 5, "5 frames through the slow link")
    frames = sink.frames()
    for frame, sent_at in zip(frames, sink.at, strict=False):
        # taken at most one publish (0.4 s) plus one period before it went out
        assert sent_at - frame.stamp_ns < 2.0e9
    assert source.calls <= len(sink.payloads) + 2  # pictures are taken only when a frame is due


def test_an_unchanged_picture_is_not_sent_again(streamer_factory):
    image = np.zeros((240, 320, 3), np.uint8)
    sink = Sink()
    stamp = time.monotonic_ns()
    calls = []

    def still():
        calls.append(1)
        return image, stamp

    streamer_factory(still, sink, max_fps=20.0)
    wait_for(lambda: len(calls) >= 10, "10 polls of the source")
    assert len(sink.payloads) == 1


def test_a_failing_source_is_counted_and_the_stream_goes_on(streamer_factory):
    sink = Sink()
    source = Source()
    state = {"n": 0}

    def flaky():
        state["n"] += 1
        if state["n"] % 3 == 0:
            raise RuntimeError("camera unplugged")
        return None if state["n"] % 3 == 1 else source()

    streamer = streamer_factory(flaky, sink, max_fps=20.0)
    wait_for(lambda: len(sink.payloads) >= 3 and streamer.source_errors >= 3, "frames and errors")


def test_allotments_from_another_thread_while_it_runs(streamer_factory):
    sink = Sink()
    streamer = streamer_factory(Source(), sink, max_fps=10.0)
    rng = np.random.default_rng(1)
    for _ in range(200):
        streamer.set_allotment(float(rng.uniform(0.5, 10.0)), float(rng.uniform(20.0, 600.0)))
    streamer.set_allotment(10.0, 300.0)
    count = len(sink.payloads)
    wait_for(lambda: len(sink.payloads) >= count + 5, "frames after the storm of allotments")
    assert streamer.source_errors == 0
    frames = sink.frames()
    assert [f.seq for f in frames] == list(range(len(frames)))


def test_a_small_budget_steps_down_to_jpeg_and_a_smaller_picture(streamer_factory):
    sink = Sink()
    streamer = streamer_factory(Source(), sink, max_fps=10.0)
    streamer.set_allotment(1.0, 30.0)
    wait_for(lambda: any(f.codec == "jpeg" for f in sink.frames()), "a JPEG frame")
    jpeg = [f for f in sink.frames() if f.codec == "jpeg"][-1]
    assert (jpeg.width, jpeg.height) == (320, 240)  # 30 kbit/s at 1 frame/s: 0.39 bit/pixel
    streamer.set_allotment(1.0, 10.0)  # 0.13 bit/pixel: JPEG cannot, at half the size it can
    wait_for(lambda: any(f.width == 160 for f in sink.frames()), "160x120 JPEG")
    streamer.set_allotment(10.0, 15.0)  # 0.02 bit/pixel at 320x240: half the size
    wait_for(
        lambda: any(f.codec == "h264" and f.width == 160 for f in sink.frames()), "160x120 H.264"
    )
