"""What a robot says about itself on ``egc/<robot>/info`` (DESIGN 15).

A queryable on every robot answers with one msgpack map: which robot, its profile and
footprint, its driver, filter and camera, the software version, and (a snapshot at the time of
the query) its state and the operator in control, and the map frame it localises in (``map``:
robots that give the same id share a map frame, so an operator draws them on one map; absent
when the driver gives no map pose). ``egc-teleop robots`` lists these; an operator started
without ``--robot`` chooses among them.

The reply is decoded like every other message from the network (DESIGN 7): bounded size, a
flat shape, typed and ranged fields, and a counted ``Rejection`` instead of an exception.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Final

from egc_common.messages import (
    MAX_SMALL_BYTES,
    SCHEMA_VERSION,
    STATES,
    Rejection,
    RejectReason,
    _decode,
    _float,
    _get,
    _InvalidError,
    _opt_str,
    _pack,
    _Shape,
    _str,
)

MAX_FOOTPRINT_VERTICES: Final = 32
MAX_FOOTPRINT_M: Final = 100.0
# One map of a dozen scalars and one short array of coordinates (x0, y0, x1, y1, ...).
_INFO_SHAPE: Final = _Shape(keys=32, max_array=2 * MAX_FOOTPRINT_VERTICES, max_str=256)


@dataclass(frozen=True, slots=True)
class RobotInfo:
    """One robot's self-description. ``footprint_m`` is the polygon in base_link, (x, y) pairs
    in metres, counter-clockwise; ``operator`` is the operator id in control, or None."""

    robot: str
    state: str
    driver: str
    profile: str
    filter: str
    camera: str
    version: str
    footprint_m: tuple[tuple[float, float], ...] = ()
    operator: str | None = None
    map: str | None = None

    def encode(self) -> bytes:
        flat = [float(c) for point in self.footprint_m for c in point]
        extra = {} if self.map is None else {"map": self.map}
        return _pack(
            {
                **extra,
                "v": SCHEMA_VERSION,
                "robot": self.robot,
                "state": self.state,
                "driver": self.driver,
                "profile": self.profile,
                "filter": self.filter,
                "camera": self.camera,
                "version": self.version,
                "footprint": flat,
                "operator": self.operator,
            }
        )

    def as_json(self) -> dict[str, Any]:
        """The ``egc-teleop robots --json`` object (DESIGN 15, pinned keys first)."""
        return {
            "robot": self.robot,
            "state": self.state,
            "driver": self.driver,
            "profile": self.profile,
            "filter": self.filter,
            "camera": self.camera,
            "operator": self.operator,
            "version": self.version,
            "footprint": [list(p) for p in self.footprint_m],
            "map": self.map,
        }


def _footprint(m: Mapping[Any, Any]) -> tuple[tuple[float, float], ...]:
    if "footprint" not in m:
        return ()
    value = _get(m, "footprint")
    if not isinstance(value, list) or len(value) % 2:
        raise _InvalidError(RejectReason.WRONG_TYPE, "'footprint' must be a flat list of x, y")
    coords = [_float({"c": c}, "c", -MAX_FOOTPRINT_M, MAX_FOOTPRINT_M) for c in value]
    return tuple((coords[i], coords[i + 1]) for i in range(0, len(coords), 2))


def _build_info(m: Mapping[Any, Any]) -> RobotInfo:
    return RobotInfo(
        robot=_str(m, "robot"),
        state=_str(m, "state", STATES),
        driver=_str(m, "driver"),
        profile=_str(m, "profile", max_chars=256),
        filter=_str(m, "filter"),
        camera=_str(m, "camera", max_chars=256),
        version=_str(m, "version"),
        footprint_m=_footprint(m),
        operator=_opt_str(m, "operator"),
        map=_opt_str(m, "map", max_chars=256),
    )


def decode_info(payload: object) -> RobotInfo | Rejection:
    return _decode(payload, MAX_SMALL_BYTES, _build_info, shape=_INFO_SHAPE)
