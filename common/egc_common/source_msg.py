"""Command sources and locks on Zenoh (DESIGN 14, pinned keys).

- ``egc/<robot>/source/<name>``: a velocity command from a source of kind ``zenoh`` (an autonomy
  stack), a msgpack map ``{"v": 1, "seq", "stamp_ns", "v_mps", "w_radps"}``: ``seq`` increasing
  per source session, ``stamp_ns`` the robot's monotonic clock as the source estimates it (0:
  not synchronised, as in an OperatorCommand), ``v_mps`` forward and ``w_radps``
  counter-clockwise in {R}. No eq. 4 mapping: the robot filters this velocity as it is.
- ``egc/<robot>/lock/<name>``: a lock's value, a msgpack bool (true: locked).

The decoders never raise (DESIGN 7): a rejection says why.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Final

import msgpack

from egc_common.messages import (
    MAX_COMMAND_BYTES,
    MAX_SPEED_MPS,
    MAX_TURN_RADPS,
    SCHEMA_VERSION,
    Rejection,
    RejectReason,
    _decode,
    _float,
    _int,
    _pack,
)

# A msgpack bool is one byte; a little slack for nothing else.
MAX_LOCK_BYTES: Final = 16


@dataclass(frozen=True, slots=True)
class SourceCommand:
    """One velocity command of a ``zenoh`` source (DESIGN 14)."""

    seq: int
    stamp_ns: int
    v_mps: float
    w_radps: float

    def encode(self) -> bytes:
        return _pack(
            {
                "v": SCHEMA_VERSION,
                "seq": self.seq,
                "stamp_ns": self.stamp_ns,
                "v_mps": float(self.v_mps),
                "w_radps": float(self.w_radps),
            }
        )


def _build(m: Mapping[Any, Any]) -> SourceCommand:
    return SourceCommand(
        seq=_int(m, "seq"),
        stamp_ns=_int(m, "stamp_ns"),
        v_mps=_float(m, "v_mps", -MAX_SPEED_MPS, MAX_SPEED_MPS),
        w_radps=_float(m, "w_radps", -MAX_TURN_RADPS, MAX_TURN_RADPS),
    )


def decode_source_command(payload: object) -> SourceCommand | Rejection:
    return _decode(payload, MAX_COMMAND_BYTES, _build, flat=True)


def encode_lock(locked: bool) -> bytes:
    data: bytes = msgpack.packb(bool(locked))
    return data


def decode_lock(payload: object) -> bool | Rejection:
    """A lock's value: exactly a msgpack bool."""
    if isinstance(payload, memoryview):
        payload = payload.tobytes()
    if not isinstance(payload, (bytes, bytearray)):
        return Rejection(RejectReason.WRONG_TYPE, "payload must be bytes")
    if len(payload) > MAX_LOCK_BYTES:
        return Rejection(RejectReason.TOO_LARGE, f"{len(payload)} bytes > limit {MAX_LOCK_BYTES}")
    try:
        value = msgpack.unpackb(bytes(payload))
    except Exception as exc:  # msgpack raises many types
        return Rejection(RejectReason.NOT_MSGPACK, f"not msgpack: {type(exc).__name__}")
    if not isinstance(value, bool):
        return Rejection(
            RejectReason.WRONG_TYPE, f"a lock is a msgpack bool, got {type(value).__name__}"
        )
    return value
