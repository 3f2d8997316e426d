"""Robot profiles as data (DESIGN 3, 14): footprint, kinematic limits and the EGC radii.

A profile is a TOML file with one ``[profile]`` table, **pinned** keys:

===============  ========================================================================
``name``         the profile's name (telemetry, the view, the info reply)
``footprint``    polygon ``[[x, y], ...]`` in base_link, metres (any simple polygon);
  or ``radius``  a disc about base_link's origin, metres (``footprint = {radius = R}`` too)
``v_max``        largest |v|, m/s
``w_max``        largest |w|, rad/s
``a_max``        linear acceleration limit, m/s^2
``a_dec``        linear deceleration limit (braking), m/s^2
``alpha_max``    angular acceleration limit, rad/s^2
``r_max``        EGC's outer radius r_max = d_robot + d_safe (paper eq. 5), m
``laser_pose``   optional ``[x, y, yaw]`` of the laser in base_link (m, m, rad)
``source``       one line: where each figure comes from
===============  ========================================================================

Optional keys with documented defaults: ``wheel_base`` (m; default the footprint's width
along y: it only bounds the wheel rim speed a command can ask for) and ``d_robot`` (m; EGC's
r_min, paper sec. 3.1; default the footprint's length along x, as the paper's Pioneer, a disc's
diameter). r_max must exceed d_robot (d_safe = r_max - d_robot > 0).

Built-ins ship as such files (``egc_common/profiles/*.toml``): ``pioneer3dx`` (the paper:
r_min 0.455 m, r_max 0.595 m), ``jackal``, ``turtlebot4``, ``husky``. ``load_profile`` takes a
built-in's name or a file's path; a bad file raises ``ProfileError`` with one line naming the
file, the key and the problem.
"""

from __future__ import annotations

import math
import os
import re
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, replace
from importlib import resources
from pathlib import Path
from typing import Any, Final

from egc_common.footprint import Footprint, FootprintError

# Pinned keys (DESIGN 14) and the optional ones with defaults; the unit each number is in.
NUMBER_KEYS: Final = {
    "v_max": "m/s",
    "w_max": "rad/s",
    "a_max": "m/s^2",
    "a_dec": "m/s^2",
    "alpha_max": "rad/s^2",
    "r_max": "m",
}
OPTIONAL_NUMBER_KEYS: Final = {"wheel_base": "m", "d_robot": "m"}
PROFILE_KEYS: Final = (
    "name",
    "footprint",
    "radius",
    *NUMBER_KEYS,
    "laser_pose",
    "source",
    *OPTIONAL_NUMBER_KEYS,
)
# Far beyond any ground robot; a figure past these is a typo (mm for m), not a robot.
_MAX_NUMBER: Final = 1000.0
_NAME = re.compile(r"[A-Za-z0-9_.+-]{1,64}")
_MAX_FILE_BYTES: Final = 64 * 1024


class ProfileError(ValueError):
    """A profile that cannot be used; the message is one line naming the key and the problem."""


