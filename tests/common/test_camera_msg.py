"""The camera message (DESIGN 12, pinned keys): round trip, and every bad payload a Rejection."""

from __future__ import annotations

import msgpack
import pytest
from egc_common.camera_msg import MAX_CAMERA_BYTES, CameraFrame, decode_camera
from egc_common.messages import Rejection, RejectReason
from hypothesis import given
from hypothesis import strategies as st


def wire(**changes):
    m = {
        "v": 1,
        "seq": 7,
        "stamp_ns": 123_456_789,
        "codec": "h264",
        "width": 320,
        "height": 240,
        "key": True,
        "data": b"\x00\x00\x00\x01\x67abc",
    }
    m.update(changes)
    return {k: v for k, v in m.items() if v is not ...}


def pack(m) -> bytes:
    return msgpack.packb(m, use_bin_type=True)


def test_round_trip_with_exactly_the_pinned_keys():
    frame = CameraFrame(3, 99, "jpeg", 160, 120, True, b"\xff\xd8jpeg")
    payload = frame.encode()
    assert set(msgpack.unpackb(payload)) == {
        "v",
        "seq",
        "stamp_ns",
        "codec",
        "width",
        "height",
        "key",
        "data",
    }
    back = decode_camera(payload)
    assert isinstance(back, CameraFrame)
    assert (back.seq, back.stamp_ns, back.codec, back.width, back.height, back.key, back.data) == (
        3,
        99,
        "jpeg",
        160,
        120,
        True,
        b"\xff\xd8jpeg",
    )


def test_unknown_keys_are_ignored():
    assert isinstance(decode_camera(pack(wire(exposure_ms=4))), CameraFrame)


@pytest.mark.parametrize(
    "changes,reason",
    [
        ({"codec": "vp9"}, RejectReason.UNKNOWN_CODEC),
        ({"codec": "H264"}, RejectReason.UNKNOWN_CODEC),
        ({"codec": 264}, RejectReason.WRONG_TYPE),
        ({"width": 8}, RejectReason.OUT_OF_RANGE),
        ({"height": 100_000}, RejectReason.OUT_OF_RANGE),
        ({"width": 4096, "height": 4096}, RejectReason.TOO_LARGE),
        ({"width": -320}, RejectReason.OUT_OF_RANGE),
        ({"width": 320.0}, RejectReason.WRONG_TYPE),
        ({"seq": -1}, RejectReason.OUT_OF_RANGE),
        ({"seq": True}, RejectReason.WRONG_TYPE),
        ({"stamp_ns": "now"}, RejectReason.WRONG_TYPE),
        ({"key": 1}, RejectReason.WRONG_TYPE),
        ({"data": "text"}, RejectReason.WRONG_TYPE),
        ({"data": b""}, RejectReason.OUT_OF_RANGE),
        ({"data": ...}, RejectReason.MISSING_KEY),
        ({"codec": ...}, RejectReason.MISSING_KEY),
        ({"v": 2}, RejectReason.UNKNOWN_VERSION),
        ({"data": [1, 2, 3]}, RejectReason.TOO_LARGE),  # no arrays in this message at all
        ({"extra": {"nested": 1}}, RejectReason.WRONG_TYPE),
    ],
)
def test_bad_fields_are_rejected_with_their_reason(changes, reason):
    result = decode_camera(pack(wire(**changes)))
    assert isinstance(result, Rejection), changes
    assert result.reason is reason, result


def test_a_50_mb_payload_is_refused_by_its_length_before_unpacking(monkeypatch):
    huge = pack(wire(data=b"\x00" * (50 * 1024 * 1024)))

    def unpack_must_not_run(*args, **kwargs):
        raise AssertionError("msgpack was asked to unpack a 50 MB payload")

    monkeypatch.setattr(msgpack, "unpackb", unpack_must_not_run)
    result = decode_camera(huge)
    assert isinstance(result, Rejection) and result.reason is RejectReason.TOO_LARGE
    # Also as a memoryview (what a transport may hand over): no copy to bytes first.
    assert decode_camera(memoryview(huge)).reason is RejectReason.TOO_LARGE  # type: ignore[union-attr]
    monkeypatch.undo()
    just_over = pack(wire(data=b"\x00" * (MAX_CAMERA_BYTES + 1)))
    assert decode_camera(just_over).reason is RejectReason.TOO_LARGE  # type: ignore[union-attr]


@pytest.mark.parametrize(
    "payload",
    [b"", b"\xc1", b"not msgpack at all", pack([1, 2]), pack("text"), 12, None, "str"],
)
def test_garbage_is_a_rejection(payload):
    assert isinstance(decode_camera(payload), Rejection)


@given(st.binary(max_size=300))
def test_no_bytes_make_it_raise(data):
    decode_camera(data)


def test_the_constructor_checks_what_the_decoder_checks():
    with pytest.raises(ValueError, match="unknown_codec"):
        CameraFrame(0, 0, "png", 320, 240, True, b"x")
    with pytest.raises(ValueError, match="out_of_range"):
        CameraFrame(0, 0, "jpeg", 320, 5, True, b"x")
