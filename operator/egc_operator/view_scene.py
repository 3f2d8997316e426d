"""What the operator view draws, as pure functions of the robot's telemetry (no Rerun here).

Everything is in SI units in the robot frame {R} (x forward, y left) or the world frame; the view
layer maps both onto the screen with one static transform each (``ROBOT_TO_SCREEN``,
``WORLD_TO_SCREEN``), so the recorded numbers stay the robot's own.

Colour code, after the paper: blue is the operator's side (reference command, initial guide
circle, Fig. 10 and 11), red is what the robot made of it (sent command, expanded guide circle).
The region of the safety index circle (eq. 5) colours the footprint: green safe, amber
conditional, red unsafe. Via points (DESIGN 7) are orange in the world frame: the active one
large and labelled, the ones ahead small, those passed grey, the route a line from the robot
through the active one and those ahead; the filter's suggested direction (``assist``) is an
orange arrow in {R}. The predictive display (DESIGN 9) is magenta, translucent and dashed,
labelled as a prediction, so that it is never taken for a measurement.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
from egc_common.footprint import mitred_outline
from egc_common.messages import Circle, Telemetry
from egc_common.profiles import RobotProfile
from egc_common.profiles import profile_named as known_profile

from egc_operator.prediction import Prediction
from egc_operator.status_line import (
    TELEMETRY_STALE_S,
    held_still,
    latency_cap_text,
    view_plane_text,
)
from egc_operator.via_route import Route, active_index

F32 = npt.NDArray[np.float32]
NO_POINTS: F32 = np.zeros((0, 2), np.float32)
Rgb = tuple[int, int, int]
Rgba = tuple[int, int, int, int]
Point = tuple[float, float]

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
PREDICTED_MAGENTA: Rgba = (200, 40, 190, 210)  # translucent: a prediction, not a measurement
PREDICTED_LABEL = "predicted (not measured)"
# From this far ahead the link panel tells the operator to steer by the ghost: a model operator
# steering by the measured robot collided in a third of the runs at 100-250 ms one-way, steering
# by the ghost in almost none (docs/network-delay.md); at 0.3 s a 1 m/s robot is 0.3 m further on.
STEER_BY_GHOST_S = 0.3
LATENCY_BROWN: Rgb = (150, 90, 30)
VIA_ORANGE: Rgb = (240, 130, 0)
CBF_TEAL: Rgb = (0, 170, 120)  # cbf's margin; the points that constrain are SENT_RED
VIA_PASSED_GREY: Rgb = (175, 175, 175)
SUGGESTED_LENGTH_M = 1.0

# Telemetry.limiter values (egc_robot.pipeline.Limiter plus the state machine's) -> short text.
LIMITER_TEXT: dict[str, str] = {
    "none": "no limit",
    "egc": "EGC",
    "ek-egc": "EK-EGC",
    "assist": "assist",
    "dwa": "DWA",
    "cbf": "CBF",
    "sweep": "footprint sweep",
    "limits": "v/a limits",
    "watchdog": "watchdog",
    "hold": "hold",
    "estop": "e-stop",
    "latency": "latency",
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
    """The profile of that name (a built-in, or one this process loaded from a file, DESIGN
    14), or None when the telemetry names none we know."""
    return known_profile(name)


def drawable_circle(circle: Circle | None) -> Circle | None:
    """The circle (x, y, r) if it can be drawn (finite, r > 0), else None."""
    if circle is None:
        return None
    if not (all(math.isfinite(v) for v in circle) and circle[2] > 0.0):
        return None
    return circle


def footprint_half_size(profile: RobotProfile) -> tuple[float, float]:
    """Half length and half width of the box centred on the origin of {R} that holds the
    footprint (the footprint itself for a centred rectangle)."""
    return profile.half_size_m


def footprint_outline(profile: RobotProfile) -> list[Point]:
    """The footprint as given (DESIGN 14: any polygon, or a disc), closed, in {R}."""
    return profile.footprint.outline()


def footprint_is_box(profile: RobotProfile) -> bool:
    """Whether the footprint is a rectangle centred on {R}'s origin (drawn as a box)."""
    return profile.footprint.centred_box is not None


