"""Wire contract (DESIGN 7, pinned): msgpack maps with strict, non-raising decoders.

Every ``decode_*`` function returns either the message (a frozen dataclass) or a ``Rejection``
with a typed ``RejectReason``; nothing that arrives from the network can make them raise.
Unknown keys are ignored (forward compatibility within schema version 1); missing keys, wrong
types, non-finite floats, out-of-range values, unknown versions and oversized payloads are
rejected.
"""

from __future__ import annotations

import enum
import math
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Final, TypeVar

import msgpack
import numpy as np
import numpy.typing as npt

from egc_common.scan_compact import PolarScan

SCHEMA_VERSION: Final = 1
MAX_COMMAND_BYTES: Final = 512
MAX_TELEMETRY_BYTES: Final = 4 * 1024 * 1024
MAX_SCAN_BYTES: Final = 4 * 1024 * 1024
MAX_SMALL_BYTES: Final = 4096
MAX_INT: Final = 2**63 - 1
MAX_ID_CHARS: Final = 64
MAX_SCAN_BEAMS: Final = 200_000
MAX_MAP_CELLS: Final = 64_000_000
MAX_MAP_BYTES: Final = MAX_MAP_CELLS // 8 + 4096
MAX_VIEW_AGE_MS: Final = 3_600_000
MAX_KBPS: Final = 10_000_000  # 10 Gbit/s: rx_kbps, and the budget's figures in telemetry
MAX_TELEMETRY_HZ: Final = 1000.0
MAX_CAMERA_FPS: Final = 1000.0
# What the downlink budget cut (DESIGN 12), in the order it gives way; telemetry ``cut``.
BUDGET_CUTS: Final = ("camera", "scan", "rate")
# Telemetry figures (DESIGN 7, 9), each in a physically sensible range; a message with one
# outside it is rejected whole (OUT_OF_RANGE), as one with a NaN is. Generous: the robot's own
# figures never come near them (its speeds are within the base's +-100, see BaseCommand).
MAX_SPEED_MPS: Final = 100.0  # v_ref, v_cmd, v_lim_latency (the latter >= 0)
MAX_TURN_RADPS: Final = 100.0  # w_ref, w_cmd, w_lim_latency (the latter >= 0)
MAX_POSE_COORD_M: Final = 1e7  # the odometry pose's x and y (as a map's origin)
MAX_LOCAL_COORD_M: Final = 1e6  # circles in {R} (x, y and radius >= 0), r_rc >= 0
MAX_CBF_POINTS: Final = 64  # points shown as constraining the command (cbf, DESIGN 13)
MAX_ANGLE_RAD: Final = 1e6  # pose theta (odometry may not wrap it), suggested_rad
# Link figures: delays (tau, the accepted commands' age p50/p90, the largest command gap) are
# >= 0 and at most a day (the robot's own are bounded by its timeouts, view_age_ms by
# MAX_VIEW_AGE_MS). cmd_age_ms and scan_age_ms count since the newest command or scan, which may
# be long ago (a sensor that died): bounded by the range of the robot's nanosecond clock; a
# command may be stamped ahead by up to max_command_age (the robot accepts it), so cmd_age_ms
# may be negative by a delay. A scan or command that another thread of the robot takes in just
# after a cycle read its clock makes scan_age_ms (seen: -0.73 ms from a real robot) or
# cmd_gap_max_ms slightly negative: down to -MAX_RACE_MS is accepted.
MAX_DELAY_MS: Final = 86_400_000.0
MAX_CLOCK_MS: Final = MAX_INT / 1e6
MAX_RACE_MS: Final = 1000.0

MODES: Final = ("direct", "shared")
# The filter family of DESIGN 6, pinned names ("none" is direct mode).
FILTER_NAMES: Final = ("none", "egc", "ek-egc", "assist", "dwa", "cbf")
GOAL_FRAMES: Final = ("odom", "map")
MAX_GOAL_POINTS: Final = 64
MAX_GOAL_COORD_M: Final = 1e6
# Telemetry keys pinned by DESIGN 7 (outside tools read them); the rest are view extras.
TELEMETRY_PINNED_KEYS: Final = (
    "v",
    "seq",
    "stamp_ns",
    "state",
    "v_ref",
    "w_ref",
    "v_cmd",
    "w_cmd",
    "w_si",
    "mode",
)
STATES: Final = ("IDLE", "DRIVING", "HOLD", "ESTOP")


class RejectReason(enum.Enum):
    """Why a message was dropped; the robot counts and logs each one by reason."""

    TOO_LARGE = "too_large"
    NOT_MSGPACK = "not_msgpack"
    NOT_A_MAP = "not_a_map"
    UNKNOWN_VERSION = "unknown_version"
    MISSING_KEY = "missing_key"
    WRONG_TYPE = "wrong_type"
    NOT_FINITE = "not_finite"
    OUT_OF_RANGE = "out_of_range"
    # Reasons the robot adds after decoding (DESIGN 8):
    STALE = "stale"
    DUPLICATE_SEQ = "duplicate_seq"
    OUT_OF_ORDER = "out_of_order"
    NOT_IN_CONTROL = "not_in_control"
    NO_INFORMATION = "no_information"  # a scan with no valid, +inf or -inf beam (REP 117)
    # Camera frames (DESIGN 12, ``egc_common.camera_msg``; the operator's camera view):
    UNKNOWN_CODEC = "unknown_codec"
    CORRUPT = "corrupt"  # the picture does not decode (a cut H.264 frame, a broken JPEG)
    FUTURE = "future"  # stamped after the robot's clock now, beyond the clock sync's error


@dataclass(frozen=True, slots=True)
class Rejection:
    reason: RejectReason
    detail: str

    def __str__(self) -> str:
        return f"{self.reason.value}: {self.detail}"


class _InvalidError(Exception):
    def __init__(self, reason: RejectReason, detail: str) -> None:
        super().__init__(detail)
        self.rejection = Rejection(reason, detail)


# ---------------------------------------------------------------------------------------------
# Field readers: each raises _InvalidError, which the decoders turn into a Rejection.


def _get(m: Mapping[Any, Any], key: str) -> Any:
    if key not in m:
        raise _InvalidError(RejectReason.MISSING_KEY, f"missing key {key!r}")
    return m[key]


