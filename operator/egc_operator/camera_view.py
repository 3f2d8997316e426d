"""The robot's camera on the operator (DESIGN 12): ``egc/<robot>/camera`` -> decoded frame ->
the view, with the frame's age on the robot's clock, and never an old frame as if it were new.

``CameraReceiver`` holds the rules, with time and the robot's clock passed in; each payload is
shown or refused with a counted reason (``RejectReason`` values):

- what ``decode_camera`` refuses: a payload over the cap (checked before msgpack sees it),
  not msgpack, wrong types, an unknown codec (``unknown_codec``), sizes outside
  16..4096 px or beyond 4K's pixel count (``out_of_range`` / ``too_large``);
- a frame stamped after the robot's clock now by more than the clock sync's error (half its
  best round trip) and ``FUTURE_SLACK_NS`` (``future``): it is on no clock of this robot's;
- a frame not newer than the newest one taken (``out_of_order``);
- a picture that does not decode (``corrupt``): PyAV raises on a cut keyframe and flags a cut
  or damaged P-frame as corrupt (a single-threaded decoder: libavcodec's frame threads lose
  that flag); a JPEG that Pillow cannot read; a picture of another size than the message says.

H.264 frames depend on the ones before them: after a gap in ``seq``, a corrupt frame or a new
robot, the decoder waits for the next keyframe (at most a second away, DESIGN 12) and skips
what comes before it (counted as ``skipped``, not refused: nothing was wrong with them), so
the view keeps the last good frame, its age growing, instead of showing garbage.

``CameraFeed`` is the thin adapter: a Zenoh subscriber whose callback only queues the payload
(bounded; an overflow is a gap), a thread that decodes in order and hands each shown frame to
the view, ``shown_stamp_ns`` (the newest shown frame's capture stamp, for the operator's
command: read without a lock, since the commands must never wait for the decoder),
``camera_age_ms`` and ``stats`` (frames a second shown and kbit/s received, for the status
line). The view gets JPEG: JPEG frames as they came, H.264 frames re-encoded (Pillow, ~1 ms at
320 x 240), only when a view records them (``ShownFrame.jpeg``); always at the largest size
shown so far (a smaller frame, sent so on a thin link, scaled up: the Rerun viewer refuses an
image stream whose size changes), its line giving the size sent.
"""

from __future__ import annotations

import io
import logging
import threading
import time
from collections import Counter, deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Final, Protocol, runtime_checkable

import numpy as np
import numpy.typing as npt
from egc_common import keys
from egc_common.camera_msg import CameraFrame, decode_camera
from egc_common.event_log import EventLog
from egc_common.messages import Rejection, RejectReason
from egc_common.transport import payload_bytes

# PyAV and Pillow load with the first frame (``_codecs``): an operator without a camera, or
# without a view, does not pay for them at start-up.

log = logging.getLogger("egc.operator.camera")

RGB = npt.NDArray[np.uint8]
NS_PER_MS: Final = 1_000_000
NS_PER_S: Final = 1_000_000_000
STALE_AFTER_MS: Final = 1000  # an older frame is marked stale in the view
FUTURE_SLACK_NS: Final = 50 * NS_PER_MS  # scheduling between the robot's clock read and capture
VIEW_JPEG_QUALITY: Final = 75
RATE_WINDOW_NS: Final = NS_PER_S
QUEUE_FRAMES: Final = 32  # payloads waiting for the decoder; more is a gap
SKIPPED: Final = "skipped"  # H.264 frames before the keyframe the decoder waits for


@dataclass(frozen=True, slots=True)
class RobotClock:
    """The clock sync's estimate at one moment: the robot's clock now and its error bound."""

    now_ns: int
    error_ns: int