def command_vector(v_mps: float, w_radps: float, horizon_s: float) -> tuple[float, float]:
    """Where (v, w) leads over the horizon kT, as the filter predicts it (paper eq. 6).

    For the operator's command this is the centre of the initial guide circle, so the blue arrow
    ends where the blue circle is centred; the red arrow is the command actually sent.
    """
    d = v_mps * horizon_s
    half = 0.5 * w_radps * horizon_s
    return d * math.cos(half), d * math.sin(half)


def status_text(t: Telemetry) -> str:
    """One line for the robot-frame view, e.g. ``DRIVING · shared · limit: EGC · conditional``.

    A robot that is not driving says why (``HOLD (command timeout) · ...``); the latency limiter
    says its cap (``limit: latency <= 0.10 m/s``). The filter that runs follows the mode
    (``shared (ek-egc)``), and the active via point comes last (``via 2.0,1.0 +1 more``).
    A robot with command sources (DESIGN 14) says which drives and which lock holds
    (``source nav · lock pause``).
    """
    limiter = LIMITER_TEXT.get(t.limiter, t.limiter)
    if t.limiter == "latency" and t.v_lim_latency is not None:
        limiter += f" <= {t.v_lim_latency:.2f} m/s"
        if t.w_lim_latency is not None:
            limiter += f", {t.w_lim_latency:.2f} rad/s"
    if held_still(t):
        limiter += ", stopped: ease off or steer away"
    state = t.state if t.state == "DRIVING" or not t.reason else f"{t.state} ({t.reason})"
    mode = t.mode if t.filter in ("", "none") else f"{t.mode} ({t.filter})"
    text = f"{state} · {mode} · limit: {limiter} · {t.region} · w_SI {t.w_si:.2f}"
    if t.goal is not None:
        more = f" +{t.goals_left} more" if t.goals_left else ""
        text += f" · via {t.goal[0]:.1f},{t.goal[1]:.1f}{more}"
    if t.source is not None:
        text += f" · source {t.source}"
    if t.lock is not None:
        text += f" · lock {t.lock}"
    return text


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
    # The footprint's outline (closed) when it is not a centred rectangle (then a box is drawn
    # from ``footprint_half_size``); None for a box or an unknown profile.
    footprint_outline: list[Point] | None = None
    # cbf (DESIGN 13): the points whose barriers changed the command, and the margin it keeps
    # (``cbf_margin_outline``); empty / None when cbf did not run.
    cbf_xy: F32 = field(default_factory=lambda: NO_POINTS)
    cbf_margin: list[Point] | None = None


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
    back = profile.footprint.bounds[0] - 0.15 if profile else -0.4
    outline = footprint_outline(profile) if profile and not footprint_is_box(profile) else None
    return RobotFrameScene(
        scan_xy=np.ascontiguousarray(t.scan_xy, dtype=np.float32).reshape(-1, 2),
        footprint_half_size=footprint_half_size(profile) if profile else None,
        region_colour=REGION_COLOURS.get(t.region, UNKNOWN_REGION),
        circles=circles,
        reference_vector=command_vector(t.v_ref, t.w_ref, horizon),
        sent_vector=command_vector(t.v_cmd, t.w_cmd, horizon),
        status=status_text(t),
        status_anchor=(back, 0.0),
        footprint_outline=outline,
        cbf_xy=np.ascontiguousarray(t.cbf_xy, dtype=np.float32).reshape(-1, 2),
        cbf_margin=cbf_margin_outline(profile, t.cbf_margin_m, t.cbf_ahead_m, t.v_cmd < 0.0)
        if profile is not None and t.cbf_margin_m is not None
        else None,
    )


def cbf_margin_outline(
    profile: RobotProfile, margin_m: float, ahead_m: float | None, reversing: bool
) -> list[Point]:
    """cbf's margin around the footprint (closed, in {R}): the footprint grown by the margin,
    its front (back, when reversing) pushed out to the margin ahead, which grows with the loop
    delay and the braking distance at the current speed (DESIGN 13)."""
    grown = mitred_outline(profile.footprint, margin_m)
    stretch = max((ahead_m or margin_m) - margin_m, 0.0)
    side = grown[:, 0] < 0.0 if reversing else grown[:, 0] > 0.0
    grown[side, 0] += -stretch if reversing else stretch
    out = [(float(x), float(y)) for x, y in grown]
    return [*out, out[0]]


