"""Wire contract (DESIGN 7): valid messages round-trip; anything else is rejected with a reason."""

from __future__ import annotations

import math

import msgpack
import numpy as np
import pytest
from egc_common.messages import (
    MAX_COMMAND_BYTES,
    TELEMETRY_PINNED_KEYS,
    BaseCommand,
    MapMessage,
    Odometry,
    OperatorCommand,
    Rejection,
    RejectReason,
    ScanMessage,
    StateMessage,
    Telemetry,
    decode_base_command,
    decode_clock_reply,
    decode_command,
    decode_map,
    decode_odometry,
    decode_scan,
    decode_state,
    decode_telemetry,
    encode_clock_reply,
)
from hypothesis import given, settings
from hypothesis import strategies as st

unit = st.floats(-1.0, 1.0, allow_nan=False)
ids = st.text(st.characters(categories=("L", "N")), min_size=1, max_size=64)
commands = st.builds(
    OperatorCommand,
    seq=st.integers(0, 2**63 - 1),
    stamp_ns=st.integers(0, 2**63 - 1),
    x=unit,
    y=unit,
    mode=st.sampled_from(["direct", "shared"]),
    deadman=st.booleans(),
    estop=st.booleans(),
    reset=st.booleans(),
    op=ids,
)
DECODERS = [
    decode_command,
    decode_telemetry,
    decode_state,
    decode_clock_reply,
    decode_scan,
    decode_base_command,
    decode_odometry,
]


def valid_command_map(**changes):
    m = {
        "v": 1,
        "seq": 3,
        "stamp_ns": 10,
        "x": 0.5,
        "y": -0.5,
        "mode": "shared",
        "deadman": True,
        "estop": False,
        "reset": False,
        "op": "op1",
    }
    m.update(changes)
    return m


def reason_of(payload):
    result = decode_command(payload)
    assert isinstance(result, Rejection), result
    return result.reason


@given(commands)
def test_every_valid_command_round_trips(cmd):
    assert decode_command(cmd.encode()) == cmd


def test_plain_msgpack_map_from_outside_tools_decodes():
    cmd = decode_command(msgpack.packb(valid_command_map(x=0, y=1)))
    assert isinstance(cmd, OperatorCommand) and (cmd.x, cmd.y) == (0.0, 1.0)


@given(st.binary(max_size=2048))
@settings(max_examples=500)
def test_random_bytes_never_raise(data):
    for decode in DECODERS:
        result = decode(data)
        if isinstance(result, Rejection):
            assert isinstance(result.reason, RejectReason) and result.detail


@given(commands, st.data())
def test_truncated_payloads_are_rejected(cmd, data):
    raw = cmd.encode()
    cut = data.draw(st.integers(0, len(raw) - 1))
    assert isinstance(decode_command(raw[:cut]), Rejection)


@pytest.mark.parametrize(
    ("changes", "reason"),
    [
        ({"x": math.nan}, RejectReason.NOT_FINITE),
        ({"y": math.inf}, RejectReason.NOT_FINITE),
        ({"x": 1.5}, RejectReason.OUT_OF_RANGE),
        ({"x": 1e308}, RejectReason.OUT_OF_RANGE),
        ({"seq": -1}, RejectReason.OUT_OF_RANGE),
        ({"seq": 2**64 - 1}, RejectReason.OUT_OF_RANGE),
        ({"seq": 1.0}, RejectReason.WRONG_TYPE),
        ({"seq": True}, RejectReason.WRONG_TYPE),
        ({"x": "0.5"}, RejectReason.WRONG_TYPE),
        ({"x": True}, RejectReason.WRONG_TYPE),
        ({"deadman": 1}, RejectReason.WRONG_TYPE),
        ({"mode": "auto"}, RejectReason.OUT_OF_RANGE),
        ({"op": ""}, RejectReason.OUT_OF_RANGE),
        ({"op": "x" * 65}, RejectReason.OUT_OF_RANGE),
        ({"op": 7}, RejectReason.WRONG_TYPE),
        ({"v": 2}, RejectReason.UNKNOWN_VERSION),
        ({"v": "1"}, RejectReason.WRONG_TYPE),
    ],
)
def test_invalid_fields_are_rejected_with_reason(changes, reason):
    assert reason_of(msgpack.packb(valid_command_map(**changes))) is reason


@pytest.mark.parametrize(
    "key", ["v", "seq", "stamp_ns", "x", "y", "mode", "deadman", "estop", "reset", "op"]
)
def test_missing_keys_are_rejected(key):
    m = valid_command_map()
    del m[key]
    assert reason_of(msgpack.packb(m)) is RejectReason.MISSING_KEY