def _int(m: Mapping[Any, Any], key: str, lo: int = 0, hi: int = MAX_INT) -> int:
    value = _get(m, key)
    if isinstance(value, bool) or not isinstance(value, int):
        raise _InvalidError(RejectReason.WRONG_TYPE, f"{key!r} must be an integer")
    if not lo <= value <= hi:
        raise _InvalidError(RejectReason.OUT_OF_RANGE, f"{key!r}={value} outside [{lo}, {hi}]")
    return value


def _float(m: Mapping[Any, Any], key: str, lo: float = -math.inf, hi: float = math.inf) -> float:
    value = _get(m, key)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise _InvalidError(RejectReason.WRONG_TYPE, f"{key!r} must be a number")
    try:
        x = float(value)
    except OverflowError:
        raise _InvalidError(RejectReason.OUT_OF_RANGE, f"{key!r} is too large") from None
    if not math.isfinite(x):
        raise _InvalidError(RejectReason.NOT_FINITE, f"{key!r} must be finite")
    if not lo <= x <= hi:
        raise _InvalidError(RejectReason.OUT_OF_RANGE, f"{key!r}={x} outside [{lo}, {hi}]")
    return x


def _opt_float(m: Mapping[Any, Any], key: str) -> float | None:
    return None if m.get(key) is None else _float(m, key)


def _bool(m: Mapping[Any, Any], key: str) -> bool:
    value = _get(m, key)
    if not isinstance(value, bool):
        raise _InvalidError(RejectReason.WRONG_TYPE, f"{key!r} must be a boolean")
    return value


def _str(
    m: Mapping[Any, Any],
    key: str,
    choices: tuple[str, ...] | None = None,
    max_chars: int = MAX_ID_CHARS,
) -> str:
    value = _get(m, key)
    if not isinstance(value, str):
        raise _InvalidError(RejectReason.WRONG_TYPE, f"{key!r} must be a string")
    if choices is not None and value not in choices:
        raise _InvalidError(
            RejectReason.OUT_OF_RANGE, f"{key!r} must be one of {', '.join(choices)}"
        )
    if not 0 < len(value) <= max_chars or not value.isprintable():
        raise _InvalidError(
            RejectReason.OUT_OF_RANGE, f"{key!r} must be 1-{max_chars} printable chars"
        )
    return value


def _f32_array(
    m: Mapping[Any, Any],
    key: str,
    width: int = 1,
    max_items: int = MAX_SCAN_BEAMS,
    allow_nonfinite: bool = False,
) -> npt.NDArray[np.float32]:
    value = _get(m, key)
    if not isinstance(value, (bytes, bytearray)):
        raise _InvalidError(RejectReason.WRONG_TYPE, f"{key!r} must be bytes of float32")
    if len(value) % (4 * width):
        raise _InvalidError(
            RejectReason.OUT_OF_RANGE, f"{key!r} length is not a multiple of {4 * width}"
        )
    arr = np.frombuffer(bytes(value), dtype="<f4")
    if arr.size // width > max_items:
        raise _InvalidError(RejectReason.TOO_LARGE, f"{key!r} has more than {max_items} items")
    if not allow_nonfinite and not np.all(np.isfinite(arr)):
        raise _InvalidError(RejectReason.NOT_FINITE, f"{key!r} holds non-finite values")
    return arr.reshape(-1, width) if width > 1 else arr


class _NotFlatError(Exception):
    """A map inside a message that has none (``_unpack(flat=True)``), or a container inside
    an array (``_Shape``)."""


def _flat_map_hook() -> Callable[[dict[Any, Any]], dict[Any, Any]]:
    """An ``object_hook`` that lets one map through, the message's own (the outermost map is
    the last one msgpack finishes), and stops the unpacker at any map inside it."""
    seen = [False]

    def hook(obj: dict[Any, Any]) -> dict[Any, Any]:
        if seen[0]:
            raise _NotFlatError
        seen[0] = True
        return obj

    return hook


@dataclass(frozen=True, slots=True)
class _Shape:
    """What a message received by the operator may hold (telemetry, state, clock reply, map):
    one map of at most ``keys`` entries whose values are scalars, strings of at most
    ``max_str`` bytes, bytes of at most ``max_bin``, or arrays of at most ``max_array``
    scalars. Nothing else nests: no map inside the message, no container inside an array.

    msgpack checks each length at the container's header and the hooks refuse a nested
    container as soon as the first one is complete, so a payload of millions of tiny containers
    (an outside check: 4 MB of empty maps took 0.24 s and 258 MB in the operator's receive
    path, empty arrays 1.2 s, and starved its command loop) is refused after its first few
    bytes. Unknown keys (DESIGN 7) are still ignored, within this shape.
    """

    keys: int = 128
    max_array: int = 64
    max_str: int = 1024
    max_bin: int = 4096

    def unpack_options(self) -> dict[str, Any]:
        def list_hook(items: list[Any]) -> list[Any]:
            for item in items:
                if isinstance(item, (list, dict)):
                    raise _NotFlatError
            return items

        return {
            "max_map_len": self.keys,
            "max_array_len": self.max_array,
            "max_str_len": self.max_str,
            "max_bin_len": self.max_bin,
            "max_ext_len": 16,  # none of these messages has one; a timestamp's is 4-12 bytes
            "object_hook": _flat_map_hook(),
            "list_hook": list_hook,
        }


_LIMIT_EXCEEDED = re.compile(r"(\d+) exceeds max_(\w+)_len\((\d+)\)")


