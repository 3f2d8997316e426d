"""The camera message on ``egc/<robot>/camera`` (DESIGN 12, pinned keys).

A msgpack map ``{"v": 1, "seq", "stamp_ns", "codec", "width", "height", "key", "data"}``:
``stamp_ns`` is the capture time on the robot's monotonic clock, ``codec`` ``"h264"`` (Annex B,
no B-frames; ``key`` marks a keyframe, which carries its SPS/PPS) or ``"jpeg"`` (every frame a
key), ``data`` the encoded picture.

``decode_camera`` never raises (DESIGN 7): the payload's length is checked before msgpack sees
it (a 50 MB payload costs a ``len``), the unpacker is limited to one flat map of at most
``MAX_CAMERA_BYTES`` of binary, and every field is checked for type and range. What it cannot
check, whether ``data`` really is a picture of that size, the receiver's decoder says
(``RejectReason.CORRUPT``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Final

from egc_common.messages import (
    SCHEMA_VERSION,
    Rejection,
    RejectReason,
    _bool,
    _decode,
    _get,
    _int,
    _InvalidError,
    _pack,
    _Shape,
)

CODECS: Final = ("h264", "jpeg")
# A picture's side in pixels, and its area: a 4K UHD frame (3840 x 2160) is the largest.
MIN_SIDE_PX: Final = 16
MAX_SIDE_PX: Final = 4096
MAX_PIXELS: Final = 3840 * 2160
# One encoded frame: a 4K JPEG at high quality stays well below it.
MAX_CAMERA_BYTES: Final = 8 * 1024 * 1024
# One map of scalars and one binary; no arrays, no nesting (``messages._Shape``).
_CAMERA_SHAPE: Final = _Shape(keys=32, max_array=0, max_str=64, max_bin=MAX_CAMERA_BYTES)


@dataclass(frozen=True, slots=True, eq=False)
class CameraFrame:
    """One encoded camera frame (DESIGN 12); construction checks what the decoder checks."""

    seq: int
    stamp_ns: int
    codec: str
    width: int
    height: int
    key: bool
    data: bytes

    def __post_init__(self) -> None:
        try:
            _check(self._wire())
        except _InvalidError as exc:
            raise ValueError(f"invalid CameraFrame: {exc.rejection}") from None

    def _wire(self) -> dict[str, Any]:
        return {
            "v": SCHEMA_VERSION,
            "seq": self.seq,
            "stamp_ns": self.stamp_ns,
            "codec": self.codec,
            "width": self.width,
            "height": self.height,
            "key": self.key,
            "data": self.data,
        }

    def encode(self) -> bytes:
        return _pack(self._wire())


def _check(m: Mapping[Any, Any]) -> dict[str, Any]:
    codec = _get(m, "codec")
    if not isinstance(codec, str):
        raise _InvalidError(RejectReason.WRONG_TYPE, "'codec' must be a string")
    if codec not in CODECS:
        shown = codec[:32].encode("unicode_escape").decode("ascii")
        raise _InvalidError(
            RejectReason.UNKNOWN_CODEC, f"codec {shown!r} is not one of {', '.join(CODECS)}"
        )
    width = _int(m, "width", MIN_SIDE_PX, MAX_SIDE_PX)
    height = _int(m, "height", MIN_SIDE_PX, MAX_SIDE_PX)
    if width * height > MAX_PIXELS:
        raise _InvalidError(
            RejectReason.TOO_LARGE, f"{width} x {height} pixels > limit {MAX_PIXELS}"
        )
    data = _get(m, "data")
    if not isinstance(data, (bytes, bytearray)):
        raise _InvalidError(RejectReason.WRONG_TYPE, "'data' must be bytes")
    if not 0 < len(data) <= MAX_CAMERA_BYTES:
        raise _InvalidError(
            RejectReason.OUT_OF_RANGE, f"'data' of {len(data)} bytes (1-{MAX_CAMERA_BYTES})"
        )
    return {
        "seq": _int(m, "seq"),
        "stamp_ns": _int(m, "stamp_ns"),
        "codec": codec,
        "width": width,
        "height": height,
        "key": _bool(m, "key"),
        "data": bytes(data),
    }


def _build_camera(m: Mapping[Any, Any]) -> CameraFrame:
    frame = object.__new__(CameraFrame)  # checked already: no second pass in __post_init__
    for name, value in _check(m).items():
        object.__setattr__(frame, name, value)
    return frame


def decode_camera(payload: object) -> CameraFrame | Rejection:
    """The frame, or why not (module docstring); never raises."""
    # ``_decode`` checks the length before unpacking; this is the cheap path for a huge one.
    size = len(payload) if isinstance(payload, (bytes, bytearray, memoryview)) else 0
    if size > MAX_CAMERA_BYTES + 1024:
        return Rejection(RejectReason.TOO_LARGE, f"{size} bytes > limit {MAX_CAMERA_BYTES}")
    return _decode(payload, MAX_CAMERA_BYTES + 1024, _build_camera, shape=_CAMERA_SHAPE)
