"""``egc/<robot>/info`` replies (DESIGN 15): round trip, and bad replies refused, never raised."""

from __future__ import annotations

import msgpack
import pytest
from egc_common.messages import Rejection, RejectReason
from egc_common.robot_info import RobotInfo, decode_info

INFO = RobotInfo(
    robot="r1",
    state="DRIVING",
    driver="ros2",
    profile="jackal",
    filter="cbf",
    camera="ros2:/image",
    version="0.1.0",
    footprint_m=((0.25, 0.2), (-0.25, 0.2), (-0.25, -0.2), (0.25, -0.2)),
    operator="alice",
)


def test_round_trip_and_the_pinned_json_keys():
    assert decode_info(INFO.encode()) == INFO
    row = INFO.as_json()
    assert {"robot", "state", "driver", "profile", "filter", "camera", "operator"} <= set(row)
    assert row["operator"] == "alice" and row["footprint"][0] == [0.25, 0.2]


def _wire(**changes):
    m = msgpack.unpackb(INFO.encode(), raw=False)
    m.update(changes)
    return msgpack.packb({k: v for k, v in m.items() if v is not ...}, use_bin_type=True)


@pytest.mark.parametrize(
    ("changes", "reason"),
    [
        ({"state": "FLYING"}, RejectReason.OUT_OF_RANGE),
        ({"robot": 7}, RejectReason.WRONG_TYPE),
        ({"driver": ...}, RejectReason.MISSING_KEY),
        ({"footprint": [1.0, 2.0, 3.0]}, RejectReason.WRONG_TYPE),
        ({"footprint": [1.0, float("nan")]}, RejectReason.NOT_FINITE),
        ({"footprint": [1e9, 0.0]}, RejectReason.OUT_OF_RANGE),
        ({"footprint": [[1.0, 2.0]]}, RejectReason.WRONG_TYPE),
        ({"footprint": [0.0] * 1000}, RejectReason.TOO_LARGE),
        ({"v": 2}, RejectReason.UNKNOWN_VERSION),
        ({"operator": "x" * 100}, RejectReason.OUT_OF_RANGE),
    ],
)
def test_bad_replies_are_refused_with_a_reason(changes, reason):
    result = decode_info(_wire(**changes))
    assert isinstance(result, Rejection) and result.reason == reason, result


def test_garbage_and_huge_payloads_are_refused():
    assert isinstance(decode_info(b"\xc1\xff"), Rejection)
    assert decode_info(b"\x00" * 100_000).reason == RejectReason.TOO_LARGE
    assert decode_info(None).reason == RejectReason.WRONG_TYPE


def test_the_map_frame_id_is_optional_and_round_trips():
    """DESIGN 15: robots giving the same ``map`` id share a map frame (the fleet's map)."""
    from dataclasses import replace

    with_map = replace(INFO, map="grid:0123456789abcdef")
    assert decode_info(with_map.encode()) == with_map
    assert with_map.as_json()["map"] == "grid:0123456789abcdef"
    assert "map" not in msgpack.unpackb(INFO.encode(), raw=False)
    assert decode_info(INFO.encode()).map is None