def _unpack(
    payload: object, max_bytes: int, flat: bool = False, shape: _Shape | None = None
) -> Mapping[Any, Any]:
    """``flat``: the message is one map of scalars and bytes (a scan): any array or inner map
    is refused as soon as its header is read, so a payload of millions of tiny containers
    (seconds of unpacking, in the receive path) costs no more than its first few bytes.
    ``shape``: the same for a message that holds short arrays of scalars (see ``_Shape``)."""
    if isinstance(payload, memoryview):
        payload = payload.tobytes()
    if not isinstance(payload, (bytes, bytearray)):
        raise _InvalidError(RejectReason.WRONG_TYPE, "payload must be bytes")
    if len(payload) > max_bytes:
        raise _InvalidError(RejectReason.TOO_LARGE, f"{len(payload)} bytes > limit {max_bytes}")
    limits: dict[str, Any] = {}
    if flat:
        limits = {"max_array_len": 0, "max_map_len": 64, "object_hook": _flat_map_hook()}
    elif shape is not None:
        limits = shape.unpack_options()
    try:
        obj = msgpack.unpackb(
            bytes(payload), raw=False, strict_map_key=False, timestamp=0, **limits
        )
    except _NotFlatError:
        what = "a map inside the message" if flat else "a container nested in the message"
        raise _InvalidError(RejectReason.WRONG_TYPE, what) from None
    except Exception as exc:  # msgpack raises many types (ExtraData, ValueError, ...)
        exceeded = None if shape is None else _LIMIT_EXCEEDED.search(str(exc))
        if exceeded is not None:
            length, kind, limit = exceeded.groups()
            unit = "bytes" if kind in ("str", "bin", "ext") else "items"
            raise _InvalidError(
                RejectReason.TOO_LARGE, f"{kind} of {length} {unit} > limit {limit}"
            ) from None
        raise _InvalidError(
            RejectReason.NOT_MSGPACK, f"not msgpack: {type(exc).__name__}"
        ) from None
    if not isinstance(obj, dict):
        raise _InvalidError(RejectReason.NOT_A_MAP, f"payload is a {type(obj).__name__}, not a map")
    version = obj.get("v")
    if isinstance(version, bool) or not isinstance(version, int):
        raise _InvalidError(
            RejectReason.MISSING_KEY if version is None else RejectReason.WRONG_TYPE,
            "schema version 'v' must be an integer",
        )
    if version != SCHEMA_VERSION:
        raise _InvalidError(RejectReason.UNKNOWN_VERSION, f"schema version {version} not supported")
    return obj


T = TypeVar("T")


def _decode(
    payload: object,
    max_bytes: int,
    build: Callable[[Mapping[Any, Any]], T],
    flat: bool = False,
    shape: _Shape | None = None,
) -> T | Rejection:
    try:
        return build(_unpack(payload, max_bytes, flat, shape))
    except _InvalidError as exc:
        return exc.rejection
    except RecursionError:
        return Rejection(RejectReason.NOT_MSGPACK, "nesting too deep")


def _shallow_fields(message: Any) -> dict[str, Any]:
    """A slotted dataclass's fields as a dict, without ``asdict``'s deep copy (a scan array per
    cycle) or ``dataclasses.fields``' per-call cost."""
    return {name: getattr(message, name) for name in message.__slots__}


def _pack(obj: Mapping[str, Any]) -> bytes:
    data: bytes = msgpack.packb(obj, use_bin_type=True)
    return data


# ---------------------------------------------------------------------------------------------
# OperatorCommand


@dataclass(frozen=True, slots=True)
class OperatorCommand:
    """One joystick sample from an operator (DESIGN 7). x forward, y left, both in [-1, 1]."""

    seq: int
    stamp_ns: int
    x: float
    y: float
    mode: str
    deadman: bool
    estop: bool
    reset: bool
    op: str
    view_age_ms: int | None = None  # DESIGN 7, 9: age of the newest telemetry the view showed
    # The filter the operator picked for shared mode (DESIGN 6); absent: the robot's default.
    filter: str | None = None
    # DESIGN 12: view-plane kbit/s received over the last second, and the robot-clock age of
    # the newest camera frame shown; absent when unknown (no camera: no camera_age_ms).
    rx_kbps: int | None = None
    camera_age_ms: int | None = None

    def __post_init__(self) -> None:
        rejection = decode_command(_pack(self._wire()))
        if isinstance(rejection, Rejection):
            raise ValueError(f"invalid OperatorCommand: {rejection}")

    def _wire(self) -> dict[str, Any]:
        wire = {"v": SCHEMA_VERSION, **{k: getattr(self, k) for k in self.__slots__}}
        for optional in ("view_age_ms", "filter", "rx_kbps", "camera_age_ms"):
            if wire[optional] is None:
                del wire[optional]  # optional keys: absent when unknown (DESIGN 7)
        return wire

    def encode(self) -> bytes:
        return _pack(self._wire())


def _build_command(m: Mapping[Any, Any]) -> OperatorCommand:
    fields_ = {
        "seq": _int(m, "seq"),
        "stamp_ns": _int(m, "stamp_ns"),
        "x": _float(m, "x", -1.0, 1.0),
        "y": _float(m, "y", -1.0, 1.0),
        "mode": _str(m, "mode", MODES),
        "deadman": _bool(m, "deadman"),
        "estop": _bool(m, "estop"),
        "reset": _bool(m, "reset"),
        "op": _str(m, "op"),
        "view_age_ms": (
            None if m.get("view_age_ms") is None else _int(m, "view_age_ms", 0, MAX_VIEW_AGE_MS)
        ),
        "filter": _opt_str(m, "filter", FILTER_NAMES),
        "rx_kbps": None if m.get("rx_kbps") is None else _int(m, "rx_kbps", 0, MAX_KBPS),
        "camera_age_ms": (
            None if m.get("camera_age_ms") is None else _int(m, "camera_age_ms", 0, MAX_VIEW_AGE_MS)
        ),
    }
    cmd = object.__new__(OperatorCommand)
    for key, value in fields_.items():
        object.__setattr__(cmd, key, value)
    return cmd


def decode_command(payload: object) -> OperatorCommand | Rejection:
    # The robot decodes every command on its command path, before the base command can go out
    # (bench link): a well-formed command in the usual types takes one short check here; any
    # other payload takes the full field-by-field decoder below, which gives the same command
    # for an acceptable one and says why for a rejected one.
    cmd = _fast_command(payload)
    if cmd is not None:
        return cmd
    return _decode(payload, MAX_COMMAND_BYTES, _build_command)


_unpackb = msgpack.unpackb
# OperatorCommand's slots in field order, stored through their descriptors (frozen class).
_COMMAND_SETTERS: Final = tuple(
    OperatorCommand.__dict__[name].__set__ for name in OperatorCommand.__slots__
)


