"""Snapshots of the other robots' cameras for the fleet panel (DESIGN 12, 15).

The driven robot's camera is a live stream, within that robot's downlink budget (DESIGN 12).
The other robots' cameras have no budget of this operator's: subscribing to one receives its
whole stream, and a thin link shared with the driven robot's view would carry it at the cost
of the view that keeps the driving safe. So the other robots get **snapshots**, and only
while the budget allows:

- **one grab at a time**, round robin over the other robots that have a camera, at most one
  every ``period_s`` (default 5 s): subscribe to ``egc/<robot>/camera`` until one picture
  decodes (a JPEG frame; an H.264 keyframe, at most a second away: DESIGN 12), then
  unsubscribe, at most ``grab_s`` (default 1.5 s). On average that is at most
  grab_s / period_s (30 %) of one camera stream, whatever the fleet's size; each robot's
  snapshot is refreshed every period_s x (robots - 1).
- **only when the budget allows** (``snapshots_allowed``, on the driven robot's newest
  telemetry): its downlink budget has never seen a queue stand on this link (``link_kbps``
  None: the link carried all that was sent), or the link's estimate leaves ``SNAPSHOT_KBPS``
  above what the driven robot's view plane sends now (``view_kbps``). A snapshot that makes a
  queue stand is seen by the driven robot's budget within a report round trip: it cuts, the
  estimate appears, and the snapshots stop (at most one grab late).
- **small**: the picture is scaled to ``THUMB_WIDTH_PX`` and re-encoded as JPEG for the view.

Decoding is ``camera_view.CameraReceiver``'s (every rule of the live camera: size caps, the
future check against that robot's clock estimate, corrupt pictures refused). Nothing from the
network raises out of the subscriber's callback or the grab thread.
"""

from __future__ import annotations

import io
import logging
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import zenoh
from egc_common import keys
from egc_common.messages import Telemetry
from egc_common.stop_flag import StopRequest
from egc_common.transport import payload_bytes

from egc_operator.camera_view import CameraReceiver, RobotClock, ShownFrame

log = logging.getLogger("egc.operator.camera")

THUMB_WIDTH_PX = 160
# What the snapshots may cost on average (a 300 kbit/s stream for 1.5 s every 5 s is 90).
SNAPSHOT_KBPS = 100.0
THUMB_JPEG_QUALITY = 70
_QUEUE = 64  # payloads kept during one grab (a second of a 10 fps stream, with room)


@dataclass(frozen=True, slots=True)
class Thumbnail:
    robot: str
    jpeg: bytes
    width: int
    height: int
    stamp_ns: int  # capture time, that robot's clock
    grabbed_ns: int  # when it was taken, this process's clock


def snapshots_allowed(t: Telemetry | None) -> bool:
    """The driven robot's budget leaves room for snapshots (module docstring)."""
    if t is None:
        return False
    if t.link_kbps is None:
        return True
    return t.link_kbps - (t.view_kbps or 0.0) >= SNAPSHOT_KBPS


def next_robot(candidates: Sequence[str], last: str | None) -> str | None:
    """Round robin: the candidate after ``last`` in sorted order (the first one after a robot
    that left), None when there is none."""
    ordered = sorted(candidates)
    if not ordered:
        return None
    if last is None:
        return ordered[0]
    after = [r for r in ordered if r > last]
    return after[0] if after else ordered[0]


def shrink(frame: ShownFrame, width_px: int = THUMB_WIDTH_PX) -> tuple[bytes, int, int]:
    """The picture scaled to ``width_px`` wide (never up), as JPEG; (bytes, width, height)."""
    from PIL import Image  # with the first thumbnail, not at every operator's start-up

    if frame.rgb is not None:
        picture = Image.fromarray(frame.rgb, "RGB")
    else:
        picture = Image.open(io.BytesIO(frame.jpeg()), formats=("JPEG",))
    if picture.width > width_px:
        height = max(1, round(picture.height * width_px / picture.width))
        picture = picture.resize((width_px, height))
    out = io.BytesIO()
    picture.convert("RGB").save(out, format="JPEG", quality=THUMB_JPEG_QUALITY)
    return out.getvalue(), picture.width, picture.height


class FleetThumbnails:
    """The grab thread (module docstring). ``candidates()``: the other robots with a camera;
    ``robot_clock(robot, local_ns)``: that robot's clock estimate (None: unknown, no future
    check); ``on_thumbnail``: the view."""

    def __init__(
        self,
        session: zenoh.Session,
        candidates: Callable[[], list[str]],
        allowed: Callable[[], bool],
        on_thumbnail: Callable[[Thumbnail], None],
        robot_clock: Callable[[str, int], RobotClock | None] = lambda *_: None,
        clock: Callable[[], int] = time.monotonic_ns,
        period_s: float = 5.0,
        grab_s: float = 1.5,
    ) -> None:
        self._session = session
        self._candidates = candidates
        self._allowed = allowed
        self._on_thumbnail = on_thumbnail
        self._robot_clock = robot_clock
        self._clock = clock
        self._period_s = period_s
        self._grab_s = grab_s
        self._last: str | None = None
        self.grabs = 0
        self.bytes_received = 0

    def run(self, stop: StopRequest) -> None:
        while not stop.wait(self._period_s):
            try:
                if not self._allowed():
                    continue
                robot = next_robot(self._candidates(), self._last)
                if robot is None:
                    continue
                self._last = robot
                thumb = self.grab(robot, stop)
                if thumb is not None:
                    self._on_thumbnail(thumb)
            except Exception as exc:  # a closing session; the view; never out of the thread
                if stop.is_set():
                    return
                log.debug("fleet thumbnail: %s", exc)

    def grab(self, robot: str, stop: StopRequest) -> Thumbnail | None:
        """One picture of ``robot``'s camera, or None within ``grab_s``."""
        queue: deque[bytes] = deque(maxlen=_QUEUE)
        arrived = threading.Event()

        def on_sample(sample: zenoh.Sample) -> None:
            try:
                queue.append(payload_bytes(sample))
                arrived.set()
            except Exception as exc:  # nothing from the network raises out of the callback
                log.debug("thumbnail sample unreadable: %s", exc)

        receiver = CameraReceiver()
        subscriber = self._session.declare_subscriber(keys.camera(robot), on_sample)
        self.grabs += 1
        deadline = self._clock() + round(self._grab_s * 1e9)
        try:
            while not stop.is_set() and self._clock() < deadline:
                arrived.wait(max(0.0, (deadline - self._clock()) / 1e9))
                arrived.clear()
                while queue:
                    payload = queue.popleft()
                    self.bytes_received += len(payload)
                    now = self._clock()
                    shown = receiver.receive(payload, now, self._robot_clock(robot, now))
                    if isinstance(shown, ShownFrame):
                        jpeg, width, height = shrink(shown)
                        return Thumbnail(robot, jpeg, width, height, shown.stamp_ns, now)
        finally:
            subscriber.undeclare()  # type: ignore[no-untyped-call]
        return None
