"""What the operator view draws, as pure functions of the robot's telemetry (no Rerun here).

Everything is in SI units in the robot frame {R} (x forward, y left) or the world frame; the view
layer maps both onto the screen with one static transform each (``ROBOT_TO_SCREEN``,
``WORLD_TO_SCREEN``), so the recorded numbers stay the robot's own.

Colour code, after the paper: blue is the operator's side (reference command, initial guide
circle, Fig. 10 and 11), red is what the robot made of it (sent command, expanded guide circle).
The region of the safety index circle (eq. 5) colours the footprint: green safe, amber
conditional, red unsafe.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from egc_common.messages import Circle, Telemetry
from egc_common.profiles import PROFILES, RobotProfile

F32 = npt.NDArray[np.float32]
Rgb = tuple[int, int, int]

# Rerun's 2D views put +y down. {R} is shown with forward up and left to the left
# (screen = (-y, -x)); the world frame with +y up (screen = (x, -y)).
ROBOT_TO_SCREEN = ((0.0, -1.0, 0.0), (-1.0, 0.0, 0.0), (0.0, 0.0, 1.0))
WORLD_TO_SCREEN = ((1.0, 0.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, 1.0))

REFERENCE_BLUE: Rgb = (31, 119, 230)
SENT_RED: Rgb = (220, 40, 40)
AGC_VIOLET: Rgb = (150, 100, 200)
REACHABLE_GREY: Rgb = (150, 150, 150)
SCAN_INK: Rgb = (40, 40, 60)
TRAJECTORY_TEAL: Rgb = (0, 140, 140)
GOAL_GREEN: Rgb = (0, 160, 60)
REGION_COLOURS: dict[str, Rgb] = {
    "safe": (40, 170, 70),
    "conditional": (235, 150, 0),
    "unsafe": (220, 30, 30),
}
UNKNOWN_REGION: Rgb = (120, 120, 120)

# Telemetry.limiter values (egc_robot.pipeline.Limiter plus the state machine's) -> short text.
LIMITER_TEXT: dict[str, str] = {
    "none": "no limit",
    "egc": "EGC",
    "sweep": "footprint sweep",
    "limits": "v/a limits",
    "watchdog": "watchdog",
    "hold": "hold",
    "estop": "e-stop",
}

CIRCLE_NAMES = ("reachable", "igc", "agc", "egc")
CIRCLE_COLOURS: dict[str, Rgb] = {
    "reachable": REACHABLE_GREY,
    "igc": REFERENCE_BLUE,
    "agc": AGC_VIOLET,
    "egc": SENT_RED,
}
CIRCLE_LABELS = {
    "reachable": "reachable",
    "igc": "initial GC",
    "agc": "aux. GC",
    "egc": "expanded GC",
}
FALLBACK_HORIZON_S = 1.0


def profile_named(name: str) -> RobotProfile | None:
    """The pinned profile of that name, or None when the telemetry names none we know."""
    return PROFILES.get(name)


def drawable_circle(circle: Circle | None) -> Circle | None:
    """The circle (x, y, r) if it can be drawn (finite, r > 0), else None."""
    if circle is None:
        return None
    if not (all(math.isfinite(v) for v in circle) and circle[2] > 0.0):
        return None
    return circle


def footprint_half_size(profile: RobotProfile) -> tuple[float, float]:
    """Half length and half width of the footprint rectangle, centred on the origin of {R}."""
    return 0.5 * profile.length_m, 0.5 * profile.width_m


def command_vector(v_mps: float, w_radps: float, horizon_s: float) -> tuple[float, float]:
    """Where (v, w) leads over the horizon kT, as the filter predicts it (paper eq. 6).

    For the operator's command this is the centre of the initial guide circle, so the blue arrow
    ends where the blue circle is centred; the red arrow is the command actually sent.
    """
    d = v_mps * horizon_s
    half = 0.5 * w_radps * horizon_s
    return d * math.cos(half), d * math.sin(half)


def status_text(t: Telemetry) -> str:
    """One line for the robot-frame view, e.g. ``DRIVING · shared · limit: EGC · conditional``."""
    limiter = LIMITER_TEXT.get(t.limiter, t.limiter)
    return f"{t.state} · {t.mode} · limit: {limiter} · {t.region} · w_SI {t.w_si:.2f}"


@dataclass(frozen=True, slots=True, eq=False)
class RobotFrameScene:
    """The robot-frame view of one control cycle; every array is in {R}, metres."""

    scan_xy: F32
    footprint_half_size: tuple[float, float] | None  # None: unknown profile
    region_colour: Rgb
    circles: dict[str, Circle | None]  # CIRCLE_NAMES -> (x, y, r), None when absent this cycle
    reference_vector: tuple[float, float]
    sent_vector: tuple[float, float]
    status: str
    status_anchor: tuple[float, float]  # just behind the robot


def robot_frame_scene(t: Telemetry) -> RobotFrameScene:
    """Build the robot-frame view from one Telemetry message.

    The footprint and the prediction horizon come from the profile named in ``t.profile``; for a
    name we do not know there is no footprint and arrows use ``FALLBACK_HORIZON_S``.
    """
    profile = profile_named(t.profile)
    horizon = profile.horizon_s if profile else FALLBACK_HORIZON_S
    circles = {
        "reachable": drawable_circle((0.0, 0.0, t.r_rc)),
        "igc": drawable_circle(t.igc),
        "agc": drawable_circle(t.agc),
        "egc": drawable_circle(t.egc),
    }
    back = -(0.5 * profile.length_m + 0.15) if profile else -0.4
    return RobotFrameScene(
        scan_xy=np.ascontiguousarray(t.scan_xy, dtype=np.float32).reshape(-1, 2),
        footprint_half_size=footprint_half_size(profile) if profile else None,
        region_colour=REGION_COLOURS.get(t.region, UNKNOWN_REGION),
        circles=circles,
        reference_vector=command_vector(t.v_ref, t.w_ref, horizon),
        sent_vector=command_vector(t.v_cmd, t.w_cmd, horizon),
        status=status_text(t),
        status_anchor=(back, 0.0),
    )


def time_series(t: Telemetry) -> dict[str, float]:
    """Scalar plots of one cycle, keyed by the series' name under ``plots/`` (paper Fig. 11).

    Ages are only present when the robot measured them this cycle.
    """
    series = {
        "v/ref": t.v_ref,
        "v/cmd": t.v_cmd,
        "w/ref": t.w_ref,
        "w/cmd": t.w_cmd,
        "w_si": t.w_si,
    }
    if t.cmd_age_ms is not None:
        series["latency/cmd_age_ms"] = t.cmd_age_ms
    if t.scan_age_ms is not None:
        series["latency/scan_age_ms"] = t.scan_age_ms
    return series


STATUS_LANES = ("state", "mode", "limiter", "region")
_AMBER: Rgb = REGION_COLOURS["conditional"]
_GREY: Rgb = (190, 190, 190)
# lane -> (value, colour) in the order shown by the state timeline.
LANE_COLOURS: dict[str, tuple[tuple[str, Rgb], ...]] = {
    "state": (
        ("IDLE", _GREY),
        ("DRIVING", REGION_COLOURS["safe"]),
        ("HOLD", _AMBER),
        ("ESTOP", REGION_COLOURS["unsafe"]),
    ),
    "mode": (("direct", (230, 120, 40)), ("shared", REFERENCE_BLUE)),
    "limiter": (
        ("none", _GREY),
        ("egc", SENT_RED),
        ("sweep", AGC_VIOLET),
        ("limits", (120, 160, 220)),
        ("watchdog", _AMBER),
        ("hold", _AMBER),
        ("estop", (140, 0, 0)),
    ),
    "region": tuple(REGION_COLOURS.items()),
}


def status_changes(previous: Telemetry | None, t: Telemetry) -> dict[str, str]:
    """The status lanes (state, mode, limiter, region) whose value differs from ``previous``."""
    now = {lane: str(getattr(t, lane)) for lane in STATUS_LANES}
    if previous is None:
        return now
    return {lane: v for lane, v in now.items() if getattr(previous, lane) != v}


def pose_moved(
    last: tuple[float, float] | None, pose: tuple[float, float, float], step_m: float
) -> bool:
    """True when the trajectory should get a new vertex: first pose, or moved at least step_m."""
    return last is None or math.hypot(pose[0] - last[0], pose[1] - last[1]) >= step_m


@dataclass(frozen=True, slots=True, eq=False)
class MapImage:
    """An occupancy grid as a grey image plus the transform placing its pixels in the world."""

    pixels: npt.NDArray[np.uint8]  # H x W, row 0 = top (largest y)
    translation: tuple[float, float, float]
    mat3x3: tuple[tuple[float, float, float], ...]


OCCUPIED_GREY = 60
FREE_GREY = 235


def map_image(
    occupancy: npt.ArrayLike, resolution_m: float, origin_xy_m: tuple[float, float]
) -> MapImage:
    """Place an occupancy grid (bool H x W, row 0 = top) in the world frame.

    ``origin_xy_m`` is the world position of the grid's lower-left corner (the ROS map
    convention); pixel (col, row) covers x in origin_x + res [col, col + 1] and
    y in origin_y + res [H - row - 1, H - row].
    """
    occ = np.asarray(occupancy, dtype=bool)
    if occ.ndim != 2 or occ.size == 0:
        raise ValueError("occupancy must be a non-empty 2-D boolean array (rows x columns)")
    if not (math.isfinite(resolution_m) and resolution_m > 0.0):
        raise ValueError("map resolution must be a positive number of metres per cell")
    if not all(math.isfinite(v) for v in origin_xy_m):
        raise ValueError("map origin must be finite")
    pixels = np.where(occ, OCCUPIED_GREY, FREE_GREY).astype(np.uint8)
    top = origin_xy_m[1] + occ.shape[0] * resolution_m
    mat = ((resolution_m, 0.0, 0.0), (0.0, -resolution_m, 0.0), (0.0, 0.0, 1.0))
    return MapImage(pixels, (origin_xy_m[0], top, 0.0), mat)