def _fast_command(payload: object) -> OperatorCommand | None:
    """The command, when ``payload`` is a valid one whose every field has its plain type (the
    full decoder would return the very same values); None to leave it to the full decoder."""
    if type(payload) is not bytes or len(payload) > MAX_COMMAND_BYTES:
        return None
    try:
        m = _unpackb(payload, raw=False, strict_map_key=False, timestamp=0)
        version, seq, stamp_ns, x, y = m["v"], m["seq"], m["stamp_ns"], m["x"], m["y"]
        mode, deadman, estop, reset, op = m["mode"], m["deadman"], m["estop"], m["reset"], m["op"]
    except Exception:  # not msgpack, not a map, a key missing: the full decoder says which
        return None
    view_age_ms = m.get("view_age_ms")
    filter_ = m.get("filter")
    rx_kbps = m.get("rx_kbps")
    camera_age_ms = m.get("camera_age_ms")
    if not (
        type(m) is dict
        and type(version) is int
        and version == SCHEMA_VERSION
        and type(seq) is int
        and 0 <= seq <= MAX_INT
        and type(stamp_ns) is int
        and 0 <= stamp_ns <= MAX_INT
        and type(x) is float
        and -1.0 <= x <= 1.0  # also false for NaN
        and type(y) is float
        and -1.0 <= y <= 1.0
        and (mode == "shared" or mode == "direct")
        and type(mode) is str
        and type(deadman) is bool
        and type(estop) is bool
        and type(reset) is bool
        and type(op) is str
        and 0 < len(op) <= MAX_ID_CHARS
        and op.isprintable()
        and (
            view_age_ms is None
            or (type(view_age_ms) is int and 0 <= view_age_ms <= MAX_VIEW_AGE_MS)
        )
        and (filter_ is None or (type(filter_) is str and filter_ in FILTER_NAMES))
        and (rx_kbps is None or (type(rx_kbps) is int and 0 <= rx_kbps <= MAX_KBPS))
        and (
            camera_age_ms is None
            or (type(camera_age_ms) is int and 0 <= camera_age_ms <= MAX_VIEW_AGE_MS)
        )
    ):
        return None
    cmd = object.__new__(OperatorCommand)  # no __post_init__: it is checked already
    for set_field, value in zip(
        _COMMAND_SETTERS,
        (
            seq,
            stamp_ns,
            x,
            y,
            mode,
            deadman,
            estop,
            reset,
            op,
            view_age_ms,
            filter_,
            rx_kbps,
            camera_age_ms,
        ),
        strict=True,
    ):
        set_field(cmd, value)
    return cmd


# ---------------------------------------------------------------------------------------------
# Telemetry (robot -> operators, at telemetry_hz: DESIGN 12)

Circle = tuple[float, float, float]


@dataclass(frozen=True, slots=True, eq=False)
class Telemetry:
    """One control cycle as the operator view needs it (DESIGN 7 keys plus view extras).

    ``scan_xy`` holds the (possibly decimated) scan points in {R}; circles are (x, y, r) in {R}.
    With ``scan_polar`` (DESIGN 12's compact scan) ``scan_xy`` is its points first, in beam
    order, then the points that are no beam's (REP 117 -inf readings); only those extra points
    go out as float32 pairs, the beams as ``scan_mm`` (uint16 millimetres) with ``scan_a0``,
    ``scan_da`` and ``scan_origin`` given once. A decoder rebuilds the same ``scan_xy``.
    """

    seq: int
    stamp_ns: int
    state: str
    mode: str
    v_ref: float
    w_ref: float
    v_cmd: float
    w_cmd: float
    w_si: float
    region: str = "safe"
    side: str | None = None
    limiter: str = "none"
    igc: Circle | None = None
    agc: Circle | None = None
    egc: Circle | None = None
    r_rc: float = 0.0
    scan_xy: npt.NDArray[np.float32] = field(default_factory=lambda: np.zeros((0, 2), np.float32))
    pose: tuple[float, float, float] | None = None
    cmd_age_ms: float | None = None
    scan_age_ms: float | None = None
    operator: str | None = None
    profile: str = ""
    rejected: int = 0
    cycle: int = 0
    # Link-aware driving (DESIGN 7, 9); None when not known yet.
    reason: str | None = None  # why the robot is in its state (HOLD: why it holds)
    filter: str = ""  # which filter of DESIGN 6 runs in shared mode
    loop_delay_ms: float | None = None  # tau
    cmd_age_p50_ms: float | None = None
    cmd_age_p90_ms: float | None = None
    cmd_gap_max_ms: float | None = None
    link_loss: float | None = None  # fraction of seq missing over the last second
    view_age_ms: float | None = None  # the controlling operator's latest report
    v_lim_latency: float | None = None  # the latency governor's cap, m/s
    w_lim_latency: float | None = None  # its cap on the turn rate, rad/s, when below w_max
    # Via points (DESIGN 7 goal): the active one in its frame, how many remain after it, and
    # the direction the filter suggests in {R} (rad; assist), for the view.
    goal: tuple[float, float] | None = None
    goal_frame: str | None = None
    goals_left: int = 0
    suggested_rad: float | None = None
    scan_polar: PolarScan | None = None  # DESIGN 12's compact scan (see the class docstring)
    # The downlink budget (DESIGN 12, ``egc_common.view_budget``): what the view plane sent over
    # the last second, the budget, what the link is estimated to carry (None: not known), the
    # plan (telemetry rate, scan beams, camera rate and kbit/s) and what gave way.
    view_kbps: float | None = None
    budget_kbps: float | None = None
    link_kbps: float | None = None
    tel_hz: float | None = None
    scan_n: int | None = None
    cam_fps: float | None = None
    cam_kbps: float | None = None
    cut: tuple[str, ...] = ()
    # Command sources (DESIGN 14; absent without [[source]] tables): the source that drives and
    # the highest active lock (None: none), and the age on the robot's clock of the newest
    # command of the source that drives, since it arrived.
    source: str | None = None
    lock: str | None = None
    source_age_ms: float | None = None
    # cbf (DESIGN 13), for the view: the points whose barriers changed the command (float32
    # (K, 2) in {R}, at most MAX_CBF_POINTS), the margin kept from everything and the margin
    # straight ahead at the current speed (m); the margins are absent unless cbf ran.
    cbf_xy: npt.NDArray[np.float32] = field(default_factory=lambda: np.zeros((0, 2), np.float32))
    cbf_margin_m: float | None = None
    cbf_ahead_m: float | None = None

    def encode(self) -> bytes:
        d = _shallow_fields(self)
        polar = d.pop("scan_polar")
        xy = np.ascontiguousarray(self.scan_xy, dtype="<f4")
        if polar is not None:
            d["scan_mm"] = np.ascontiguousarray(polar.ranges_mm, dtype="<u2").tobytes()
            d["scan_a0"] = polar.angle_min_rad
            d["scan_da"] = polar.angle_increment_rad
            if polar.origin_xy_m != (0.0, 0.0):
                d["scan_origin"] = [float(v) for v in polar.origin_xy_m]
            xy = xy[polar.shown :]  # the beams' points travel as scan_mm
        d["scan_xy"] = xy.tobytes()
        cbf_xy = np.ascontiguousarray(self.cbf_xy, dtype="<f4")
        d["cbf_xy"] = cbf_xy.tobytes() if len(cbf_xy) else None
        for key in ("igc", "agc", "egc", "pose", "goal"):
            if d[key] is not None:
                d[key] = [float(v) for v in d[key]]
        d["cut"] = ",".join(self.cut) if self.cut else None
        for key in _TELEMETRY_OPTIONAL:
            if d[key] is None:
                del d[key]  # absent when unknown: smaller, and what older robots sent
        return _pack({"v": SCHEMA_VERSION, **d})