def test_oversized_and_non_map_payloads():
    big = msgpack.packb(valid_command_map(op="a" * 60, pad="z" * MAX_COMMAND_BYTES))
    assert reason_of(big) is RejectReason.TOO_LARGE
    assert reason_of(msgpack.packb([1, 2, 3])) is RejectReason.NOT_A_MAP
    assert reason_of(b"") is RejectReason.NOT_MSGPACK
    assert reason_of("not bytes") is RejectReason.WRONG_TYPE
    assert reason_of(msgpack.packb(valid_command_map()) + b"\x00") is RejectReason.NOT_MSGPACK


@given(
    st.recursive(
        st.none()
        | st.booleans()
        | st.floats()
        | st.integers(-(2**63), 2**64 - 1)
        | st.text(max_size=20)
        | st.binary(max_size=20),
        lambda c: st.lists(c, max_size=4) | st.dictionaries(st.text(max_size=8), c, max_size=4),
        max_leaves=20,
    )
)
@settings(max_examples=300)
def test_wrong_types_anywhere_never_raise(value):
    for key in ("x", "seq", "mode", "deadman", "op"):
        payload = msgpack.packb(valid_command_map(**{key: value}))
        result = decode_command(payload)
        assert isinstance(result, (OperatorCommand, Rejection))
    for decode in DECODERS:
        decode(msgpack.packb(value))


def test_constructing_an_invalid_command_raises():
    with pytest.raises(ValueError, match="x"):
        OperatorCommand(
            seq=0,
            stamp_ns=0,
            x=2.0,
            y=0.0,
            mode="shared",
            deadman=True,
            estop=False,
            reset=False,
            op="a",
        )


def test_telemetry_round_trips_with_scan_and_circles():
    scan = np.random.default_rng(0).normal(size=(720, 2)).astype(np.float32)
    t = Telemetry(
        seq=5,
        stamp_ns=123,
        state="DRIVING",
        mode="shared",
        v_ref=0.1,
        w_ref=0.2,
        v_cmd=0.05,
        w_cmd=0.1,
        w_si=0.8,
        region="conditional",
        side="left",
        limiter="egc",
        igc=(0.5, 0.0, 0.3),
        agc=(0.4, 0.3, 0.5),
        egc=(0.45, 0.1, 0.5),
        r_rc=0.5,
        scan_xy=scan,
        pose=(1.0, 2.0, 0.5),
        cmd_age_ms=3.0,
        operator="op1",
        profile="pioneer3dx",
        rejected=2,
        cycle=9,
    )
    back = decode_telemetry(t.encode())
    assert isinstance(back, Telemetry)
    np.testing.assert_array_equal(back.scan_xy, scan)
    for key in (
        "seq",
        "stamp_ns",
        "state",
        "mode",
        "v_ref",
        "w_si",
        "region",
        "side",
        "limiter",
        "igc",
        "agc",
        "egc",
        "pose",
        "cmd_age_ms",
        "operator",
        "profile",
        "rejected",
        "cycle",
    ):
        assert getattr(back, key) == getattr(t, key), key
    raw = msgpack.unpackb(t.encode())
    design_7 = {"v", "seq", "stamp_ns", "state", "v_ref", "w_ref", "v_cmd", "w_cmd", "w_si", "mode"}
    assert set(TELEMETRY_PINNED_KEYS) == design_7
    for key in TELEMETRY_PINNED_KEYS:
        assert key in raw  # the pinned keys (DESIGN 7)


def test_telemetry_rejects_nan_in_scan_and_bad_state():
    t = Telemetry(
        seq=1,
        stamp_ns=1,
        state="HOLD",
        mode="direct",
        v_ref=0,
        w_ref=0,
        v_cmd=0,
        w_cmd=0,
        w_si=1.0,
        scan_xy=np.array([[np.nan, 0.0]], np.float32),
    )
    assert decode_telemetry(t.encode()).reason is RejectReason.NOT_FINITE
    raw = msgpack.unpackb(t.encode())
    raw["state"] = "FLYING"
    raw["scan_xy"] = b""
    assert decode_telemetry(msgpack.packb(raw)).reason is RejectReason.OUT_OF_RANGE