def time_series(t: Telemetry) -> dict[str, float]:
    """Scalar plots of one cycle, keyed by the series' name under ``plots/`` (paper Fig. 11).

    Ages and link figures are only present when the robot measured them this cycle; the
    latency governor's caps are drawn with the speeds (``v/lim_latency``, ``w/lim_latency``).
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
    for name in LINK_SERIES:
        value = getattr(t, name)
        if value is not None:
            series[f"latency/{name}"] = value
    if t.v_lim_latency is not None:
        series["v/lim_latency"] = t.v_lim_latency
    if t.w_lim_latency is not None:
        series["w/lim_latency"] = t.w_lim_latency
    return series


# Telemetry link figures plotted under plots/latency (DESIGN 7, 9), all in milliseconds.
LINK_SERIES = ("cmd_age_p50_ms", "cmd_age_p90_ms", "cmd_gap_max_ms", "view_age_ms", "loop_delay_ms")


STATUS_LANES = ("state", "mode", "filter", "limiter", "region")
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
        ("ek-egc", (180, 30, 90)),
        ("assist", VIA_ORANGE),
        ("dwa", (100, 60, 160)),
        ("cbf", CBF_TEAL),
        ("sweep", AGC_VIOLET),
        ("limits", (120, 160, 220)),
        ("watchdog", _AMBER),
        ("hold", _AMBER),
        ("estop", (140, 0, 0)),
        ("latency", LATENCY_BROWN),
    ),
    "filter": (
        ("none", _GREY),
        ("egc", SENT_RED),
        ("ek-egc", (180, 30, 90)),
        ("assist", VIA_ORANGE),
        ("dwa", (100, 60, 160)),
        ("cbf", CBF_TEAL),
        ("unknown", (120, 120, 120)),
    ),
    "region": tuple(REGION_COLOURS.items()),
}


def _lane_value(t: Telemetry, lane: str) -> str:
    if lane == "filter":
        return t.filter or "unknown"  # an older robot does not say
    return str(getattr(t, lane))


def status_changes(previous: Telemetry | None, t: Telemetry) -> dict[str, str]:
    """The status lanes (state, mode, filter, limiter, region) that differ from ``previous``."""
    now = {lane: _lane_value(t, lane) for lane in STATUS_LANES}
    if previous is None:
        return now
    return {lane: v for lane, v in now.items() if _lane_value(previous, lane) != v}


# ---------------------------------------------------------------------------------------------
# Via points (DESIGN 7 goal) in the world frame, the suggested direction in {R}.


@dataclass(frozen=True, slots=True)
class ViaScene:
    """What the world-frame view draws for the via points (world frame, metres)."""

    active: Point | None  # the robot's active via point (telemetry ``goal``)
    active_label: str
    others: list[Point]  # the operator's other route points
    other_colours: list[Rgb]  # grey: passed; orange: still ahead (or unknown)
    route: list[Point]  # the robot's pose, the active point, then those ahead

    @property
    def empty(self) -> bool:
        return self.active is None and not self.others


NO_VIA = ViaScene(None, "", [], [], [])


def via_scene(
    route_points: tuple[Point, ...], route_frame: str | None, t: Telemetry | None
) -> ViaScene:
    """The via points to draw from the operator's route (may be empty: a view that was not
    told, e.g. a headless episode) and the robot's echo in the newest telemetry.

    With the route known and the echo of it, the points before the active one are passed and
    those after it ahead; without the echo (route done, or not accepted yet) the route is drawn
    as it is; without the route, the active point alone, with how many follow.
    """
    goal = None if t is None else t.goal
    pose = None if t is None or t.pose is None else (t.pose[0], t.pose[1])
    index = None
    if goal is not None and t is not None and route_frame is not None and route_points:
        route = Route(route_frame, route_points)
        index = active_index(route, goal, t.goal_frame, t.goals_left)
    if goal is None or t is None:
        others = list(route_points)
        return ViaScene(None, "", others, [VIA_ORANGE] * len(others), others)
    frame = "" if t.goal_frame in (None, "odom") else f", {t.goal_frame}"
    if index is None:
        more = f", {t.goals_left} more" if t.goals_left else ""
        label = f"via point (active{frame}){more}"
        return ViaScene(goal, label, [], [], [*([pose] if pose else []), goal])
    passed, ahead = list(route_points[:index]), list(route_points[index + 1 :])
    label = f"via {index + 1}/{len(route_points)} (active{frame})"
    return ViaScene(
        goal,
        label,
        passed + ahead,
        [VIA_PASSED_GREY] * len(passed) + [VIA_ORANGE] * len(ahead),
        [*([pose] if pose else []), goal, *ahead],
    )


def suggested_vector(t: Telemetry, length_m: float = SUGGESTED_LENGTH_M) -> Point | None:
    """The filter's suggested direction (``suggested_rad`` in {R}) as an arrow, or None."""
    a = t.suggested_rad
    if a is None or not math.isfinite(a):
        return None
    return length_m * math.cos(a), length_m * math.sin(a)


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


