"""DESIGN 12's compact telemetry scan and the new optional keys: sizes, round trips, strictness."""

from __future__ import annotations

import math

import msgpack
import numpy as np
import pytest
from egc_common.messages import (
    OperatorCommand,
    Rejection,
    RejectReason,
    Telemetry,
    decode_command,
    decode_telemetry,
)
from egc_common.scan import Scan
from egc_common.scan_compact import PolarScan, compact


def scan(ranges: np.ndarray, **kwargs: object) -> Scan:
    n = ranges.size
    return Scan.uniform(ranges, -math.pi, 2 * math.pi / n, 0.1, 20.0, **kwargs)  # type: ignore[arg-type]


def telemetry(**kwargs: object) -> Telemetry:
    base: dict[str, object] = dict(
        seq=1, stamp_ns=10, state="DRIVING", mode="shared", v_ref=0.1, w_ref=0.0, v_cmd=0.1,
        w_cmd=0.0, w_si=1.0,
    )  # fmt: skip
    base.update(kwargs)
    return Telemetry(**base)  # type: ignore[arg-type]


def test_compact_keeps_the_nearest_reading_of_each_group() -> None:
    r = np.full(360, 5.0)
    r[101] = 0.75  # a thin obstacle seen by one beam
    r[200:204] = np.inf  # no return in a whole group: not shown
    r[300] = 0.05  # below range_min: not shown
    polar = compact(scan(r, mount_x_m=0.2), 90)
    assert polar is not None and polar.beams == 90
    assert polar.ranges_mm[25] == 750  # beams 100-103: the obstacle survives the decimation
    assert polar.ranges_mm[50] == 0 and polar.ranges_mm[75] == 5000
    assert polar.angle_increment_rad == pytest.approx(4 * 2 * math.pi / 360)
    assert polar.origin_xy_m == (0.2, 0.0)
    xy = polar.points()
    assert len(xy) == polar.shown == 89  # one group without a reading
    assert np.allclose(np.hypot(xy[:, 0] - 0.2, xy[:, 1]).max(), 5.0, atol=1e-3)


def test_compact_refuses_uneven_beams() -> None:
    uneven = Scan(np.array([0.0, 0.1, 0.3]), np.array([1.0, 1.0, 1.0]), 0.1, 10.0)
    assert compact(uneven, 10) is None


def test_telemetry_round_trip_is_smaller_and_the_same_points() -> None:
    raw = scan(np.linspace(1.0, 10.0, 360))
    polar = compact(raw, 180)
    assert polar is not None
    extra = np.array([[0.3, 0.0]], np.float32)  # a REP 117 -inf point: no beam's
    xy = np.concatenate((polar.points(), extra))
    compact_msg = telemetry(scan_xy=xy, scan_polar=polar, tel_hz=20.0, cut=("camera",))
    legacy_msg = telemetry(scan_xy=xy)
    payload = compact_msg.encode()
    assert len(payload) < len(legacy_msg.encode()) - 1000  # 2 bytes a beam, not 8 a point
    decoded = decode_telemetry(payload)
    assert isinstance(decoded, Telemetry)
    assert np.array_equal(decoded.scan_xy, xy)
    assert decoded.cut == ("camera",) and decoded.tel_hz == 20.0
    old = decode_telemetry(legacy_msg.encode())  # an older robot's telemetry still decodes
    assert isinstance(old, Telemetry) and np.array_equal(old.scan_xy, xy)
    assert old.scan_polar is None and old.tel_hz is None and old.cut == ()


@pytest.mark.parametrize(
    ("changes", "reason"),
    [
        ({"scan_mm": "abc"}, RejectReason.WRONG_TYPE),
        ({"scan_mm": b"\x01\x02\x03"}, RejectReason.OUT_OF_RANGE),
        ({"scan_a0": 100.0}, RejectReason.OUT_OF_RANGE),
        ({"scan_da": math.nan}, RejectReason.NOT_FINITE),
        ({"scan_a0": None}, RejectReason.MISSING_KEY),
        ({"scan_origin": [1.0]}, RejectReason.WRONG_TYPE),
        ({"cut": "camera,bogus"}, RejectReason.OUT_OF_RANGE),
        ({"cut": "scan,scan"}, RejectReason.OUT_OF_RANGE),
        ({"tel_hz": -1.0}, RejectReason.OUT_OF_RANGE),
        ({"scan_n": 1.5}, RejectReason.WRONG_TYPE),
        ({"link_kbps": math.inf}, RejectReason.NOT_FINITE),
    ],
)
def test_bad_compact_keys_are_refused(changes: dict[str, object], reason: RejectReason) -> None:
    polar = PolarScan(np.array([1000, 0, 2000], np.uint16), 0.0, 0.1)
    wire = msgpack.unpackb(telemetry(scan_xy=polar.points(), scan_polar=polar).encode())
    for key, value in changes.items():
        if value is None:
            del wire[key]
        else:
            wire[key] = value
    result = decode_telemetry(msgpack.packb(wire, use_bin_type=True))
    assert isinstance(result, Rejection) and result.reason is reason, result


def test_command_reports_round_trip_and_are_checked() -> None:
    cmd = OperatorCommand(
        seq=3, stamp_ns=5, x=0.5, y=0.0, mode="shared", deadman=True, estop=False, reset=False,
        op="op", view_age_ms=120, rx_kbps=190, camera_age_ms=240,
    )  # fmt: skip
    assert decode_command(cmd.encode()) == cmd
    wire = msgpack.unpackb(cmd.encode())
    for key, value, reason in (
        ("rx_kbps", -1, RejectReason.OUT_OF_RANGE),
        ("rx_kbps", 1.5, RejectReason.WRONG_TYPE),
        ("camera_age_ms", 10**12, RejectReason.OUT_OF_RANGE),
    ):
        bad = decode_command(msgpack.packb({**wire, key: value}, use_bin_type=True))
        assert isinstance(bad, Rejection) and bad.reason is reason, (key, value, bad)
    older = {k: v for k, v in wire.items() if k not in ("rx_kbps", "camera_age_ms")}
    decoded = decode_command(msgpack.packb(older, use_bin_type=True))
    assert isinstance(decoded, OperatorCommand) and decoded.rx_kbps is None