@dataclass(slots=True, eq=False)
class ShownFrame:
    """A decoded frame: H.264 as RGB, JPEG as received (already checked by decoding it)."""

    seq: int
    stamp_ns: int
    codec: str
    width: int
    height: int
    key: bool
    rgb: RGB | None = None
    _jpeg: bytes | None = field(default=None, repr=False)

    def jpeg(self, quality: int = VIEW_JPEG_QUALITY) -> bytes:
        """The picture as JPEG, encoded once on first use (H.264 frames)."""
        if self._jpeg is None:
            assert self.rgb is not None
            buffer = io.BytesIO()
            _, Image = _codecs()
            Image.fromarray(self.rgb, "RGB").save(buffer, format="JPEG", quality=quality)
            self._jpeg = buffer.getvalue()
        return self._jpeg


class FrameDecoder:
    """PyAV's H.264 decoder and Pillow's JPEG, as the module docstring says; not thread-safe."""

    def __init__(self) -> None:
        self._h264: Any = None
        self.waiting_for_key = True

    def gap(self) -> None:
        """Frames went missing: the next H.264 picture must be a keyframe."""
        self.waiting_for_key = True

    def decode(self, frame: CameraFrame) -> ShownFrame | Rejection | None:
        """The shown frame, a Rejection (corrupt), or None (skipped: waiting for a keyframe)."""
        if frame.codec == "jpeg":
            return self._jpeg(frame)
        if self.waiting_for_key and not frame.key:
            return None
        if self._h264 is None or (frame.key and self.waiting_for_key):
            self._h264 = _h264_decoder()
        av, _ = _codecs()
        try:
            pictures = self._h264.decode(av.Packet(frame.data))
        except Exception as exc:  # PyAV raises InvalidDataError and others on broken input
            return self._corrupt(f"H.264 does not decode: {type(exc).__name__}")
        if len(pictures) != 1:
            return self._corrupt(f"H.264 frame gave {len(pictures)} pictures, not 1")
        picture = pictures[0]
        if picture.is_corrupt:
            return self._corrupt("H.264 picture decoded with errors (cut or damaged)")
        if self.waiting_for_key and not picture.key_frame:
            return self._corrupt("marked as a keyframe, but it is not one")
        if (picture.width, picture.height) != (frame.width, frame.height):
            return self._corrupt(
                f"H.264 picture is {picture.width}x{picture.height}, "
                f"the message says {frame.width}x{frame.height}"
            )
        self.waiting_for_key = False
        rgb: RGB = picture.to_ndarray(format="rgb24")
        return ShownFrame(
            frame.seq, frame.stamp_ns, "h264", frame.width, frame.height, frame.key, rgb=rgb
        )

    def _corrupt(self, detail: str) -> Rejection:
        self.waiting_for_key = True
        self._h264 = None  # its references may be broken: start afresh at the next keyframe
        return Rejection(RejectReason.CORRUPT, detail)

    @staticmethod
    def _jpeg(frame: CameraFrame) -> ShownFrame | Rejection:
        _, Image = _codecs()
        try:
            image = Image.open(io.BytesIO(frame.data), formats=("JPEG",))
            if image.size != (frame.width, frame.height):
                return Rejection(
                    RejectReason.CORRUPT,
                    f"JPEG is {image.size[0]}x{image.size[1]}, "
                    f"the message says {frame.width}x{frame.height}",
                )
            image.load()  # the whole picture: a cut one raises here
        except Exception as exc:
            return Rejection(RejectReason.CORRUPT, f"JPEG does not decode: {type(exc).__name__}")
        return ShownFrame(
            frame.seq, frame.stamp_ns, "jpeg", frame.width, frame.height, True, _jpeg=frame.data
        )


def _codecs() -> tuple[Any, Any]:
    """The modules ``av`` and ``PIL.Image``, imported on first use."""
    import av
    from PIL import Image

    return av, Image


def _h264_decoder() -> Any:
    av, _ = _codecs()
    ctx = av.CodecContext.create("h264", "r")
    ctx.thread_count = 1  # frame threads delay pictures and drop the corrupt flag
    ctx.options = {"max_pixels": str(4096 * 4096)}
    return ctx


