"""DESIGN 14 wire messages: a zenoh source's command, a lock's value, and the telemetry and
state keys ``source`` / ``lock`` (optional: absent, an older decoder sees nothing new)."""

from __future__ import annotations

import math

import msgpack
import pytest
from egc_common import keys
from egc_common.messages import (
    Rejection,
    RejectReason,
    StateMessage,
    Telemetry,
    decode_state,
    decode_telemetry,
)
from egc_common.source_msg import SourceCommand, decode_lock, decode_source_command, encode_lock
from hypothesis import given
from hypothesis import strategies as st


def test_the_pinned_source_command_round_trips():
    cmd = SourceCommand(seq=7, stamp_ns=123, v_mps=0.25, w_radps=-0.5)
    raw = msgpack.unpackb(cmd.encode())
    assert raw == {"v": 1, "seq": 7, "stamp_ns": 123, "v_mps": 0.25, "w_radps": -0.5}
    assert decode_source_command(cmd.encode()) == cmd
    # Integers are numbers too (an autonomy stack in another language may send 0).
    ints = msgpack.packb({"v": 1, "seq": 1, "stamp_ns": 0, "v_mps": 0, "w_radps": 1})
    assert decode_source_command(ints) == SourceCommand(1, 0, 0.0, 1.0)


@pytest.mark.parametrize(
    ("change", "reason"),
    [
        ({"v_mps": math.nan}, RejectReason.NOT_FINITE),
        ({"v_mps": 1e3}, RejectReason.OUT_OF_RANGE),
        ({"w_radps": "fast"}, RejectReason.WRONG_TYPE),
        ({"seq": -1}, RejectReason.OUT_OF_RANGE),
        ({"v": 2}, RejectReason.UNKNOWN_VERSION),
        ({"v_mps": {"x": 1}}, RejectReason.WRONG_TYPE),
    ],
)
def test_bad_source_commands_are_rejected_with_a_reason(change, reason):
    msg = {"v": 1, "seq": 1, "stamp_ns": 0, "v_mps": 0.1, "w_radps": 0.0} | change
    out = decode_source_command(msgpack.packb(msg))
    assert isinstance(out, Rejection) and out.reason is reason


def test_a_missing_key_and_an_oversized_payload_are_rejected():
    missing = decode_source_command(msgpack.packb({"v": 1, "seq": 1, "stamp_ns": 0, "v_mps": 0}))
    assert isinstance(missing, Rejection) and missing.reason is RejectReason.MISSING_KEY
    big = decode_source_command(b"\x00" * 10_000)
    assert isinstance(big, Rejection) and big.reason is RejectReason.TOO_LARGE


@given(st.binary(max_size=64))
def test_decoders_never_raise(payload):
    decode_source_command(payload)
    decode_lock(payload)


def test_a_lock_is_a_msgpack_bool():
    assert decode_lock(encode_lock(True)) is True
    assert decode_lock(encode_lock(False)) is False
    assert encode_lock(True) == b"\xc3"
    for bad in (msgpack.packb(1), msgpack.packb("true"), msgpack.packb({"v": 1}), b"", "x"):
        assert isinstance(decode_lock(bad), Rejection)


def test_keys():
    assert keys.source("r1", "nav") == "egc/r1/source/nav"
    assert keys.lock("r1", "pause") == "egc/r1/lock/pause"
    with pytest.raises(ValueError):
        keys.source("r1", "a/b")


def test_telemetry_and_state_carry_source_and_lock_when_known():
    t = Telemetry(1, 2, "DRIVING", "shared", 0, 0, 0, 0, 1, source="nav", lock="pause")
    back = decode_telemetry(t.encode())
    assert not isinstance(back, Rejection)
    assert (back.source, back.lock, back.source_age_ms) == ("nav", "pause", None)
    s = StateMessage(1, "HOLD", "lock pause: true", None, 0, source=None, lock="pause")
    raw = msgpack.unpackb(s.encode())
    assert raw["lock"] == "pause" and "source" not in raw
    assert decode_state(s.encode()) == s


@given(
    st.dictionaries(
        st.sampled_from(["v", "seq", "stamp_ns", "v_mps", "w_radps", "x"]),
        st.one_of(
            st.integers(-5, 2**64 - 1),
            st.floats(allow_nan=True),
            st.booleans(),
            st.text(max_size=3),
            st.lists(st.integers(), max_size=2),
            st.dictionaries(st.text(max_size=2), st.integers(), max_size=2),
        ),
    )
)
def test_the_fast_path_and_the_full_decoder_agree(m):
    from egc_common.messages import _decode
    from egc_common.source_msg import MAX_COMMAND_BYTES, _build

    payload = msgpack.packb(m)
    full = _decode(payload, MAX_COMMAND_BYTES, _build, flat=True)
    fast = decode_source_command(payload)
    assert fast == full or (isinstance(fast, Rejection) and isinstance(full, Rejection))