@dataclass(frozen=True, slots=True)
class RobotProfile:
    """Everything the filter, the limits and the simulator need to know about one robot.

    ``footprint`` is the shape as given (polygon or disc); ``length_m``, ``width_m`` and
    ``half_size_m`` are its bounding box, for code that only needs a bound. Contact is decided
    on ``footprint`` (``egc_common.footprint``)."""

    name: str
    footprint: Footprint
    wheel_base_m: float
    v_max_mps: float
    w_max_radps: float
    accel_max_mps2: float
    decel_max_mps2: float
    angular_accel_max_radps2: float
    d_robot_m: float
    r_max_m: float
    laser_pose: tuple[float, float, float] | None = None
    source: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not _NAME.fullmatch(self.name):
            raise ValueError(
                f"profile name must be 1 to 64 of A-Z a-z 0-9 _ . + -, got {self.name!r}"
            )
        if not isinstance(self.footprint, Footprint):
            raise ValueError(f"profile {self.name!r}: footprint must be a Footprint")
        for key in (
            "wheel_base_m",
            "v_max_mps",
            "w_max_radps",
            "accel_max_mps2",
            "decel_max_mps2",
            "angular_accel_max_radps2",
            "d_robot_m",
            "r_max_m",
        ):
            value = getattr(self, key)
            if (
                not isinstance(value, (int, float))
                or isinstance(value, bool)
                or not math.isfinite(value)
                or value <= 0
            ):
                raise ValueError(f"profile {self.name!r}: {key} must be a positive finite number")
        if self.r_max_m <= self.d_robot_m:
            raise ValueError(
                f"profile {self.name!r}: r_max ({self.r_max_m} m) must exceed d_robot "
                f"({self.d_robot_m} m)"
            )
        if self.laser_pose is not None and (
            len(self.laser_pose) != 3 or not all(math.isfinite(v) for v in self.laser_pose)
        ):
            raise ValueError(f"profile {self.name!r}: laser_pose must be 3 finite numbers")

    @property
    def length_m(self) -> float:
        """The footprint's extent along x."""
        return self.footprint.length_m

    @property
    def width_m(self) -> float:
        """The footprint's extent along y."""
        return self.footprint.width_m

    @property
    def d_safe_m(self) -> float:
        """The safety distance beyond the robot (paper sec. 3.1): r_max - d_robot."""
        return self.r_max_m - self.d_robot_m

    @property
    def r_min_m(self) -> float:
        """Radius of the unsafe region (paper eq. 5)."""
        return self.d_robot_m

    @property
    def horizon_s(self) -> float:
        """Default prediction horizon kT = r_max / v_max (DESIGN 5.8)."""
        return self.r_max_m / self.v_max_mps

    @property
    def half_size_m(self) -> tuple[float, float]:
        """(max |x|, max |y|) of the footprint: a bound, the smallest box centred on {R}'s
        origin that holds it (for a centred rectangle, its half length and half width)."""
        return self.footprint.half_size_m

    @property
    def half_diagonal_m(self) -> float:
        """Radius of the circle swept by the footprint when turning in place (its reach)."""
        return self.footprint.reach_m

    @property
    def wheel_speed_max_mps(self) -> float:
        """Largest wheel rim speed the profile's (v_max, w_max) can ask for."""
        return self.v_max_mps + 0.5 * self.wheel_base_m * self.w_max_radps

    def with_overrides(self, **overrides: Any) -> RobotProfile:
        """A copy with some fields replaced (validated again)."""
        return replace(self, **overrides)


# -- loading ----------------------------------------------------------------------------------


def profile_from_table(table: Mapping[str, Any], origin: str = "profile") -> RobotProfile:
    """A profile from the ``[profile]`` table's contents; ``origin`` prefixes every error."""

    def fail(key: str, problem: str) -> ProfileError:
        return ProfileError(f"{origin}: {key}: {problem}")

    unknown = sorted(str(k) for k in table if k not in PROFILE_KEYS)
    if unknown:
        raise fail(unknown[0], f"unknown key (known: {', '.join(k for k in PROFILE_KEYS)})")
    name = table.get("name")
    if name is None:
        raise fail("name", "missing")
    if not isinstance(name, str) or not _NAME.fullmatch(name):
        raise fail("name", f"must be 1 to 64 of A-Z a-z 0-9 _ . + -, got {name!r}")
    source = table.get("source")
    if source is None:
        raise fail("source", "missing (one line saying where each figure comes from)")
    if not isinstance(source, str) or not source.strip() or "\n" in source.strip():
        raise fail("source", "must be one non-empty line of text")

    footprint = _footprint(table, fail)
    numbers = {key: _number(table, key, unit, fail) for key, unit in NUMBER_KEYS.items()}
    wheel_base = (
        _number(table, "wheel_base", "m", fail) if "wheel_base" in table else footprint.width_m
    )
    d_robot = _number(table, "d_robot", "m", fail) if "d_robot" in table else _d_robot(footprint)
    if numbers["r_max"] <= d_robot:
        raise fail(
            "r_max",
            f"must exceed d_robot = {d_robot:g} m (r_max = d_robot + d_safe, paper eq. 5), "
            f"got {numbers['r_max']:g}",
        )
    laser = _laser_pose(table, fail)
    return RobotProfile(
        name=name,
        footprint=footprint,
        wheel_base_m=wheel_base,
        v_max_mps=numbers["v_max"],
        w_max_radps=numbers["w_max"],
        accel_max_mps2=numbers["a_max"],
        decel_max_mps2=numbers["a_dec"],
        angular_accel_max_radps2=numbers["alpha_max"],
        d_robot_m=d_robot,
        r_max_m=numbers["r_max"],
        laser_pose=laser,
        source=source.strip(),
    )


