"""ROS 2 camera images as RGB arrays (DESIGN 11, 12; ``--camera ros2:TOPIC``), without rclpy.

``rgb_from_image`` takes the fields of a ``sensor_msgs/Image``: ``encoding`` (the names of
``sensor_msgs/image_encodings.hpp`` this supports: ``rgb8``, ``bgr8``, ``rgba8``, ``bgra8``,
``mono8`` / ``8UC1``, ``mono16`` / ``16UC1`` (shown by their high byte), ``yuv422`` / ``uyvy``
(U Y V Y) and ``yuv422_yuy2`` / ``yuyv`` (Y U Y V), BT.601 limited range as OpenCV converts
them), ``width``, ``height``, ``step`` (bytes per row, which may include padding), the
``is_bigendian`` flag (for 16-bit samples) and ``data``. ``rgb_from_compressed`` decodes a
``sensor_msgs/CompressedImage`` (JPEG or PNG, whatever ``format`` says: image_transport writes
``"jpeg"``, ``"png"`` or ``"bgr8; jpeg compressed bgr8"``) with Pillow, checking the picture's
size in its header before decoding it.

Never raises: anything malformed (a step shorter than a row, data shorter than the rows, an
unknown encoding, a picture beyond ``MAX_PIXELS``, a broken JPEG) is a ``Rejected`` with a
reason the driver counts.
"""

from __future__ import annotations

import io
import warnings
from typing import Any, Final

import numpy as np
import numpy.typing as npt
from PIL import Image

from egc_robot.ros2_core import Rejected

RGB = npt.NDArray[np.uint8]
MAX_SIDE_PX: Final = 8192
MAX_PIXELS: Final = 4096 * 4096
MAX_BYTES: Final = 4 * MAX_PIXELS * 2
# bytes per pixel of the uncompressed encodings supported
_BYTES_PER_PIXEL: Final = {
    "rgb8": 3,
    "bgr8": 3,
    "rgba8": 4,
    "bgra8": 4,
    "mono8": 1,
    "8UC1": 1,
    "mono16": 2,
    "16UC1": 2,
    "yuv422": 2,
    "uyvy": 2,
    "yuv422_yuy2": 2,
    "yuyv": 2,
}
ENCODINGS: Final = tuple(_BYTES_PER_PIXEL)


def _yuv422_to_rgb(
    y: npt.NDArray[np.uint8], u: npt.NDArray[np.uint8], v: npt.NDArray[np.uint8]
) -> RGB:
    """BT.601, limited range; ``u`` and ``v`` per pixel pair, repeated for both pixels."""
    yy = 1.164 * (y.astype(np.float32) - 16.0)
    uu = np.repeat(u.astype(np.float32) - 128.0, 2, axis=1)
    vv = np.repeat(v.astype(np.float32) - 128.0, 2, axis=1)
    rgb = np.stack([yy + 1.596 * vv, yy - 0.392 * uu - 0.813 * vv, yy + 2.017 * uu], axis=-1)
    out: RGB = np.clip(rgb, 0.0, 255.0).round().astype(np.uint8)
    return out


def rgb_from_image(
    encoding: str, width: int, height: int, step: int, is_bigendian: int, data: Any
) -> RGB | Rejected:
    """A ``sensor_msgs/Image`` as an ``H x W x 3`` RGB array (module docstring)."""
    try:
        return _rgb_from_image(
            encoding, int(width), int(height), int(step), bool(is_bigendian), data
        )
    except Exception as exc:  # never out of the receive path
        return Rejected("malformed_image", f"{type(exc).__name__}: {exc}")


def _rgb_from_image(
    encoding: str, width: int, height: int, step: int, big_endian: bool, data: Any
) -> RGB | Rejected:
    bpp = _BYTES_PER_PIXEL.get(encoding)
    if bpp is None:
        return Rejected(
            "unsupported_encoding",
            f"image encoding {encoding[:32]!r} (supported: {', '.join(ENCODINGS)})",
        )
    if not (0 < width <= MAX_SIDE_PX and 0 < height <= MAX_SIDE_PX) or width * height > MAX_PIXELS:
        return Rejected("bad_size", f"image of {width} x {height} pixels")
    if bpp == 2 and encoding not in ("mono16", "16UC1") and width % 2:
        return Rejected("bad_size", f"{encoding} needs an even width, got {width}")
    if step < width * bpp:
        return Rejected("bad_step", f"step {step} < width {width} x {bpp} bytes")
    raw = np.frombuffer(data, dtype=np.uint8)
    if raw.size < step * (height - 1) + width * bpp or raw.size > MAX_BYTES:
        return Rejected("bad_size", f"{raw.size} bytes of data for {height} rows of step {step}")
    # Each row's pixels, without the row padding: (height, width * bpp), a view.
    rows = np.lib.stride_tricks.as_strided(
        raw, shape=(height, width * bpp), strides=(step, 1), writeable=False
    )
    if encoding == "rgb8":
        return rows.reshape(height, width, 3).copy()
    if encoding == "bgr8":
        return rows.reshape(height, width, 3)[:, :, ::-1].copy()
    if encoding == "rgba8":
        return rows.reshape(height, width, 4)[:, :, :3].copy()
    if encoding == "bgra8":
        return rows.reshape(height, width, 4)[:, :, 2::-1].copy()
    if encoding in ("mono8", "8UC1"):
        return np.repeat(rows[:, :, None], 3, axis=2)
    if encoding in ("mono16", "16UC1"):
        high = rows.reshape(height, width, 2)[:, :, 0 if big_endian else 1]
        return np.repeat(high[:, :, None], 3, axis=2)
    pairs = rows.reshape(height, width // 2, 4)
    if encoding in ("yuv422", "uyvy"):  # U Y0 V Y1
        u, y0, v, y1 = (pairs[:, :, i] for i in range(4))
    else:  # Y0 U Y1 V
        y0, u, y1, v = (pairs[:, :, i] for i in range(4))
    y = np.stack([y0, y1], axis=-1).reshape(height, width)
    return _yuv422_to_rgb(y, u, v)


def rgb_from_compressed(format_: str, data: Any) -> RGB | Rejected:
    """A ``sensor_msgs/CompressedImage`` (JPEG or PNG) as an RGB array (module docstring)."""
    try:
        raw = bytes(data)
        if not raw or len(raw) > MAX_BYTES:
            return Rejected("bad_size", f"compressed image of {len(raw)} bytes")
        if "compresseddepth" in format_.lower():
            return Rejected("unsupported_encoding", f"format {format_[:48]!r} (a depth image)")
        with warnings.catch_warnings():
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            image = Image.open(io.BytesIO(raw), formats=("JPEG", "PNG"))
            w, h = image.size
            if not (0 < w <= MAX_SIDE_PX and 0 < h <= MAX_SIDE_PX) or w * h > MAX_PIXELS:
                return Rejected("bad_size", f"compressed image of {w} x {h} pixels")
            image.load()
        rgb: RGB = np.asarray(image.convert("RGB"))
        return rgb
    except Exception as exc:  # a broken or unknown picture; never out of the receive path
        return Rejected("corrupt_image", f"{type(exc).__name__}: {str(exc)[:120]}")