def test_other_messages_round_trip():
    s = StateMessage(
        stamp_ns=5, state="ESTOP", reason="operator e-stop", operator="op1", rejected=3
    )
    assert decode_state(s.encode()) == s
    assert decode_clock_reply(encode_clock_reply(42)) == 42
    b = BaseCommand(stamp_ns=1, seq=2, linear_mps=0.1, angular_radps=-0.2)
    assert decode_base_command(b.encode()) == b
    o = Odometry(stamp_ns=1, x_m=1.0, y_m=2.0, theta_rad=0.1, linear_mps=0.1, angular_radps=0.0)
    assert decode_odometry(o.encode()) == o
    ranges = np.array([1.0, np.inf, np.nan, 2.0], np.float32)
    sc = ScanMessage(
        stamp_ns=3,
        angle_min_rad=-1.0,
        angle_increment_rad=0.01,
        range_min_m=0.1,
        range_max_m=10.0,
        ranges_m=ranges,
    )
    back = decode_scan(sc.encode())
    assert isinstance(back, ScanMessage)
    np.testing.assert_array_equal(back.ranges_m, ranges)  # no-return readings survive the wire


@pytest.mark.parametrize(
    "extra",
    [
        [1, 2, 3],
        {"a": 1},
        [[]] * 1000,
    ],
)
def test_a_scan_is_one_flat_map(extra):
    """A scan holds scalars and bytes only: a container in it is refused at its header. (An
    outside check: 4 MB of empty arrays took 1.2 s to unpack in the receive path, and froze
    the robot that long; see _unpack's flat mode.)"""
    fields = {"v": 1, "stamp_ns": 3, "angle_min_rad": -1.0, "angle_increment_rad": 0.01}
    fields |= {"range_min_m": 0.1, "range_max_m": 10.0, "ranges_m": b"\0\0\0\0" * 4}
    assert isinstance(decode_scan(msgpack.packb(fields | {"x": 1.0})), ScanMessage)
    rejected = decode_scan(msgpack.packb(fields | {"x": extra}))
    assert isinstance(rejected, Rejection)
    assert rejected.reason in (RejectReason.NOT_MSGPACK, RejectReason.WRONG_TYPE)
    bomb = b"\xdd" + (4 * 1024 * 1024 - 10).to_bytes(4, "big") + b"\x90" * (4 * 1024 * 1024 - 10)
    assert decode_scan(bomb).reason is RejectReason.NOT_MSGPACK  # at the header, not NOT_A_MAP


def test_map_round_trips_bit_packed_and_rejects_mismatches():
    grid = np.random.default_rng(1).random((37, 53)) > 0.7
    m = MapMessage(
        stamp_ns=1,
        resolution_m=0.05,
        origin_x_m=-15.0,
        origin_y_m=2.0,
        blocked=grid,
        goal=(1.0, 2.0),
    )
    raw = m.encode()
    back = decode_map(raw)
    assert isinstance(back, MapMessage)
    np.testing.assert_array_equal(back.blocked, grid)
    assert (back.resolution_m, back.origin_x_m, back.origin_y_m, back.goal) == (
        0.05,
        -15.0,
        2.0,
        (1.0, 2.0),
    )
    assert len(raw) < grid.size // 8 + 200  # bit-packed on the wire
    doc = msgpack.unpackb(raw)
    doc["width"] = 54
    assert decode_map(msgpack.packb(doc)).reason is RejectReason.OUT_OF_RANGE
    doc["width"], doc["height"] = 10**5, 10**5
    assert decode_map(msgpack.packb(doc)).reason is RejectReason.TOO_LARGE
    assert isinstance(decode_map(raw[:-2]), Rejection)


def test_clock_reply_names_its_clock_optionally():
    from egc_common.clock_id import monotonic_clock_id
    from egc_common.messages import decode_clock_id

    assert decode_clock_id(encode_clock_reply(42)) is None
    assert decode_clock_id(encode_clock_reply(42, "linux-boot:abc")) == "linux-boot:abc"
    assert decode_clock_reply(encode_clock_reply(42, "linux-boot:abc")) == 42
    assert decode_clock_id(b"\xc1garbage") is None
    clock = monotonic_clock_id()
    assert clock is None or clock.startswith("linux-boot:")


def test_a_state_message_may_carry_the_map_pose_for_the_fleet_map():
    """DESIGN 15: the state (1 Hz) gives where the robot is in its map frame; the key is
    optional (older robots leave it out) and checked like every other."""
    s = StateMessage(stamp_ns=5, state="HOLD", reason="x", map_pose=(1.5, -2.0, 0.3))
    assert decode_state(s.encode()) == s
    assert "map_pose" not in msgpack.unpackb(StateMessage(5, "IDLE", "x").encode())
    raw = msgpack.unpackb(s.encode())
    raw["map_pose"] = [1.0, float("nan"), 0.0]
    assert isinstance(decode_state(msgpack.packb(raw)), Rejection)
    raw["map_pose"] = [1.0, 2.0]
    assert decode_state(msgpack.packb(raw)).reason is RejectReason.WRONG_TYPE
