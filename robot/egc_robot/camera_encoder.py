"""Camera frames into H.264 (PyAV's libx264) or JPEG (Pillow), at a bitrate it is given
(DESIGN 12).

H.264 as a viewer on a thin link needs it: Annex B (each keyframe carries its SPS/PPS, so a
viewer that joins decodes from the next one), no B-frames and x264's ``zerolatency`` tune (a
frame in, its packet out: nothing waits for later frames), the ``ultrafast`` preset (a few ms a
frame at 320 x 240), a keyframe at least every second (``keyint`` = the frame rate, no scene
cuts, and one forced whenever a second has passed since the last on the capture clock, or when
asked: a new viewer, a reconfiguration), and average-bitrate rate control under a VBV of one
frame (``maxrate`` ``VBV_PEAK`` times the target, ``bufsize`` one frame period of it): no frame,
a keyframe included, is larger than 1.25 times the average frame at the target. On a thin link
that is what keeps the view fresh: a frame of B bits holds everything behind it in the link's
queue for B / rate, and with half a second of VBV (x264's usual streaming setting) a keyframe was
5 times the average frame, 250 ms on a 192 kbit/s link every second (the downlink budget then
saw a queue and cut). The price: x264 spends about 85 % of the target (measured by
``bench/bench_camera.py``), and keyframes are a little softer than the frames between them.

Changing the target at run time: a lower or higher ``kbps`` is applied to the open encoder at
once (libavcodec's libx264 wrapper calls ``x264_encoder_reconfig`` when ``bit_rate`` changes);
the VBV cap, which cannot change on an open encoder, follows at the next keyframe, where the
encoder is reopened at no extra cost (a keyframe was due anyway). A new frame rate or picture
size reopens it at once (x264 spreads the bits over the frames it was told of).

JPEG (every frame stands alone): the quality follows the frame-size target
``kbps / fps`` by ``next_jpeg_quality``.

``plan_stream`` is the pure choice of what to send for an allotment: below a few hundredths of
a bit per pixel for H.264 (a few tenths for JPEG) the picture halves (down to
``MIN_SIDE_PX``), and at one frame a second or less it is JPEG (each H.264 frame would be a
keyframe anyway, and a JPEG needs no decoder state).
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass, replace
from fractions import Fraction
from typing import Any, Final

import numpy as np
import numpy.typing as npt
from PIL import Image

RGB = npt.NDArray[np.uint8]

CODECS: Final = ("h264", "jpeg")
NS_PER_S: Final = 1_000_000_000
KEYFRAME_PERIOD_NS: Final = NS_PER_S  # DESIGN 12: a viewer that joins sees a picture within 1 s
VBV_PEAK: Final = 1.25  # the VBV's rate and one frame's size, over the target's
MIN_SIDE_PX: Final = 64  # the picture is not halved below this (height)
# Below these bits per pixel a frame is mush (H.264) or cannot be made that small at all
# (JPEG at quality 10 is ~0.27 bit/pixel at 320x240): halve the picture instead.
MIN_BITS_PER_PIXEL: Final = {"h264": 0.03, "jpeg": 0.3}
JPEG_MAX_FPS: Final = 1.0  # at or below this rate every frame is JPEG
JPEG_QUALITY: Final = (10, 90)  # the controller's range
JPEG_START_QUALITY: Final = 70
MIN_KBPS: Final = 8.0


@dataclass(frozen=True, slots=True)
class StreamPlan:
    """What the encoder produces: codec, picture size (even), frame rate and bitrate."""

    codec: str
    width_px: int
    height_px: int
    fps: float
    kbps: float

    def __post_init__(self) -> None:
        if self.codec not in CODECS:
            raise ValueError(f"codec must be one of {', '.join(CODECS)}, got {self.codec!r}")
        if self.width_px < 2 or self.height_px < 2 or self.width_px % 2 or self.height_px % 2:
            raise ValueError(f"picture size {self.width_px}x{self.height_px} must be even, >= 2")
        if not (math.isfinite(self.fps) and self.fps > 0.0):
            raise ValueError(f"fps must be positive, got {self.fps}")
        if not (math.isfinite(self.kbps) and self.kbps > 0.0):
            raise ValueError(f"kbps must be positive, got {self.kbps}")

    @property
    def bits_per_pixel(self) -> float:
        return self.kbps * 1000.0 / (self.fps * self.width_px * self.height_px)


def even(value: float) -> int:
    """The even integer nearest below ``value`` (at least 2): H.264 4:2:0 wants even sides."""
    return max(2, int(value) // 2 * 2)


def fit_size(source_w: int, source_h: int, max_w: int, max_h: int) -> tuple[int, int]:
    """The largest even size within ``max_w x max_h`` with the source's aspect ratio (never
    larger than the source)."""
    scale = min(max_w / source_w, max_h / source_h, 1.0)
    return even(source_w * scale), even(source_h * scale)


def plan_stream(
    codec: str, width_px: int, height_px: int, fps: float, kbps: float
) -> StreamPlan | None:
    """What to send for an allotment of ``fps`` and ``kbps`` with the configured ``codec`` and
    the largest picture ``width_px x height_px`` (module docstring); None when ``fps`` is 0."""
    if not (math.isfinite(fps) and fps > 0.0):
        return None
    kbps = max(MIN_KBPS, kbps if math.isfinite(kbps) else MIN_KBPS)
    w, h = even(width_px), even(height_px)
    if codec == "h264" and fps <= JPEG_MAX_FPS:
        codec = "jpeg"
    while h // 2 >= MIN_SIDE_PX and kbps * 1000.0 / (fps * w * h) < MIN_BITS_PER_PIXEL[codec]:
        w, h = even(w / 2), even(h / 2)
    return StreamPlan(codec, w, h, fps, kbps)


def next_jpeg_quality(quality: int, frame_bytes: int, target_bytes: float) -> int:
    """The next JPEG quality after a frame of ``frame_bytes`` against ``target_bytes``: a step
    proportional to the log of the ratio (JPEG's size roughly doubles per 20 quality points
    in the middle range), within ``JPEG_QUALITY``."""
    if frame_bytes <= 0 or target_bytes <= 0:
        return quality
    step = -15.0 * math.log2(frame_bytes / target_bytes)
    step = max(-20.0, min(10.0, step))
    lo, hi = JPEG_QUALITY
    return int(max(lo, min(hi, round(quality + step))))


def x264_options(plan: StreamPlan) -> dict[str, str]:
    """libx264's options for ``plan`` (module docstring)."""
    keyint = max(1, math.ceil(plan.fps))
    peak = plan.kbps * 1000 * VBV_PEAK
    return {
        "preset": "ultrafast",
        "tune": "zerolatency",
        "maxrate": str(int(peak)),
        "bufsize": str(max(1000, int(peak / plan.fps))),
        "x264-params": f"keyint={keyint}:min-keyint={keyint}:scenecut=0:bframes=0:"
        "repeat-headers=1:threads=1",
    }