# ---------------------------------------------------------------------------------------------
# Predictive display (DESIGN 9): drawn in the world frame, dashed.

DASH_M = 0.06
GAP_M = 0.04


def dashed(points: list[Point], dash_m: float = DASH_M, gap_m: float = GAP_M) -> list[list[Point]]:
    """A polyline cut into dashes of ``dash_m`` with gaps of ``gap_m`` (each dash a strip).

    The pattern runs on along the whole polyline (it does not restart at every vertex); a dash
    that crosses a vertex bends with it.
    """
    if not (dash_m > 0 and gap_m >= 0):
        raise ValueError("dash_m must be > 0 and gap_m >= 0")
    period = dash_m + gap_m
    dashes: list[list[Point]] = []
    current: list[Point] = []
    s = 0.0  # arc length travelled so far
    for (x0, y0), (x1, y1) in itertools.pairwise(points):
        length = math.hypot(x1 - x0, y1 - y0)
        if length == 0.0:
            continue
        a = 0.0  # position along this segment
        while a < length:
            phase = (s + a) % period
            drawing = phase < dash_m
            step = (dash_m - phase) if drawing else (period - phase)
            b = min(length, a + max(step, 1e-12))
            if drawing:
                start = (x0 + (x1 - x0) * a / length, y0 + (y1 - y0) * a / length)
                end = (x0 + (x1 - x0) * b / length, y0 + (y1 - y0) * b / length)
                if not current:
                    current.append(start)
                current.append(end)
            elif current:
                dashes.append(current)
                current = []
            a = b
        s += length
    if len(current) >= 2:
        dashes.append(current)
    return dashes


def footprint_corners(pose: tuple[float, float, float], profile: RobotProfile) -> list[Point]:
    """The footprint at ``pose`` in the world frame, closed (a rectangle: 5 points, front-left
    first; any polygon or disc: its outline)."""
    x, y, th = pose
    c, s = math.cos(th), math.sin(th)
    return [(x + c * px - s * py, y + s * px + c * py) for px, py in footprint_outline(profile)]


@dataclass(frozen=True, slots=True)
class GhostScene:
    """The predicted footprint, its heading and the path to it, in the world frame (metres)."""

    footprint: list[list[Point]]  # dashes
    heading_origin: Point
    heading_vector: Point
    path: list[list[Point]]  # dashes, from the measured pose to the predicted one
    label: str


def ghost_scene(prediction: Prediction, profile: RobotProfile) -> GhostScene:
    """What the world-frame view draws for one prediction."""
    x, y, th = prediction.pose
    ahead = (prediction.end_ns - prediction.start_ns) / 1e9
    return GhostScene(
        footprint=dashed(footprint_corners(prediction.pose, profile)),
        heading_origin=(x, y),
        heading_vector=(  # to the front of the footprint
            profile.footprint.bounds[1] * math.cos(th),
            profile.footprint.bounds[1] * math.sin(th),
        ),
        path=dashed([(px, py) for px, py, _ in prediction.path]),
        label=f"{PREDICTED_LABEL}, +{ahead:.2f} s",
    )