# Optional telemetry keys left out when None (DESIGN 12: bytes count on a thin link).
_TELEMETRY_OPTIONAL: Final = (
    "cbf_xy",
    "cbf_margin_m",
    "cbf_ahead_m",
    "view_kbps",
    "budget_kbps",
    "link_kbps",
    "tel_hz",
    "scan_n",
    "cam_fps",
    "cam_kbps",
    "cut",
    "source",
    "lock",
    "source_age_ms",
)


REGIONS: Final = ("safe", "conditional", "unsafe")
SIDES: Final = ("left", "right")


def _opt_tuple(
    m: Mapping[Any, Any],
    key: str,
    n: int,
    bounds: tuple[tuple[float, float], ...] | None = None,
) -> tuple[float, ...] | None:
    """An optional list of ``n`` numbers; ``bounds``: each one's (lo, hi), in order."""
    value = m.get(key)
    if value is None:
        return None
    if not isinstance(value, list) or len(value) != n:
        raise _InvalidError(RejectReason.WRONG_TYPE, f"{key!r} must be a list of {n} numbers")
    if bounds is None:
        return tuple(_float({key: v}, key) for v in value)
    return tuple(
        _float({f"{key}[{i}]": v}, f"{key}[{i}]", lo, hi)
        for i, (v, (lo, hi)) in enumerate(zip(value, bounds, strict=True))
    )


def _opt_range(m: Mapping[Any, Any], key: str, lo: float, hi: float) -> float | None:
    return None if m.get(key) is None else _float(m, key, lo, hi)


def _opt_str(
    m: Mapping[Any, Any],
    key: str,
    choices: tuple[str, ...] | None = None,
    max_chars: int = MAX_ID_CHARS,
) -> str | None:
    return None if m.get(key) is None else _str(m, key, choices, max_chars)


_CIRCLE: Final = (
    (-MAX_LOCAL_COORD_M, MAX_LOCAL_COORD_M),
    (-MAX_LOCAL_COORD_M, MAX_LOCAL_COORD_M),
    (0.0, MAX_LOCAL_COORD_M),
)
_POSE: Final = (
    (-MAX_POSE_COORD_M, MAX_POSE_COORD_M),
    (-MAX_POSE_COORD_M, MAX_POSE_COORD_M),
    (-MAX_ANGLE_RAD, MAX_ANGLE_RAD),
)
_GOAL: Final = ((-MAX_GOAL_COORD_M, MAX_GOAL_COORD_M), (-MAX_GOAL_COORD_M, MAX_GOAL_COORD_M))
# The telemetry's shape: ~40 keys, arrays of 2-3 numbers, the scan's points as bytes.
_TELEMETRY_SHAPE: Final = _Shape(max_bin=MAX_SCAN_BEAMS * 8)


_TWO_PI: Final = 2.0 * math.pi


def _polar_scan(m: Mapping[Any, Any]) -> PolarScan | None:
    """DESIGN 12's compact scan: ``scan_mm`` (uint16 LE millimetres, beam order), ``scan_a0`` and
    ``scan_da`` (rad, each within one turn), ``scan_origin`` ([x, y] m in {R}, default 0, 0)."""
    if "scan_mm" not in m:
        return None
    raw = _get(m, "scan_mm")
    if not isinstance(raw, (bytes, bytearray)):
        raise _InvalidError(RejectReason.WRONG_TYPE, "'scan_mm' must be bytes of uint16")
    if len(raw) % 2:
        raise _InvalidError(RejectReason.OUT_OF_RANGE, "'scan_mm' length is not a multiple of 2")
    if len(raw) // 2 > MAX_SCAN_BEAMS:
        raise _InvalidError(RejectReason.TOO_LARGE, f"'scan_mm' has more than {MAX_SCAN_BEAMS}")
    origin = _opt_tuple(m, "scan_origin", 2, _CIRCLE[:2])
    return PolarScan(
        ranges_mm=np.frombuffer(bytes(raw), dtype="<u2").astype(np.uint16),
        angle_min_rad=_float(m, "scan_a0", -_TWO_PI, _TWO_PI),
        angle_increment_rad=_float(m, "scan_da", -_TWO_PI, _TWO_PI),
        origin_xy_m=(0.0, 0.0) if origin is None else (origin[0], origin[1]),
    )


def _cuts(m: Mapping[Any, Any]) -> tuple[str, ...]:
    text = _opt_str(m, "cut")
    if text is None:
        return ()
    cuts = tuple(text.split(","))
    if any(c not in BUDGET_CUTS for c in cuts) or len(set(cuts)) != len(cuts):
        raise _InvalidError(
            RejectReason.OUT_OF_RANGE, f"'cut' must list some of {', '.join(BUDGET_CUTS)}"
        )
    return cuts


