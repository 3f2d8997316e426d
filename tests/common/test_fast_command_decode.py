"""``decode_command``'s short path (issue 9) gives what the full decoder gives, for any payload.

The robot decodes every command before its base command can go out, so a well-formed command in
the usual types is checked in one go; anything else goes through the field-by-field decoder.
Both must agree on every payload: the same command, or the same rejection.
"""

from __future__ import annotations

import math

import msgpack
from egc_common.messages import (
    MAX_COMMAND_BYTES,
    OperatorCommand,
    Rejection,
    _build_command,
    _decode,
    _fast_command,
    decode_command,
)
from hypothesis import given, settings
from hypothesis import strategies as st

GOOD = {
    "v": 1,
    "seq": 12,
    "stamp_ns": 123_456_789_012,
    "x": 0.5,
    "y": -0.25,
    "mode": "shared",
    "deadman": True,
    "estop": False,
    "reset": False,
    "op": "bench",
}

odd_values = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(2**63), 2**64 - 1),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([-1.0, 1.0, -1, 1, 0, 0.0, 1.0000001, "direct", "shared", "egc", "dwa"]),
    st.text(max_size=70),
    st.binary(max_size=8),
    st.lists(st.integers(-5, 5), max_size=2),
)


def full(payload: object) -> OperatorCommand | Rejection:
    return _decode(payload, MAX_COMMAND_BYTES, _build_command)


def same(a: OperatorCommand | Rejection, b: OperatorCommand | Rejection) -> bool:
    if isinstance(a, OperatorCommand) and isinstance(b, OperatorCommand):
        return all(
            type(getattr(a, k)) is type(getattr(b, k)) and getattr(a, k) == getattr(b, k)
            for k in a.__slots__
        )
    return a == b


def test_the_usual_command_takes_the_short_path():
    payload = msgpack.packb(GOOD)
    cmd = _fast_command(payload)
    assert cmd is not None and same(cmd, full(payload))
    with_extras = msgpack.packb(GOOD | {"view_age_ms": 40, "filter": "ek-egc", "more": [1]})
    cmd = _fast_command(with_extras)
    assert cmd is not None and cmd.view_age_ms == 40 and cmd.filter == "ek-egc"
    assert same(cmd, full(with_extras))


@settings(max_examples=2000)
@given(
    st.sampled_from([*GOOD, "view_age_ms", "filter", "extra"]),
    odd_values,
    st.booleans(),
)
def test_one_field_changed_or_dropped(key, value, drop):
    message = dict(GOOD)
    if drop:
        message.pop(key, None)
    else:
        message[key] = value
    payload = msgpack.packb(message, use_bin_type=True)
    assert same(decode_command(payload), full(payload))


@settings(max_examples=1000)
@given(st.dictionaries(st.sampled_from([*GOOD, "view_age_ms", "filter"]), odd_values))
def test_any_map(message):
    payload = msgpack.packb(GOOD | message, use_bin_type=True)
    assert same(decode_command(payload), full(payload))


@settings(max_examples=500)
@given(st.one_of(st.binary(max_size=600), odd_values.map(msgpack.packb)))
def test_any_bytes(payload):
    assert same(decode_command(payload), full(payload))


def test_not_bytes_and_oversized():
    for payload in (
        bytearray(msgpack.packb(GOOD)),
        memoryview(msgpack.packb(GOOD)),
        "text",
        None,
        msgpack.packb(GOOD | {"op": "o" * 60, "pad": "p" * 600}),
    ):
        assert same(decode_command(payload), full(payload))


def test_nan_and_edges():
    for x in (math.nan, math.inf, -1.0, 1.0, -0.0, 1, True):
        payload = msgpack.packb(GOOD | {"x": x})
        assert same(decode_command(payload), full(payload))