def profile_from_toml(text: str, origin: str) -> RobotProfile:
    """A profile from a TOML document with one ``[profile]`` table."""
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ProfileError(f"{origin}: not valid TOML: {exc}") from None
    others = sorted(k for k in doc if k != "profile")
    if others:
        raise ProfileError(
            f"{origin}: {others[0]}: unknown key or table (a profile file holds one "
            "[profile] table)"
        )
    table = doc.get("profile")
    if table is None:
        raise ProfileError(f"{origin}: profile: missing [profile] table")
    if not isinstance(table, dict):
        raise ProfileError(f"{origin}: profile: must be a table, [profile]")
    return profile_from_table(table, origin)


def read_profile_file(path: str | Path) -> RobotProfile:
    """A profile from a TOML file; every failure (missing, unreadable, not TOML, a bad key) is
    one ``ProfileError`` line."""
    p = Path(path)
    origin = f"profile {p}"
    try:
        with p.open("rb") as f:
            data = f.read(_MAX_FILE_BYTES + 1)
    except FileNotFoundError:
        raise ProfileError(f"{origin}: file not found") from None
    except IsADirectoryError:
        raise ProfileError(f"{origin}: is a directory, not a file") from None
    except OSError as exc:
        raise ProfileError(f"{origin}: cannot read: {exc.strerror or exc}") from None
    if len(data) > _MAX_FILE_BYTES:
        raise ProfileError(f"{origin}: larger than {_MAX_FILE_BYTES // 1024} KiB: not a profile")
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise ProfileError(f"{origin}: not valid TOML: not UTF-8 text") from None
    return profile_from_toml(text, origin)


def _builtin_profiles() -> dict[str, RobotProfile]:
    folder = resources.files("egc_common") / "profiles"
    out: dict[str, RobotProfile] = {}
    for entry in sorted(folder.iterdir(), key=lambda e: e.name):
        if entry.name.endswith(".toml"):
            profile = profile_from_toml(entry.read_text("utf-8"), f"built-in {entry.name}")
            out[profile.name] = profile
    return out


_FILE_CACHE: dict[tuple[str, int, int], RobotProfile] = {}
_LOADED: dict[str, RobotProfile] = {}


def is_profile_path(text: str) -> bool:
    """Whether ``--profile`` names a file (``.toml``, a path separator, or an existing file)
    rather than a built-in."""
    return text.endswith(".toml") or os.sep in text or "/" in text or Path(text).is_file()


def load_profile(name_or_path: str | Path) -> RobotProfile:
    """The built-in profile of that name, or the profile in that TOML file (DESIGN 14).

    Raises ``ProfileError`` (one line) for an unknown name or a bad file."""
    text = str(name_or_path)
    if isinstance(name_or_path, str) and text in PROFILES:
        return PROFILES[text]
    if not is_profile_path(text):
        known = ", ".join(sorted(PROFILES))
        raise ProfileError(
            f"unknown robot profile {text!r} (known: {known}; or a profile FILE.toml)"
        )
    p = Path(text)
    try:
        st = p.stat()
        key = (str(p.resolve()), st.st_mtime_ns, st.st_size)
    except OSError:
        return read_profile_file(p)  # says what is wrong
    cached = _FILE_CACHE.get(key)
    if cached is None:
        cached = read_profile_file(p)
        _FILE_CACHE[key] = cached
    _LOADED[cached.name] = cached
    return cached


def profile_named(name: str) -> RobotProfile | None:
    """The profile this process knows by ``name`` (what telemetry carries): one loaded from a
    file under that name (the latest), else the built-in, else None. An operator view in the
    process that loaded the file (``episode --record``, ``replay --record``) draws its shape."""
    return _LOADED.get(name) or PROFILES.get(name)


def get_profile(name_or_path: str | Path) -> RobotProfile:
    """``load_profile`` under its older name."""
    return load_profile(name_or_path)