@dataclass(frozen=True, slots=True)
class Encoded:
    """One encoded frame."""

    data: bytes
    key: bool
    codec: str
    width_px: int
    height_px: int


class _H264:
    """One open libx264 context for one plan (PyAV as IO: the codec). PyAV is imported here,
    not with the module: a robot without a camera does not load it (~17 MB of RSS)."""

    def __init__(self, plan: StreamPlan) -> None:
        import av

        self._av = av
        self.plan = plan
        self.vbv_kbps = plan.kbps  # the VBV cap it opened with; fixed while it is open
        ctx: Any = av.CodecContext.create("libx264", "w")
        ctx.width, ctx.height = plan.width_px, plan.height_px
        ctx.pix_fmt = "yuv420p"
        rate = Fraction(plan.fps).limit_denominator(1000)
        ctx.framerate = rate
        ctx.time_base = 1 / rate
        ctx.bit_rate = int(plan.kbps * 1000)
        ctx.options = x264_options(plan)
        ctx.open()
        self._ctx = ctx
        self._pts = 0

    def retarget(self, kbps: float) -> None:
        self._ctx.bit_rate = int(kbps * 1000)
        self.plan = replace(self.plan, kbps=kbps)

    def encode(self, rgb: RGB, key: bool) -> Encoded | None:
        av = self._av
        frame = av.VideoFrame.from_ndarray(np.ascontiguousarray(rgb), format="rgb24")
        frame = frame.reformat(
            width=self.plan.width_px, height=self.plan.height_px, format="yuv420p"
        )
        frame.pts = self._pts
        self._pts += 1
        if key:
            frame.pict_type = av.video.frame.PictureType.I
        packets = self._ctx.encode(frame)
        if not packets:
            return None
        data = b"".join(bytes(p) for p in packets)
        return Encoded(
            data,
            any(p.is_keyframe for p in packets),
            "h264",
            self.plan.width_px,
            self.plan.height_px,
        )