def _build_telemetry(m: Mapping[Any, Any]) -> Telemetry:
    t = object.__new__(Telemetry)
    v, w = MAX_SPEED_MPS, MAX_TURN_RADPS
    polar = _polar_scan(m)
    extra = _f32_array(m, "scan_xy", 2) if "scan_xy" in m else np.zeros((0, 2), np.float32)
    scan_xy = extra if polar is None else np.concatenate((polar.points(), extra))
    if len(scan_xy) > MAX_SCAN_BEAMS:
        raise _InvalidError(RejectReason.TOO_LARGE, f"more than {MAX_SCAN_BEAMS} scan points")
    values: dict[str, Any] = {
        "seq": _int(m, "seq"),
        "stamp_ns": _int(m, "stamp_ns"),
        "state": _str(m, "state", STATES),
        "mode": _str(m, "mode", MODES),
        "v_ref": _float(m, "v_ref", -v, v),
        "w_ref": _float(m, "w_ref", -w, w),
        "v_cmd": _float(m, "v_cmd", -v, v),
        "w_cmd": _float(m, "w_cmd", -w, w),
        "w_si": _float(m, "w_si", 0.0, 1.0),
        "region": _str(m, "region", REGIONS) if "region" in m else "safe",
        "side": _opt_str(m, "side", SIDES),
        "limiter": _str(m, "limiter") if "limiter" in m else "none",
        "igc": _opt_tuple(m, "igc", 3, _CIRCLE),
        "agc": _opt_tuple(m, "agc", 3, _CIRCLE),
        "egc": _opt_tuple(m, "egc", 3, _CIRCLE),
        "r_rc": _float(m, "r_rc", 0.0, MAX_LOCAL_COORD_M) if "r_rc" in m else 0.0,
        "scan_xy": scan_xy,
        "pose": _opt_tuple(m, "pose", 3, _POSE),
        "cmd_age_ms": _opt_range(m, "cmd_age_ms", -MAX_DELAY_MS, MAX_CLOCK_MS),
        "scan_age_ms": _opt_range(m, "scan_age_ms", -MAX_RACE_MS, MAX_CLOCK_MS),
        "operator": _opt_str(m, "operator"),
        "profile": _str(m, "profile") if m.get("profile") else "",
        "rejected": _int(m, "rejected") if "rejected" in m else 0,
        "cycle": _int(m, "cycle") if "cycle" in m else 0,
        "reason": _opt_str(m, "reason", max_chars=256),
        "filter": _str(m, "filter") if m.get("filter") else "",
        "loop_delay_ms": _opt_range(m, "loop_delay_ms", 0.0, MAX_DELAY_MS),
        "cmd_age_p50_ms": _opt_range(m, "cmd_age_p50_ms", 0.0, MAX_DELAY_MS),
        "cmd_age_p90_ms": _opt_range(m, "cmd_age_p90_ms", 0.0, MAX_DELAY_MS),
        "cmd_gap_max_ms": _opt_range(m, "cmd_gap_max_ms", -MAX_RACE_MS, MAX_DELAY_MS),
        "link_loss": _opt_range(m, "link_loss", 0.0, 1.0),
        "view_age_ms": _opt_range(m, "view_age_ms", 0.0, MAX_VIEW_AGE_MS),
        "v_lim_latency": _opt_range(m, "v_lim_latency", 0.0, v),
        "w_lim_latency": _opt_range(m, "w_lim_latency", 0.0, w),
        "goal": _opt_tuple(m, "goal", 2, _GOAL),
        "goal_frame": _opt_str(m, "goal_frame", GOAL_FRAMES),
        "goals_left": _int(m, "goals_left", 0, MAX_GOAL_POINTS) if "goals_left" in m else 0,
        "suggested_rad": _opt_range(m, "suggested_rad", -MAX_ANGLE_RAD, MAX_ANGLE_RAD),
        "scan_polar": polar,
        "view_kbps": _opt_range(m, "view_kbps", 0.0, MAX_KBPS),
        "budget_kbps": _opt_range(m, "budget_kbps", 0.0, MAX_KBPS),
        "link_kbps": _opt_range(m, "link_kbps", 0.0, MAX_KBPS),
        "tel_hz": _opt_range(m, "tel_hz", 0.0, MAX_TELEMETRY_HZ),
        "scan_n": None if m.get("scan_n") is None else _int(m, "scan_n", 0, MAX_SCAN_BEAMS),
        "cam_fps": _opt_range(m, "cam_fps", 0.0, MAX_CAMERA_FPS),
        "cam_kbps": _opt_range(m, "cam_kbps", 0.0, MAX_KBPS),
        "cut": _cuts(m),
        "source": _opt_str(m, "source"),
        "lock": _opt_str(m, "lock"),
        "source_age_ms": _opt_range(m, "source_age_ms", -MAX_RACE_MS, MAX_CLOCK_MS),
        "cbf_xy": _f32_array(m, "cbf_xy", 2, MAX_CBF_POINTS)
        if "cbf_xy" in m
        else np.zeros((0, 2), np.float32),
        "cbf_margin_m": _opt_range(m, "cbf_margin_m", 0.0, MAX_LOCAL_COORD_M),
        "cbf_ahead_m": _opt_range(m, "cbf_ahead_m", 0.0, MAX_LOCAL_COORD_M),
    }
    for key, value in values.items():
        object.__setattr__(t, key, value)
    return t


def decode_telemetry(payload: object) -> Telemetry | Rejection:
    return _decode(payload, MAX_TELEMETRY_BYTES, _build_telemetry, shape=_TELEMETRY_SHAPE)


# ---------------------------------------------------------------------------------------------
# Via points (operator -> robot, DESIGN 7 ``egc/<robot>/goal``)