@dataclass(frozen=True, slots=True)
class CameraStats:
    """For the status line: the last second's frames shown and kbit/s received, the newest
    shown frame's age, and counts since the start."""

    fps: float
    kbps: float
    age_ms: int | None
    stale: bool
    shown: int
    refused: int
    skipped: int


class CameraReceiver:
    """The operator's camera rules (module docstring). Not thread-safe; times passed in."""

    def __init__(
        self, stale_after_ms: int = STALE_AFTER_MS, future_slack_ns: int = FUTURE_SLACK_NS
    ) -> None:
        self._stale_after_ms = stale_after_ms
        self._future_slack_ns = future_slack_ns
        self._decoder = FrameDecoder()
        self.shown: ShownFrame | None = None
        self._newest: tuple[int, int] | None = None  # (stamp_ns, seq) of the newest taken
        self.refused: Counter[str] = Counter()
        self.frames_shown = 0
        self.skipped = 0
        self.bytes_received = 0
        self._received: deque[tuple[int, int]] = deque()  # (local ns, bytes)
        self._shown_at: deque[int] = deque()  # local ns of the frames shown

    def reset(self) -> None:
        """A new robot (or the same after a long outage): nothing shown is its, the decoder
        starts afresh."""
        self._decoder = FrameDecoder()
        self.shown = None
        self._newest = None

    def gap(self) -> None:
        """Payloads were lost before they reached ``receive`` (the feed's queue overflowed)."""
        self._decoder.gap()

    def receive(
        self, payload: object, local_ns: int, clock: RobotClock | None
    ) -> ShownFrame | Rejection | None:
        """One payload: the frame to show, a Rejection (counted), or None (skipped)."""
        size = len(payload) if isinstance(payload, (bytes, bytearray, memoryview)) else 0
        self.bytes_received += size
        self._received.append((local_ns, size))
        result = self._take(payload, clock)
        if isinstance(result, Rejection):
            self.refused[result.reason.value] += 1
        elif result is None:
            self.skipped += 1
        else:
            self.shown = result
            self.frames_shown += 1
            self._shown_at.append(local_ns)
        self._trim(local_ns)
        return result

    def _take(self, payload: object, clock: RobotClock | None) -> ShownFrame | Rejection | None:
        frame = decode_camera(payload)
        if isinstance(frame, Rejection):
            return frame
        if clock is not None:
            ahead_ns = frame.stamp_ns - clock.now_ns
            if ahead_ns > clock.error_ns + self._future_slack_ns:
                return Rejection(
                    RejectReason.FUTURE,
                    f"stamped {ahead_ns / NS_PER_MS:.0f} ms after the robot's clock now "
                    f"(clock error up to {clock.error_ns / NS_PER_MS:.0f} ms)",
                )
        if self._newest is not None:
            stamp, seq = self._newest
            if frame.stamp_ns < stamp or (frame.stamp_ns == stamp and frame.seq <= seq):
                return Rejection(
                    RejectReason.OUT_OF_ORDER,
                    f"frame {frame.seq} stamped {(stamp - frame.stamp_ns) / NS_PER_MS:.0f} ms "
                    "before the newest one taken",
                )
            if frame.seq != seq + 1:
                self._decoder.gap()  # lost frames (or a restarted stream)
        self._newest = (frame.stamp_ns, frame.seq)
        return self._decoder.decode(frame)

    def _trim(self, local_ns: int) -> None:
        while self._received and local_ns - self._received[0][0] >= RATE_WINDOW_NS:
            self._received.popleft()
        while self._shown_at and local_ns - self._shown_at[0] >= RATE_WINDOW_NS:
            self._shown_at.popleft()

    def age_ms(self, clock: RobotClock | None) -> int | None:
        """The shown frame's age on the robot's clock (>= 0), None when unknown."""
        if clock is None or self.shown is None or clock.now_ns <= 0:
            return None
        return max(0, (clock.now_ns - self.shown.stamp_ns) // NS_PER_MS)

    def stale(self, age_ms: int | None) -> bool:
        return age_ms is None or age_ms > self._stale_after_ms

    def stats(self, local_ns: int, clock: RobotClock | None) -> CameraStats:
        self._trim(local_ns)
        age = self.age_ms(clock)
        window_s = RATE_WINDOW_NS / NS_PER_S
        return CameraStats(
            fps=len(self._shown_at) / window_s,
            kbps=sum(n for _, n in self._received) * 8 / 1000.0 / window_s,
            age_ms=age,
            stale=self.stale(age),
            shown=self.frames_shown,
            refused=sum(self.refused.values()),
            skipped=self.skipped,
        )


def camera_text(stats: CameraStats, codec: str | None, size: tuple[int, int] | None) -> str:
    """The view's line under the picture, e.g. ``camera 120 ms old, 10 fps, 250 kbit/s``."""
    if stats.shown == 0:
        return "camera: no frame yet"
    if stats.age_ms is None:
        age = "age unknown (clock not synchronised)"
    elif stats.stale:
        age = f"STALE: last frame {stats.age_ms / 1000:.1f} s old"
    else:
        age = f"{stats.age_ms} ms old"
    what = "" if codec is None or size is None else f", {codec} {size[0]}x{size[1]}"
    return f"camera {age}, {stats.fps:.0f} fps, {stats.kbps:.0f} kbit/s{what}"


@runtime_checkable
class CameraView(Protocol):
    """What ``CameraFeed`` needs of the operator view (``OperatorView``)."""

    def on_camera(self, frame: ShownFrame, text: str, robot_now_ns: int | None) -> None: ...
    def on_camera_text(self, text: str, stale: bool, robot_now_ns: int | None) -> None: ...


class CameraFeed:
    """The Zenoh side of the camera (module docstring). ``robot_clock(local_ns)`` is the clock
    sync's estimate (None until synchronised), ``local_clock`` this process's monotonic clock
    as the operator node reads it; ``on_reject(kind, rejection)`` counts a refusal where the
    operator counts the rest (its status line and log); ``on_bytes(n)`` is told every sample's
    payload size (the operator's ``rx_kbps``)."""

    def __init__(
        self,
        session: Any,
        robot_id: str,
        robot_clock: Callable[[int], RobotClock | None],
        view: CameraView | None = None,
        local_clock: Callable[[], int] = time.monotonic_ns,
        on_reject: Callable[[str, Rejection], None] | None = None,
        on_bytes: Callable[[int], None] | None = None,
    ) -> None:
        self.receiver = CameraReceiver()
        self._on_bytes = on_bytes  # the view plane's byte count (DESIGN 12 rx_kbps)
        self._robot_clock = robot_clock
        self._view = view
        self._clock = local_clock
        self._on_reject = on_reject
        self._log = EventLog()
        self._lock = threading.Lock()  # the receiver: the decoder thread and the callers
        self._queue: deque[bytes] = deque()
        self._overflow = False
        self._wake = threading.Condition()
        self._closed = False
        self._text_drawn: tuple[str, bool] | None = None
        self._shown_ns: int | None = None  # written by the decoder thread, read lock-free
        self._view_size: tuple[int, int] | None = None  # the view's picture (decoder thread)
        self._thread = threading.Thread(target=self._decode_loop, name="camera", daemon=True)
        self._thread.start()
        self._subscriber = session.declare_subscriber(keys.camera(robot_id), self._on_sample)

    def _on_sample(self, sample: Any) -> None:
        try:
            payload = payload_bytes(sample)
        except Exception as exc:  # nothing from the network raises out of the callback
            log.debug("camera sample unreadable: %s", exc)
            return
        if self._on_bytes is not None:  # refused or not, it crossed the link
            self._on_bytes(len(payload))
        with self._wake:
            if len(self._queue) >= QUEUE_FRAMES:
                self._queue.popleft()
                self._overflow = True
            self._queue.append(payload)
            self._wake.notify()

    def _decode_loop(self) -> None:
        while True:
            with self._wake:
                while not self._queue and not self._closed:
                    self._wake.wait()
                if self._closed:
                    return
                payload = self._queue.popleft()
                overflow, self._overflow = self._overflow, False
            try:
                self._one(payload, overflow)
            except Exception as exc:  # never: but a view error must not end the thread
                log.warning("camera frame not shown: %s: %s", type(exc).__name__, exc)

    def _one(self, payload: bytes, overflow: bool) -> None:
        now = self._clock()
        clock = self._robot_clock(now)
        with self._lock:
            if overflow:
                self.receiver.gap()
            result = self.receiver.receive(payload, now, clock)
            stats = self.receiver.stats(now, clock)
            shown = self.receiver.shown
            self._shown_ns = None if shown is None else shown.stamp_ns
        if isinstance(result, Rejection):
            if self._on_reject is not None:
                self._on_reject("camera", result)
            held = self._log.allow(result.reason.value, now)
            if held is not None and self._on_reject is None:
                log.warning("refused camera frame (%s): %s", result.reason.value, result.detail)
            return
        if result is None or self._view is None:
            return
        text = camera_text(stats, result.codec, (result.width, result.height))
        shown_frame = self._at_view_size(result)
        self._view.on_camera(shown_frame, text, None if clock is None else clock.now_ns)
        self._text_drawn = (text, False)

    def _at_view_size(self, frame: ShownFrame) -> ShownFrame:
        """``frame`` at the largest size shown so far: a frame the budget sent smaller (a thin
        link halves the picture) is scaled up, so that the view's image keeps one size (the
        Rerun viewer refuses an image stream whose size changes); its line says the size sent."""
        size = self._view_size
        if size is None or frame.width * frame.height > size[0] * size[1]:
            self._view_size = (frame.width, frame.height)
            return frame
        if (frame.width, frame.height) == size:
            return frame
        _, Image = _codecs()
        image = (
            Image.fromarray(frame.rgb, "RGB")
            if frame.rgb is not None
            else Image.open(io.BytesIO(frame.jpeg())).convert("RGB")
        )
        rgb: RGB = np.asarray(image.resize(size, Image.Resampling.BILINEAR))
        return ShownFrame(frame.seq, frame.stamp_ns, frame.codec, *size, frame.key, rgb=rgb)

    def shown_stamp_ns(self) -> int | None:
        """The newest shown frame's capture stamp (robot clock), None when none is shown; no
        lock (a single attribute read)."""
        return self._shown_ns

    def camera_age_ms(self) -> int | None:
        """The newest shown frame's age on the robot's clock (ms), None when unknown."""
        now = self._clock()
        clock = self._robot_clock(now)
        with self._lock:
            return self.receiver.age_ms(clock)

    def stats(self) -> CameraStats:
        now = self._clock()
        clock = self._robot_clock(now)
        with self._lock:
            return self.receiver.stats(now, clock)

    def tick(self) -> None:
        """Refresh the view's age line (call a few times a second): a frame that stops being
        fresh is marked stale even when no new one comes."""
        if self._view is None:
            return
        now = self._clock()
        clock = self._robot_clock(now)
        with self._lock:
            stats = self.receiver.stats(now, clock)
            shown = self.receiver.shown
        if shown is None:
            return
        text = camera_text(stats, shown.codec, (shown.width, shown.height))
        if (text, stats.stale) == self._text_drawn:
            return
        self._text_drawn = (text, stats.stale)
        self._view.on_camera_text(text, stats.stale, None if clock is None else clock.now_ns)

    def reset(self) -> None:
        """A new robot: forget the old one's frames (see ``CameraReceiver.reset``)."""
        with self._lock:
            self.receiver.reset()
            self._shown_ns = None

    def close(self) -> None:
        try:
            self._subscriber.undeclare()
        except Exception as exc:  # a closing session
            log.debug("camera subscriber: %s", exc)
        with self._wake:
            self._closed = True
            self._wake.notify_all()
        self._thread.join(2.0)
