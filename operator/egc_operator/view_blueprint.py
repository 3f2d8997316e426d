"""Where the operator view logs things (entity paths, timelines) and its default layout.

Layout (paper Fig. 8 as a Rerun blueprint)::

    +---------------------------+----------------------+------------------+
    |                           | camera, its age      | v: ref vs sent   |
    | robot frame {R}           +----------------------+                  |
    |                           | world frame          |                  |
    | scan, footprint, circles, | map, trajectory,     | w: ref vs sent   |
    | command arrows, suggested | goal, via points,    | w_SI             |
    | direction, status         | robot, ghost         |                  |
    +---------------------------+----------------------+ latency          |
    | state / mode / filter /   | link figures         |                  |
    | limiter / region lanes    +----------------------+                  |
    |                           | text log             |                  |
    +---------------------------+----------------------+------------------+

An operator driving a fleet (DESIGN 15, ``fleet=True``) gets a fleet panel beside the driven
robot's view, under the world frame: every robot's state, who controls it and its link figures
(``FLEET_TABLE``), and snapshots of the other robots' cameras in a row (``FLEET_CAMERAS``,
``fleet_thumbnails``); the robots that share the driven robot's map frame are drawn in the
world frame at their map poses (``FLEET_POSES``, from their state messages at 1 Hz).

The world frame shows the newest state of everything (latest-at) except the trajectory, which
shows its whole history up to the time cursor; the ghost (the predictive display, DESIGN 9) is
its own latest row only.

Two timelines carry every row logged from telemetry: ``robot_time`` (a duration: the robot's
monotonic clock, ``Telemetry.stamp_ns``) and ``cycle`` (a sequence: the robot's control cycle,
``Telemetry.cycle``). The robot's black box uses the same two, so the recordings line up.
"""

from __future__ import annotations

import rerun.blueprint as rrb

ROBOT_TIME = "robot_time"
CYCLE = "cycle"

# Robot-frame view: ``robot`` carries the {R} -> screen transform, children are in {R}.
ROBOT = "robot"
SCAN = "robot/scan"
FOOTPRINT = "robot/footprint"
STATUS = "robot/status"
CIRCLES = "robot/circles"  # + /reachable, /igc, /agc, /egc
REFERENCE_ARROW = "robot/command/reference"
SENT_ARROW = "robot/command/sent"
SUGGESTED_ARROW = "robot/suggested"  # the filter's suggested direction (assist), in {R}
CBF_MARGIN = "robot/cbf/margin"  # cbf's margin around the footprint (DESIGN 13), in {R}
CBF_POINTS = "robot/cbf/points"  # the points whose barriers changed the command
ROBOT_VIA = "robot/via"  # the active via point seen from the robot (odom frame only)

# World-frame view: ``world`` carries the world -> screen transform.
WORLD = "world"
MAP = "world/map"
GOAL = "world/goal"
TRAJECTORY = "world/trajectory"
ROBOT_POSE = "world/robot"  # Transform3D per cycle; its children are static, in {R}
POSE_FOOTPRINT = "world/robot/footprint"
# Via points (DESIGN 7 goal), in the world frame.
VIA = "world/via"
VIA_ACTIVE = "world/via/active"
VIA_POINTS = "world/via/points"
VIA_ROUTE = "world/via/route"
# Predictive display (DESIGN 9), in world coordinates: never children of ``world/robot``.
PREDICTED = "world/predicted"
PREDICTED_FOOTPRINT = "world/predicted/footprint"
PREDICTED_HEADING = "world/predicted/heading"
PREDICTED_PATH = "world/predicted/path"
LINK_TEXT = "link"  # TextDocument: the link figures in plain numbers
# The robot's camera (DESIGN 12): the newest frame (JPEG) and its age, in image pixels.
CAMERA = "camera"
CAMERA_IMAGE = "camera/image"
CAMERA_AGE = "camera/age"

# The fleet (DESIGN 15): a table of every robot, and the others' poses on the driven one's map.
FLEET = "fleet"
FLEET_TABLE = "fleet/table"
FLEET_POSES = "world/fleet"
FLEET_CAMERAS = "fleet/cameras"  # + /<robot>: the other robots' camera snapshots, in a row