@dataclass(frozen=True, slots=True)
class GoalMessage:
    """The operator's via points, in order, in ``frame`` (metres); an empty list clears them."""

    seq: int
    stamp_ns: int
    op: str
    frame: str
    points: tuple[tuple[float, float], ...]

    def __post_init__(self) -> None:
        rejection = decode_goal(self.encode())
        if isinstance(rejection, Rejection):
            raise ValueError(f"invalid GoalMessage: {rejection}")

    def encode(self) -> bytes:
        wire = {
            "v": SCHEMA_VERSION,
            "seq": self.seq,
            "stamp_ns": self.stamp_ns,
            "op": self.op,
            "frame": self.frame,
            "points": [[float(x), float(y)] for x, y in self.points],
        }
        return _pack(wire)


def _goal_points(m: Mapping[Any, Any]) -> tuple[tuple[float, float], ...]:
    value = _get(m, "points")
    if not isinstance(value, list):
        raise _InvalidError(RejectReason.WRONG_TYPE, "'points' must be a list of [x, y]")
    if len(value) > MAX_GOAL_POINTS:
        raise _InvalidError(RejectReason.TOO_LARGE, f"more than {MAX_GOAL_POINTS} via points")
    points = []
    for i, item in enumerate(value):
        if not isinstance(item, list) or len(item) != 2:
            raise _InvalidError(RejectReason.WRONG_TYPE, f"via point {i} must be [x, y]")
        lim = MAX_GOAL_COORD_M
        xy = (
            _float({"x": item[0]}, "x", -lim, lim),
            _float({"y": item[1]}, "y", -lim, lim),
        )
        points.append(xy)
    return tuple(points)


def _build_goal(m: Mapping[Any, Any]) -> GoalMessage:
    goal = object.__new__(GoalMessage)
    values = {
        "seq": _int(m, "seq"),
        "stamp_ns": _int(m, "stamp_ns"),
        "op": _str(m, "op"),
        "frame": _str(m, "frame", GOAL_FRAMES),
        "points": _goal_points(m),
    }
    for key, value in values.items():
        object.__setattr__(goal, key, value)
    return goal


def decode_goal(payload: object) -> GoalMessage | Rejection:
    return _decode(payload, MAX_SMALL_BYTES, _build_goal)


# ---------------------------------------------------------------------------------------------
# State (robot -> operators, on change and at 1 Hz)


@dataclass(frozen=True, slots=True)
class StateMessage:
    stamp_ns: int
    state: str
    reason: str
    operator: str | None = None
    rejected: int = 0
    # DESIGN 14, as in the telemetry; left out when None (a robot without [[source]] tables).
    source: str | None = None
    lock: str | None = None
    # The robot's pose in the map frame when its driver localises (x, y, theta): an optional
    # key (DESIGN 7 additions) for the fleet's map (DESIGN 15), at the state's 1 Hz, so an
    # operator sees where every robot is without taking every robot's telemetry.
    map_pose: tuple[float, float, float] | None = None

    def encode(self) -> bytes:
        d = _shallow_fields(self)
        for key in ("source", "lock"):
            if d[key] is None:
                del d[key]
        if self.map_pose is None:
            del d["map_pose"]
        else:
            d["map_pose"] = [float(v) for v in self.map_pose]
        return _pack({"v": SCHEMA_VERSION, **d})


def _build_state(m: Mapping[Any, Any]) -> StateMessage:
    map_pose = _opt_tuple(m, "map_pose", 3, _POSE)
    return StateMessage(
        stamp_ns=_int(m, "stamp_ns"),
        state=_str(m, "state", STATES),
        reason=_str(m, "reason", max_chars=256),
        operator=_opt_str(m, "operator"),
        rejected=_int(m, "rejected") if "rejected" in m else 0,
        source=_opt_str(m, "source"),
        lock=_opt_str(m, "lock"),
        map_pose=None if map_pose is None else (map_pose[0], map_pose[1], map_pose[2]),
    )


# State and clock replies: a handful of keys, short strings, no arrays in use.
_SMALL_SHAPE: Final = _Shape(keys=64, max_array=16)


def decode_state(payload: object) -> StateMessage | Rejection:
    return _decode(payload, MAX_SMALL_BYTES, _build_state, shape=_SMALL_SHAPE)


# ---------------------------------------------------------------------------------------------
# Clock reply (robot queryable)


def encode_clock_reply(robot_now_ns: int, clock_id: str | None = None) -> bytes:
    """``clock_id`` (optional key ``clock``): which clock the stamp reads, e.g. the kernel's boot
    id for CLOCK_MONOTONIC (``egc_common.clock_id``); an operator reading the same clock knows
    the offset is exactly 0."""
    reply: dict[str, Any] = {"v": SCHEMA_VERSION, "stamp_ns": int(robot_now_ns)}
    if clock_id is not None:
        reply["clock"] = clock_id
    return _pack(reply)


def decode_clock_reply(payload: object) -> int | Rejection:
    return _decode(payload, MAX_SMALL_BYTES, lambda m: _int(m, "stamp_ns"), shape=_SMALL_SHAPE)


def decode_clock_id(payload: object) -> str | None:
    """The reply's optional ``clock`` key, or None (absent, or not a valid id)."""
    result = _decode(
        payload, MAX_SMALL_BYTES, lambda m: _opt_str(m, "clock", max_chars=128), shape=_SMALL_SHAPE
    )
    return None if isinstance(result, Rejection) else result


# ---------------------------------------------------------------------------------------------
# Remote driver messages: scan, base command, odometry


@dataclass(frozen=True, slots=True, eq=False)
class ScanMessage:
    """A planar scan in the ROS LaserScan layout; ranges per REP 117 (+inf no return, NaN
    unknown, -inf an object nearer than range_min)."""

    stamp_ns: int
    angle_min_rad: float
    angle_increment_rad: float
    range_min_m: float
    range_max_m: float
    ranges_m: npt.NDArray[np.float32]
    no_return_is_free: bool = False

    def encode(self) -> bytes:
        d = {f: getattr(self, f) for f in self.__slots__}
        d["ranges_m"] = np.ascontiguousarray(self.ranges_m, dtype="<f4").tobytes()
        return _pack({"v": SCHEMA_VERSION, **d})


