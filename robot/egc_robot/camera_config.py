"""The robot's camera settings (DESIGN 12): ``--camera``, ``--camera-size``, ``--camera-fps``,
``--camera-codec`` and the robot TOML's ``[camera]`` table (keys ``source``, ``size``, ``fps``,
``codec``; the flags override them).

- ``source``: ``sim`` (the simulator renders a forward camera; only with ``--driver sim``, and
  its default), ``ros2:TOPIC`` (a ``sensor_msgs/Image`` or ``CompressedImage`` topic; only with
  ``--driver ros2``), ``none`` (the default with every other driver).
- ``size``: ``WxH``, the largest picture sent (default 320x240); a source of another aspect
  ratio is fitted inside it. Even sides (H.264 4:2:0), 32-1920 by 32-1080.
- ``fps``: the most frames a second the camera sends (default 10, 0.5-30); the downlink budget
  may allot fewer.
- ``codec``: ``h264`` (default) or ``jpeg``.

Pure: ``camera_config`` checks everything and raises ValueError with one line naming the key.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Final

from egc_robot.ros2_core import is_topic_name

CAMERA_KEYS: Final = ("source", "size", "fps", "codec")
SOURCES: Final = ("sim", "ros2", "none")
CODECS: Final = ("h264", "jpeg")
DEFAULT_SIZE: Final = (320, 240)
DEFAULT_FPS: Final = 10.0
FPS_RANGE: Final = (0.5, 30.0)
WIDTH_RANGE: Final = (32, 1920)
HEIGHT_RANGE: Final = (32, 1080)
_SIZE = re.compile(r"^\s*(\d{1,5})\s*[xX]\s*(\d{1,5})\s*$")


@dataclass(frozen=True, slots=True)
class CameraConfig:
    source: str = "none"  # sim | ros2 | none
    topic: str | None = None  # ros2: the image topic
    width_px: int = DEFAULT_SIZE[0]
    height_px: int = DEFAULT_SIZE[1]
    max_fps: float = DEFAULT_FPS
    codec: str = "h264"

    @property
    def enabled(self) -> bool:
        return self.source != "none"


def parse_source(text: str) -> tuple[str, str | None]:
    """``sim`` | ``none`` | ``ros2:TOPIC`` -> (source, topic)."""
    if not isinstance(text, str):
        raise ValueError(f"camera source must be a string, got {text!r}")
    kind, colon, topic = text.strip().partition(":")
    if kind == "ros2" and colon:
        if not is_topic_name(topic):
            raise ValueError(f"--camera ros2:{topic}: {topic!r} is not a valid ROS 2 topic name")
        return "ros2", topic
    if kind in ("sim", "none") and not colon:
        return kind, None
    raise ValueError(f"--camera must be sim, none or ros2:TOPIC, got {text!r}")


def parse_size(text: str) -> tuple[int, int]:
    """``WxH`` -> (W, H), even and within the ranges of the module docstring."""
    found = _SIZE.match(text) if isinstance(text, str) else None
    if found is None:
        raise ValueError(f"--camera-size must be WxH in pixels, e.g. 320x240, got {text!r}")
    w, h = int(found.group(1)), int(found.group(2))
    (w0, w1), (h0, h1) = WIDTH_RANGE, HEIGHT_RANGE
    if not (w0 <= w <= w1 and h0 <= h <= h1) or w % 2 or h % 2:
        raise ValueError(
            f"--camera-size {w}x{h}: width and height must be even, {w0}-{w1} by {h0}-{h1}"
        )
    return w, h


def camera_config(table: Mapping[str, Any], flags: Mapping[str, Any], driver: str) -> CameraConfig:
    """The ``[camera]`` table overridden by the flags that are not None, for ``driver``."""
    unknown = sorted(set(table) - set(CAMERA_KEYS))
    if unknown:
        raise ValueError(
            f"[camera] has unknown keys: {', '.join(unknown)} (known: {', '.join(CAMERA_KEYS)})"
        )
    merged = dict(table)
    merged.update({k: v for k, v in flags.items() if v is not None})
    source, topic = parse_source(merged.get("source", "sim" if driver == "sim" else "none"))
    if source == "sim" and driver != "sim":
        raise ValueError(
            f"--camera sim renders the in-process simulator: it needs --driver sim, not "
            f"--driver {driver} (use --camera none, or ros2:TOPIC with --driver ros2)"
        )
    if source == "ros2" and driver != "ros2":
        raise ValueError(
            f"--camera ros2:{topic} subscribes through the ROS 2 node: it needs --driver ros2, "
            f"not --driver {driver}"
        )
    w, h = parse_size(merged.get("size", f"{DEFAULT_SIZE[0]}x{DEFAULT_SIZE[1]}"))
    fps = merged.get("fps", DEFAULT_FPS)
    lo, hi = FPS_RANGE
    if isinstance(fps, bool) or not isinstance(fps, (int, float)) or not math.isfinite(fps):
        raise ValueError(f"--camera-fps must be a number, got {fps!r}")
    if not lo <= fps <= hi:
        raise ValueError(f"--camera-fps must be within [{lo:g}, {hi:g}], got {fps:g}")
    codec = merged.get("codec", "h264")
    if codec not in CODECS:
        raise ValueError(f"--camera-codec must be one of {', '.join(CODECS)}, got {codec!r}")
    return CameraConfig(source, topic, w, h, float(fps), codec)
