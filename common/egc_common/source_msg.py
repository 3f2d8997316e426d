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
    MAX_INT,
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
    # Every cycle a source drives decodes one (bench sources): a well-formed one in the usual
    # types takes one short check; any other payload the full decoder, which says why.
    fast = _fast(payload)
    if fast is not None:
        return fast
    return _decode(payload, MAX_COMMAND_BYTES, _build, flat=True)


def _fast(payload: object) -> SourceCommand | None:
    """The command, when ``payload`` is a valid one of plain types (the full decoder would give
    the very same); None to leave it to the full decoder."""
    if type(payload) is not bytes or len(payload) > MAX_COMMAND_BYTES:
        return None
    try:
        m = msgpack.unpackb(payload, raw=False, max_array_len=0, max_map_len=8)
        version, seq, stamp_ns, v, w = m["v"], m["seq"], m["stamp_ns"], m["v_mps"], m["w_radps"]
    except Exception:  # not msgpack, not a map, a key missing, a container: the full decoder
        return None
    if not (
        type(m) is dict
        and type(version) is int
        and version == SCHEMA_VERSION
        and type(seq) is int
        and 0 <= seq <= MAX_INT
        and type(stamp_ns) is int
        and 0 <= stamp_ns <= MAX_INT
        and type(v) is float
        and -MAX_SPEED_MPS <= v <= MAX_SPEED_MPS  # also false for NaN
        and type(w) is float
        and -MAX_TURN_RADPS <= w <= MAX_TURN_RADPS
        and not any(type(x) is dict for x in m.values())  # the full decoder refuses nesting
    ):
        return None
    return SourceCommand(seq, stamp_ns, v, w)


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