def _ms(value: float | None, approx: bool = False) -> str:
    if value is None:
        return "--"
    return f"{'~' if approx else ''}{value:.0f} ms"


STALE_GREY = (120, 120, 120)


def is_stale(telemetry_age_s: float | None, robot_present: bool) -> bool:
    """The newest telemetry is not the robot now: its liveliness token is gone, or nothing
    came for longer than ``TELEMETRY_STALE_S`` (a few telemetry periods)."""
    return not robot_present or (
        telemetry_age_s is not None and telemetry_age_s > TELEMETRY_STALE_S
    )


def stale_texts(telemetry_age_s: float | None, robot_present: bool) -> tuple[str, str]:
    """(robot-frame status, link panel) while the telemetry is stale: no prediction and no
    link figures are shown from it (DESIGN 9: never a prediction as if it were a measurement),
    only how old the view is."""
    why = (
        "robot or link silent"
        if robot_present
        else "robot gone: its session ended or the link dropped"
    )
    age = "" if telemetry_age_s is None else f" for {telemetry_age_s:.1f} s"
    head = f"NO TELEMETRY{age} ({why})"
    old = "" if telemetry_age_s is None else f", {telemetry_age_s:.1f} s old,"
    status = f"{head} · this view is the robot's last telemetry{old} not the robot now"
    panel = (
        f"{head}\n"
        f"link figures: none current (the last ones{old} are not shown)\n"
        "ghost: none (no fresh telemetry to predict from)"
    )
    return status, panel


def link_text(
    uplink_ms: float | None,
    uplink_from_rtt: bool,
    downlink_ms: float | None,
    view_age_ms: float | None,
    t: Telemetry | None,
    prediction: Prediction | None,
) -> str:
    """The link figures in plain numbers, then what the ghost is (the view's link panel).

    e.g. ``uplink 210 ms, downlink ~200 ms, view age 230 ms, loop delay 0.76 s, gap max 40 ms,
    loss 0.0 %``. The uplink is the robot's median command age, or half the clock-sync round
    trip (marked ``~ (rtt/2)``) before the robot reports one; the downlink is the median age of
    the telemetry on arrival (``~``: the clock-sync error is in it).
    """
    uplink = _ms(uplink_ms, approx=uplink_from_rtt) + (" (rtt/2)" if uplink_from_rtt else "")
    parts = [f"uplink {uplink}", f"downlink {_ms(downlink_ms, approx=True)}"]
    parts.append(f"view age {_ms(view_age_ms)}")
    loop = None if t is None else t.loop_delay_ms
    parts.append("loop delay --" if loop is None else f"loop delay {loop / 1000.0:.2f} s")
    parts.append(f"gap max {_ms(None if t is None else t.cmd_gap_max_ms)}")
    loss = None if t is None else t.link_loss
    parts.append("loss --" if loss is None else f"loss {100.0 * loss:.1f} %")
    lines = [", ".join(parts)]
    if t is not None and (t.cmd_age_p50_ms is not None or t.cmd_age_p90_ms is not None):
        lines.append(
            f"command age on arrival p50 {_ms(t.cmd_age_p50_ms)}, p90 {_ms(t.cmd_age_p90_ms)}"
        )
    if t is not None and t.limiter == "latency":
        cap = latency_cap_text(t.v_lim_latency, t.w_lim_latency)
        lines.append(f"limit: latency - speed capped{cap}")
    view_plane = view_plane_text(t)  # DESIGN 12: the same text as the status line's
    if view_plane is not None:
        lines.append(f"view plane: {view_plane}")
    if prediction is None:
        lines.append("ghost: no prediction (no pose, unknown profile or clock not synced)")
    else:
        ahead = (prediction.end_ns - prediction.start_ns) / 1e9
        clamped = " (cut at the horizon)" if prediction.clamped else ""
        stops = ", the robot stops" if prediction.stopping else ""
        lines.append(
            f"ghost (dashed magenta): {PREDICTED_LABEL}, +{ahead:.2f} s{clamped}: "
            f"where the command sent now takes effect{stops}"
        )
        if ahead >= STEER_BY_GHOST_S:
            lines.append(f"the robot drawn solid is {ahead:.1f} s behind: steer by the ghost")
    return "\n".join(lines)