PLOTS = "plots"  # + /v/ref, /v/cmd, /w/ref, /w/cmd, /w_si, /latency/...
LINK_RTT = "plots/latency/link_rtt_ms"
LANES = "status"  # + /state, /mode, /filter, /limiter, /region
TEXT_LOG = "log"


def circle_path(name: str) -> str:
    return f"{CIRCLES}/{name}"


def plot_path(name: str) -> str:
    return f"{PLOTS}/{name}"


def lane_path(name: str) -> str:
    return f"{LANES}/{name}"


def _whole_history() -> list[rrb.VisibleTimeRange]:
    """Show everything up to the time cursor (the trajectory is logged one segment per row)."""
    return [
        rrb.VisibleTimeRange(
            timeline,
            start=rrb.TimeRangeBoundary.infinite(),
            end=rrb.TimeRangeBoundary.cursor_relative(),
        )
        for timeline in (ROBOT_TIME, CYCLE, "log_time")
    ]


def operator_blueprint(
    robot_id: str,
    view_radius_m: float = 3.0,
    world_bounds_m: tuple[float, float, float, float] | None = None,
    fleet: bool = False,
) -> rrb.Blueprint:
    """The default layout; ``view_radius_m`` frames the robot-frame view (forward is up).

    ``world_bounds_m`` (x_min, x_max, y_min, y_max in the world frame) frames the world view;
    by default it shows everything logged there (the whole map). ``fleet``: the layout of an
    operator driving a fleet (the fleet panel; the robot frame is the driven robot's).
    """
    r = view_radius_m
    world_bounds = None
    if world_bounds_m is not None:
        x0, x1, y0, y1 = world_bounds_m
        # Screen coordinates: x = x_W, y = -y_W (north up).
        world_bounds = rrb.VisualBounds2D(x_range=[x0, x1], y_range=[-y1, -y0])
    who = "driven robot" if fleet else robot_id
    robot_view = rrb.Spatial2DView(
        name=f"{who}: robot frame, forward up (blue: operator, initial GC; red: sent, expanded GC)",
        origin="/",
        contents=f"{ROBOT}/**",
        # Screen coordinates: x = -y_R, y = -x_R; show more ahead than behind.
        visual_bounds=rrb.VisualBounds2D(x_range=[-r, r], y_range=[-1.5 * r, 0.5 * r]),
    )
    world_view = rrb.Spatial2DView(
        name="world frame (dashed magenta: predicted, not measured)",
        origin="/",
        contents=f"{WORLD}/**",
        visual_bounds=world_bounds,
        # Latest-at for the robot and the ghost; the trajectory's segments accumulate.
        overrides={TRAJECTORY: rrb.VisibleTimeRanges(_whole_history())},
    )
    plots = rrb.Vertical(
        rrb.TimeSeriesView(name="v (m/s): reference vs sent", origin=f"{PLOTS}/v"),
        rrb.TimeSeriesView(name="w (rad/s): reference vs sent", origin=f"{PLOTS}/w"),
        rrb.TimeSeriesView(
            name="w_SI (safety index)",
            origin=plot_path("w_si"),
            axis_y=rrb.ScalarAxis(range=(0.0, 1.05)),
        ),
        rrb.TimeSeriesView(name="latency (ms)", origin=f"{PLOTS}/latency"),
    )
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                robot_view,
                rrb.StateTimelineView(name="state, mode, filter, limiter, region", origin=LANES),
                row_shares=[3, 1],
            ),
            rrb.Vertical(
                rrb.Spatial2DView(
                    name="camera (newest frame, age on the robot's clock)", origin=CAMERA
                ),
                world_view,
                *(
                    [
                        rrb.TextDocumentView(name="fleet: every robot seen", origin=FLEET_TABLE),
                        rrb.Spatial2DView(
                            name="fleet: the other robots' camera snapshots",
                            origin=FLEET_CAMERAS,
                        ),
                    ]
                    if fleet
                    else []
                ),
                rrb.TextDocumentView(name="link (plain numbers)", origin=LINK_TEXT),
                rrb.TextLogView(name="log: state changes, rejections, link", origin=TEXT_LOG),
                row_shares=[4, 4, 2, 2, 2, 2] if fleet else [4, 4, 2, 2],
            ),
            plots,
            column_shares=[4, 3, 3],
        ),
        rrb.TimePanel(timeline=ROBOT_TIME, state="collapsed"),
        collapse_panels=True,
    )