def profile_names_help() -> str:
    """For --help: the built-in names and the file form."""
    return f"{'|'.join(sorted(PROFILES))}|FILE.toml"


# -- keys -------------------------------------------------------------------------------------


def _number(table: Mapping[str, Any], key: str, unit: str, fail: Any) -> float:
    if key not in table:
        raise fail(key, f"missing (a number of {unit})")
    value = table[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise fail(key, f"must be a number of {unit}, got {_shown(value)}")
    if not math.isfinite(value):
        raise fail(key, f"must be finite, got {value}")
    if value <= 0:
        raise fail(key, f"must be positive ({unit}), got {value}")
    if value > _MAX_NUMBER:
        raise fail(key, f"must be at most {_MAX_NUMBER:g} {unit}, got {value}")
    return float(value)


def _footprint(table: Mapping[str, Any], fail: Any) -> Footprint:
    polygon: Any = table.get("footprint")
    radius: Any = table.get("radius")
    if isinstance(polygon, dict):  # footprint = {radius = R}
        extra = sorted(k for k in polygon if k != "radius")
        if extra or "radius" not in polygon:
            raise fail("footprint", "a table form must be {radius = R}")
        if radius is not None:
            raise fail("radius", "given twice (footprint.radius and radius)")
        polygon, radius = None, polygon["radius"]
    if polygon is None and radius is None:
        raise fail("footprint", "missing (a polygon [[x, y], ...] in metres, or radius = R)")
    if polygon is not None and radius is not None:
        raise fail("footprint", "give a polygon or a radius, not both")
    if radius is not None:
        if isinstance(radius, bool) or not isinstance(radius, (int, float)):
            raise fail("radius", f"must be a number of m, got {_shown(radius)}")
        if not math.isfinite(radius):
            raise fail("radius", f"must be finite, got {radius}")
        if radius <= 0:
            raise fail("radius", f"must be positive (m), got {radius}")
        try:
            return Footprint.disc(float(radius))
        except FootprintError as exc:
            raise fail("radius", str(exc)) from None
    if not isinstance(polygon, list) or not all(
        isinstance(v, list) and len(v) == 2 for v in polygon
    ):
        raise fail("footprint", f"must be a list of [x, y] pairs in metres, got {_shown(polygon)}")
    for v in polygon:
        for c in v:
            if isinstance(c, bool) or not isinstance(c, (int, float)):
                raise fail("footprint", f"vertex {v!r}: coordinates must be numbers")
            if not math.isfinite(c):
                raise fail("footprint", f"vertex {v!r}: coordinates must be finite")
    try:
        return Footprint.polygon(polygon)
    except FootprintError as exc:
        raise fail("footprint", str(exc)) from None


def _d_robot(footprint: Footprint) -> float:
    """EGC's r_min by default: the footprint's length along x (the paper's d_robot for the
    Pioneer is its length), a disc's diameter."""
    return footprint.length_m


def _laser_pose(table: Mapping[str, Any], fail: Any) -> tuple[float, float, float] | None:
    if "laser_pose" not in table:
        return None
    value = table["laser_pose"]
    if (
        not isinstance(value, list)
        or len(value) != 3
        or any(isinstance(c, bool) or not isinstance(c, (int, float)) for c in value)
    ):
        raise fail("laser_pose", f"must be [x, y, yaw] (m, m, rad), got {_shown(value)}")
    if not all(math.isfinite(c) for c in value):
        raise fail("laser_pose", f"must be finite, got {value}")
    x, y, yaw = (float(c) for c in value)
    if abs(x) > 100.0 or abs(y) > 100.0 or abs(yaw) > 2.0 * math.pi:
        raise fail("laser_pose", f"out of range (|x|, |y| <= 100 m, |yaw| <= 2 pi), got {value}")
    return x, y, yaw


def _shown(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


# The built-ins, read once at import (after every helper above is defined).
PROFILES: Final[dict[str, RobotProfile]] = _builtin_profiles()
PIONEER3DX: Final = PROFILES["pioneer3dx"]
JACKAL: Final = PROFILES["jackal"]
TURTLEBOT4: Final = PROFILES["turtlebot4"]
HUSKY: Final = PROFILES["husky"]