def _build_scan(m: Mapping[Any, Any]) -> ScanMessage:
    range_min = _float(m, "range_min_m", 0.0, 1e4)
    range_max = _float(m, "range_max_m", 0.0, 1e4)
    if not range_min < range_max:
        raise _InvalidError(RejectReason.OUT_OF_RANGE, "range_min_m must be < range_max_m")
    return ScanMessage(
        stamp_ns=_int(m, "stamp_ns"),
        angle_min_rad=_float(m, "angle_min_rad", -10.0, 10.0),
        angle_increment_rad=_float(m, "angle_increment_rad", -1.0, 1.0),
        range_min_m=range_min,
        range_max_m=range_max,
        ranges_m=_f32_array(m, "ranges_m", allow_nonfinite=True),
        no_return_is_free=_bool(m, "no_return_is_free") if "no_return_is_free" in m else False,
    )


def decode_scan(payload: object) -> ScanMessage | Rejection:
    return _decode(payload, MAX_SCAN_BYTES, _build_scan, flat=True)


@dataclass(frozen=True, slots=True)
class BaseCommand:
    """Velocity sent to the base (robot -> driver)."""

    stamp_ns: int
    seq: int
    linear_mps: float
    angular_radps: float

    def encode(self) -> bytes:
        return _pack({"v": SCHEMA_VERSION, **_shallow_fields(self)})


def _build_base_cmd(m: Mapping[Any, Any]) -> BaseCommand:
    return BaseCommand(
        stamp_ns=_int(m, "stamp_ns"),
        seq=_int(m, "seq"),
        linear_mps=_float(m, "linear_mps", -100.0, 100.0),
        angular_radps=_float(m, "angular_radps", -100.0, 100.0),
    )


def decode_base_command(payload: object) -> BaseCommand | Rejection:
    return _decode(payload, MAX_SMALL_BYTES, _build_base_cmd)


@dataclass(frozen=True, slots=True)
class Odometry:
    """Pose and twist reported by the base (driver -> robot); world frame, SI units."""

    stamp_ns: int
    x_m: float
    y_m: float
    theta_rad: float
    linear_mps: float
    angular_radps: float
    collided: bool = False
    # The pose in the ``map`` frame when the driver localises (x, y, theta); None otherwise.
    # The simulator knows its true pose, so it reports both (odom == map, no drift).
    map_pose: tuple[float, float, float] | None = None

    def encode(self) -> bytes:
        d = _shallow_fields(self)
        if self.map_pose is None:
            del d["map_pose"]
        else:
            d["map_pose"] = [float(v) for v in self.map_pose]
        return _pack({"v": SCHEMA_VERSION, **d})


def _build_odom(m: Mapping[Any, Any]) -> Odometry:
    map_pose = _opt_tuple(m, "map_pose", 3)
    return Odometry(
        stamp_ns=_int(m, "stamp_ns"),
        x_m=_float(m, "x_m"),
        y_m=_float(m, "y_m"),
        theta_rad=_float(m, "theta_rad"),
        linear_mps=_float(m, "linear_mps"),
        angular_radps=_float(m, "angular_radps"),
        collided=_bool(m, "collided") if "collided" in m else False,
        map_pose=None if map_pose is None else (map_pose[0], map_pose[1], map_pose[2]),
    )


def decode_odometry(payload: object) -> Odometry | Rejection:
    return _decode(payload, MAX_SMALL_BYTES, _build_odom)


# ---------------------------------------------------------------------------------------------
# Static map (robot or its driver -> operators, a queryable on egc/<robot>/map)


@dataclass(frozen=True, slots=True, eq=False)
class MapMessage:
    """The robot's occupancy map for the operator's world-frame view.

    ``blocked`` is a bool grid, row 0 = the **top** row (highest y) as in a map_server image;
    ``origin`` is the world position (m) of the lower-left corner of the lower-left cell. On the
    wire the grid is bit-packed (numpy ``packbits``, row-major).
    """

    stamp_ns: int
    resolution_m: float
    origin_x_m: float
    origin_y_m: float
    blocked: npt.NDArray[np.bool_]
    goal: tuple[float, float] | None = None

    def encode(self) -> bytes:
        grid = np.asarray(self.blocked, dtype=bool)
        return _pack(
            {
                "v": SCHEMA_VERSION,
                "stamp_ns": self.stamp_ns,
                "resolution_m": self.resolution_m,
                "origin_x_m": self.origin_x_m,
                "origin_y_m": self.origin_y_m,
                "height": int(grid.shape[0]),
                "width": int(grid.shape[1]),
                "blocked": np.packbits(grid, axis=None).tobytes(),
                "goal": None if self.goal is None else [float(v) for v in self.goal],
            }
        )


def _build_map(m: Mapping[Any, Any]) -> MapMessage:
    height = _int(m, "height", 1, MAX_MAP_CELLS)
    width = _int(m, "width", 1, MAX_MAP_CELLS)
    if height * width > MAX_MAP_CELLS:
        raise _InvalidError(RejectReason.TOO_LARGE, f"map of {height} x {width} cells is too large")
    packed = _get(m, "blocked")
    if not isinstance(packed, (bytes, bytearray)):
        raise _InvalidError(RejectReason.WRONG_TYPE, "'blocked' must be bytes")
    if len(packed) != (height * width + 7) // 8:
        raise _InvalidError(RejectReason.OUT_OF_RANGE, "'blocked' does not match height x width")
    bits = np.unpackbits(np.frombuffer(bytes(packed), dtype=np.uint8), count=height * width)
    goal = _opt_tuple(m, "goal", 2)
    return MapMessage(
        stamp_ns=_int(m, "stamp_ns"),
        resolution_m=_float(m, "resolution_m", 1e-4, 100.0),
        origin_x_m=_float(m, "origin_x_m", -1e7, 1e7),
        origin_y_m=_float(m, "origin_y_m", -1e7, 1e7),
        blocked=bits.astype(bool).reshape(height, width),
        goal=None if goal is None else (goal[0], goal[1]),
    )


# The map: a few keys, the goal's 2 numbers, the grid as bytes.
_MAP_SHAPE: Final = _Shape(keys=64, max_array=16, max_bin=MAX_MAP_BYTES)


def decode_map(payload: object) -> MapMessage | Rejection:
    return _decode(payload, MAX_MAP_BYTES, _build_map, shape=_MAP_SHAPE)
