"""The robot's camera stream (DESIGN 12): newest picture -> encoder -> ``egc/<robot>/camera``.

``CameraStreamer`` runs in its own thread at the frame rate it is allotted. Each tick it asks
its source for the newest picture (``CameraSource``: a callable returning ``(rgb, stamp_ns)``,
an ``H x W x 3`` uint8 array and its capture time on the robot's monotonic clock, or None when
there is none), encodes it (``camera_encoder``) and publishes one ``CameraFrame``. Nothing
queues: a picture is taken when a frame is due, so one that came while the previous frame was
being encoded or sent is replaced by a newer one, never sent late; a tick that finds the
previous frame still going is skipped; a picture already sent (the same stamp) is not sent
again. The publisher is on the view plane (priority DATA_LOW, congestion control DROP, best
effort: ``camera_publisher``), so a full link drops frames instead of delaying anything else.

The downlink budget drives it through ``set_allotment(fps, kbps)`` (thread-safe; fps 0 turns
it off): ``plan_stream`` turns that into codec, picture size, rate and bitrate within the
configured maximum. The budget is a number it is given; nothing here estimates the link.
``request_keyframe`` makes the next frame a keyframe (a new viewer).

Counters for the summary's pinned ``camera`` object (DESIGN 12): ``frames_sent``,
``bytes_sent``, the codec and size in use; ``summary()`` gives the object, ``recent_kbps``
the last second's rate.

Sources: ``--camera sim`` (``egc_app.robot_cmd`` wires the in-process simulator's renderer:
egc_robot may not import egc_sim), ``--camera ros2:TOPIC`` (``Ros2Driver.newest_image``).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any

import numpy as np
import numpy.typing as npt
import zenoh
from egc_common import keys
from egc_common.camera_msg import CameraFrame

from egc_robot.camera_config import CameraConfig
from egc_robot.camera_encoder import CameraEncoder, fit_size, plan_stream

log = logging.getLogger("egc.robot.camera")

RGB = npt.NDArray[np.uint8]
CameraSource = Callable[[], "tuple[RGB, int] | None"]
NS_PER_S = 1_000_000_000
DEFAULT_KBPS = 300.0  # until a budget allots one
_RATE_WINDOW_NS = NS_PER_S


def camera_publisher(session: zenoh.Session, key: str) -> zenoh.Publisher:
    """The view plane's lowest priority (DESIGN 12): dropped under congestion, never blocking,
    never retransmitted; a lost frame is replaced by the next one."""
    return session.declare_publisher(
        key,
        priority=zenoh.Priority.DATA_LOW,
        congestion_control=zenoh.CongestionControl.DROP,
        reliability=zenoh.Reliability.BEST_EFFORT,
    )


def keyframe_for_new_operators(session: zenoh.Session, robot: str, streamer: CameraStreamer) -> Any:
    """A new operator's liveliness token (``egc/<robot>/alive/operator/*``) asks for a
    keyframe: its view shows a picture with the next frame, not up to a second later."""

    def on_token(sample: zenoh.Sample) -> None:
        if sample.kind == zenoh.SampleKind.PUT:
            streamer.request_keyframe()

    return session.liveliness().declare_subscriber(keys.alive_operators(robot), on_token)


class CameraStreamer:
    """See the module docstring. ``publish`` sends one encoded ``CameraFrame`` payload."""

    def __init__(
        self,
        source: CameraSource,
        publish: Callable[[bytes], Any],
        config: CameraConfig,
        kbps: float = DEFAULT_KBPS,
        clock: Callable[[], int] = time.monotonic_ns,
    ) -> None:
        self._source = source
        self._publish = publish
        self._config = config
        self._clock = clock
        self._encoder = CameraEncoder()
        self._cond = threading.Condition()
        self._fps = config.max_fps
        self._kbps = kbps
        self._changed = True
        self._key_wanted = False
        self._stop = False
        self._thread: threading.Thread | None = None
        self._seq = 0
        self._last_stamp: int | None = None
        self._window: deque[tuple[int, int]] = deque()  # (sent at, bytes) over the last second
        self._started_ns: int | None = None
        self._stopped_ns: int | None = None
        self.frames_sent = 0
        self.bytes_sent = 0
        self.keyframes_sent = 0
        self.source_errors = 0
        self.codec: str | None = None
        self.width_px: int | None = None
        self.height_px: int | None = None

    # -- the budget's interface ---------------------------------------------------------------

    def set_allotment(self, fps: float, kbps: float) -> None:
        """At most ``fps`` frames a second (0: off) and ``kbps`` kbit/s, from the next frame;
        the configured ``--camera-fps`` stays the ceiling."""
        fps, kbps = float(fps), float(kbps)
        with self._cond:
            self._fps = min(fps, self._config.max_fps) if math.isfinite(fps) and fps > 0 else 0.0
            self._kbps = kbps if math.isfinite(kbps) and kbps > 0 else 0.0
            self._changed = True
            self._cond.notify_all()

    @property
    def allotment(self) -> tuple[float, float]:
        with self._cond:
            return self._fps, self._kbps

    def request_keyframe(self) -> None:
        """The next frame is a keyframe (a new viewer joined)."""
        with self._cond:
            self._key_wanted = True

    # -- counters -------------------------------------------------------------------------------

    def recent_kbps(self, now_ns: int | None = None) -> float:
        """The camera's kbit/s over the last second."""
        now = self._clock() if now_ns is None else now_ns
        with self._cond:
            sent = sum(n for t, n in self._window if now - t < _RATE_WINDOW_NS)
        return sent * 8 / 1000.0 / (_RATE_WINDOW_NS / NS_PER_S)

    def summary(self) -> dict[str, Any]:
        """DESIGN 12's pinned ``camera`` object: codec, size in use, frames sent, and the mean
        frame rate and kbit/s since the stream started."""
        with self._cond:
            start, end = self._started_ns, self._stopped_ns
        elapsed_s = 0.0 if start is None else ((end or self._clock()) - start) / NS_PER_S
        return {
            "codec": self.codec or self._config.codec,
            "width": self.width_px or self._config.width_px,
            "height": self.height_px or self._config.height_px,
            "frames_sent": self.frames_sent,
            "fps": round(self.frames_sent / elapsed_s, 2) if elapsed_s > 0 else 0.0,
            "kbps": round(self.bytes_sent * 8 / 1000.0 / elapsed_s, 1) if elapsed_s > 0 else 0.0,
        }

    # -- the thread -----------------------------------------------------------------------------

    def start(self) -> None:
        self._started_ns = self._clock()
        self._thread = threading.Thread(target=self._run, name="camera", daemon=True)
        self._thread.start()

    def close(self) -> None:
        with self._cond:
            self._stop = True
            self._cond.notify_all()
        if self._thread is not None:
            self._thread.join(5.0)
        self._stopped_ns = self._clock()

    def _run(self) -> None:
        next_ns = last_tick_ns = self._clock()
        while True:
            with self._cond:
                while True:
                    if self._stop:
                        return
                    now = self._clock()
                    if self._fps <= 0.0:  # off until an allotment turns it on
                        self._cond.wait()
                        next_ns = self._clock()
                        continue
                    if self._changed:  # a new rate counts from the last frame, not the next
                        self._changed = False
                        next_ns = min(next_ns, last_tick_ns + int(NS_PER_S / self._fps))
                    if next_ns <= now:
                        break
                    self._cond.wait((next_ns - now) / NS_PER_S)
                fps, kbps = self._fps, self._kbps
                key_wanted, self._key_wanted = self._key_wanted, False
            if key_wanted:
                self._encoder.request_keyframe()
            last_tick_ns = self._clock()
            try:
                self._one_frame(fps, kbps)
            except Exception as exc:  # the camera must never take the robot down
                self.source_errors += 1
                if self.source_errors == 1 or self.source_errors % 100 == 0:
                    log.warning(
                        "camera frame failed (%d so far): %s: %s",
                        self.source_errors,
                        type(exc).__name__,
                        exc,
                    )
            period = int(NS_PER_S / fps)
            next_ns += period
            if next_ns <= self._clock():  # behind (a slow frame): skip the missed ticks
                next_ns = self._clock() + period

    def _one_frame(self, fps: float, kbps: float) -> None:
        grabbed = self._source()
        if grabbed is None:
            return
        rgb, stamp_ns = grabbed
        if stamp_ns == self._last_stamp:
            return  # nothing new since the last frame
        src_h, src_w = rgb.shape[:2]
        cfg = self._config
        w, h = fit_size(src_w, src_h, cfg.width_px, cfg.height_px)
        plan = plan_stream(cfg.codec, w, h, fps, kbps)
        if plan is None:
            return
        if plan != self._encoder.plan:
            self._encoder.set_plan(plan)
        encoded = self._encoder.encode(rgb, stamp_ns)
        if encoded is None:
            return
        frame = CameraFrame(
            seq=self._seq,
            stamp_ns=stamp_ns,
            codec=encoded.codec,
            width=encoded.width_px,
            height=encoded.height_px,
            key=encoded.key,
            data=encoded.data,
        )
        payload = frame.encode()
        self._publish(payload)
        self._seq += 1
        self._last_stamp = stamp_ns
        sent_at = self._clock()
        with self._cond:
            self._window.append((sent_at, len(payload)))
            while self._window and sent_at - self._window[0][0] >= _RATE_WINDOW_NS:
                self._window.popleft()
        self.frames_sent += 1
        self.bytes_sent += len(payload)
        self.keyframes_sent += int(encoded.key)
        self.codec = encoded.codec
        self.width_px, self.height_px = encoded.width_px, encoded.height_px