class CameraEncoder:
    """Frames in, ``Encoded`` out, following the plan it is given (module docstring).

    Not thread-safe: one thread (the streamer's) encodes and changes the plan.
    """

    def __init__(self) -> None:
        self._h264: _H264 | None = None
        self._plan: StreamPlan | None = None
        self._reopen_at_key = False
        self._key_requested = True
        self._last_key_ns: int | None = None
        self.jpeg_quality = JPEG_START_QUALITY
        self.reopened = 0

    @property
    def plan(self) -> StreamPlan | None:
        return self._plan

    def request_keyframe(self) -> None:
        """The next frame is a keyframe (a new viewer; after a gap)."""
        self._key_requested = True

    def set_plan(self, plan: StreamPlan) -> None:
        """Follow ``plan`` from the next frame (module docstring: when the encoder reopens)."""
        old, self._plan = self._plan, plan
        if old is None or self._h264 is None or plan.codec != "h264":
            self._h264 = None
            return
        if (plan.width_px, plan.height_px, plan.fps) != (old.width_px, old.height_px, old.fps):
            self._h264 = None  # reopened (with a keyframe) at the next frame
            return
        if plan.kbps != self._h264.plan.kbps:
            self._h264.retarget(plan.kbps)
        cap = self._h264.vbv_kbps
        self._reopen_at_key = abs(plan.kbps - cap) > 0.1 * cap

    def encode(self, rgb: RGB, stamp_ns: int) -> Encoded | None:
        """Encode one RGB frame captured at ``stamp_ns``; None when there is no plan (off) or
        the codec held the frame back (it does not with these settings)."""
        plan = self._plan
        if plan is None:
            return None
        if plan.codec == "jpeg":
            return self._jpeg(rgb, plan)
        due = (
            self._key_requested
            or self._last_key_ns is None
            or stamp_ns - self._last_key_ns >= KEYFRAME_PERIOD_NS
        )
        if self._h264 is None or (due and self._reopen_at_key):
            self._h264 = _H264(plan)
            self._reopen_at_key = False
            self.reopened += 1
            due = True
        out = self._h264.encode(rgb, key=due)
        if out is not None and out.key:
            self._last_key_ns = stamp_ns
            self._key_requested = False
        return out

    def _jpeg(self, rgb: RGB, plan: StreamPlan) -> Encoded:
        image = Image.fromarray(np.ascontiguousarray(rgb), "RGB")
        if image.size != (plan.width_px, plan.height_px):
            image = image.resize((plan.width_px, plan.height_px), Image.Resampling.BILINEAR)
        buffer = io.BytesIO()
        image.save(buffer, format="JPEG", quality=self.jpeg_quality)
        data = buffer.getvalue()
        target = plan.kbps * 1000.0 / 8.0 / plan.fps
        self.jpeg_quality = next_jpeg_quality(self.jpeg_quality, len(data), target)
        self._key_requested = False
        return Encoded(data, True, "jpeg", plan.width_px, plan.height_px)
