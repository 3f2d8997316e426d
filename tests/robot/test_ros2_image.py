"""ROS 2 images as RGB without rclpy (``egc_robot.ros2_image``): encodings, row padding, byte
order, YUV 4:2:2, JPEG/PNG, and every malformed image a counted Rejected, never an exception."""

from __future__ import annotations

import array
import io

import numpy as np
import pytest
from egc_robot.ros2_core import Rejected
from egc_robot.ros2_image import rgb_from_compressed, rgb_from_image
from hypothesis import given
from hypothesis import strategies as st
from PIL import Image

RNG = np.random.default_rng(5)
RGB = RNG.integers(0, 256, (6, 8, 3), dtype=np.uint8)  # 6 rows of 8 pixels


def padded(rows: np.ndarray, pad: int) -> tuple[bytes, int]:
    """Rows (H x bytes) with ``pad`` junk bytes after each, and the step."""
    h = rows.shape[0]
    junk = np.full((h, pad), 0xEE, np.uint8)
    data = np.concatenate([rows.reshape(h, -1), junk], axis=1)
    return data.tobytes(), data.shape[1]


@pytest.mark.parametrize("pad", [0, 3, 16])
@pytest.mark.parametrize(
    "encoding,pixels",
    [
        ("rgb8", RGB),
        ("bgr8", RGB[:, :, ::-1]),
        ("rgba8", np.concatenate([RGB, np.full((6, 8, 1), 7, np.uint8)], axis=2)),
        ("bgra8", np.concatenate([RGB[:, :, ::-1], np.full((6, 8, 1), 7, np.uint8)], axis=2)),
    ],
)
def test_colour_encodings_with_row_padding(encoding, pixels, pad):
    data, step = padded(np.ascontiguousarray(pixels), pad)
    out = rgb_from_image(encoding, 8, 6, step, 0, array.array("B", data))  # rclpy's uint8[]
    assert isinstance(out, np.ndarray) and out.dtype == np.uint8
    np.testing.assert_array_equal(out, RGB)


@pytest.mark.parametrize("encoding", ["mono8", "8UC1"])
def test_mono8(encoding):
    grey = RGB[:, :, 0]
    data, step = padded(grey, 2)
    out = rgb_from_image(encoding, 8, 6, step, 0, data)
    np.testing.assert_array_equal(out, np.repeat(grey[:, :, None], 3, axis=2))


@pytest.mark.parametrize("big_endian", [0, 1])
def test_mono16_shows_the_high_byte_in_either_byte_order(big_endian):
    values = RNG.integers(0, 65536, (6, 8), dtype=np.uint16)
    data = values.astype(">u2" if big_endian else "<u2").tobytes()
    out = rgb_from_image("mono16", 8, 6, 16, big_endian, data)
    np.testing.assert_array_equal(out[:, :, 1], (values >> 8).astype(np.uint8))


def uyvy(y: int, u: int, v: int, pixels: int) -> bytes:
    return bytes([u, y, v, y] * (pixels // 2))


@pytest.mark.parametrize(
    "yuv,rgb",
    [
        ((235, 128, 128), (255, 255, 255)),  # BT.601 limited-range white
        ((16, 128, 128), (0, 0, 0)),
        ((81, 90, 240), (255, 0, 0)),  # red
        ((145, 54, 34), (0, 255, 0)),  # green
        ((41, 240, 110), (0, 0, 255)),  # blue
    ],
)
def test_yuv422_both_byte_orders(yuv, rgb):
    y, u, v = yuv
    out = rgb_from_image("yuv422", 8, 2, 16, 0, uyvy(y, u, v, 16))
    assert np.all(np.abs(out.astype(int) - rgb) <= 3), out[0, 0]
    yuyv = bytes([y, u, y, v] * 8)
    out2 = rgb_from_image("yuv422_yuy2", 8, 2, 16, 0, yuyv)
    np.testing.assert_array_equal(out, out2)


def encoded(fmt: str, rgb: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    Image.fromarray(rgb).save(buffer, format=fmt, **({"quality": 95} if fmt == "JPEG" else {}))
    return buffer.getvalue()


def test_compressed_png_is_exact_and_jpeg_close():
    big = np.kron(RGB, np.ones((8, 8, 1), np.uint8))  # 48 x 64, smooth enough for JPEG
    np.testing.assert_array_equal(rgb_from_compressed("png", encoded("PNG", big)), big)
    out = rgb_from_compressed("bgr8; jpeg compressed bgr8", encoded("JPEG", big))
    assert isinstance(out, np.ndarray) and out.shape == big.shape
    assert np.abs(out.astype(int) - big).mean() < 12


@pytest.mark.parametrize(
    "args,reason",
    [
        (("bayer_rggb8", 8, 6, 8, 0, bytes(48)), "unsupported_encoding"),
        (("rgb8", 8, 6, 20, 0, bytes(120)), "bad_step"),  # a step shorter than a row
        (("rgb8", 8, 6, 24, 0, bytes(100)), "bad_size"),  # data shorter than its rows
        (("rgb8", 0, 6, 0, 0, b""), "bad_size"),
        (("rgb8", 100_000, 100_000, 300_000, 0, b""), "bad_size"),
        (("yuv422", 7, 2, 14, 0, bytes(28)), "bad_size"),  # odd width in 4:2:2
        (("rgb8", "x", 6, 24, 0, bytes(144)), "malformed_image"),
    ],
)
def test_malformed_images_are_rejected(args, reason):
    out = rgb_from_image(*args)
    assert isinstance(out, Rejected) and out.reason == reason, out


def test_a_decompression_bomb_is_refused_from_its_header():
    # A PNG 20000 pixels wide (a few hundred bytes): refused from its header's size.
    buffer = io.BytesIO()
    Image.new("L", (20_000, 1)).save(buffer, format="PNG")
    wide = rgb_from_compressed("png", buffer.getvalue())
    assert isinstance(wide, Rejected) and wide.reason == "bad_size"


@pytest.mark.parametrize(
    "data,fmt",
    [
        (b"", "jpeg"),
        (b"\xff\xd8\xff\xe0 not really a jpeg", "jpeg"),
        (encoded("JPEG", RGB)[:40], "jpeg"),  # cut short
        (encoded("PNG", RGB), "16UC1; compressedDepth png"),
        (b"GIF89a" + bytes(30), "gif"),
    ],
)
def test_broken_or_unsupported_compressed_images_are_rejected(data, fmt):
    assert isinstance(rgb_from_compressed(fmt, data), Rejected)


@given(st.binary(max_size=200), st.sampled_from(["jpeg", "png", ""]))
def test_no_compressed_bytes_make_it_raise(data, fmt):
    rgb_from_compressed(fmt, data)


@given(
    st.sampled_from(["rgb8", "bgr8", "mono8", "mono16", "yuv422", "rgba8", "nonsense"]),
    st.integers(-2, 40),
    st.integers(-2, 40),
    st.integers(-2, 200),
    st.binary(max_size=400),
)
def test_no_image_fields_make_it_raise(encoding, width, height, step, data):
    rgb_from_image(encoding, width, height, step, 0, data)
