"""The pure half of the ROS 2 driver (DESIGN 11): REP 117 scans, laser pose, settings, odometry.

No rclpy here: these run everywhere.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from egc_common.messages import Odometry
from egc_common.profiles import get_profile
from egc_common.scan import Scan, blind_sectors, footprint_exit_m, seen_along_axis_m
from egc_robot.pipeline import PipelineConfig, step_command
from egc_robot.ros2_core import (
    LaserPose,
    Rejected,
    Ros2Settings,
    blind_directions,
    cmd_topic_warning,
    odometry_from_ros,
    parse_laser_pose,
    quaternion_from_yaw,
    ros2_settings,
    scan_from_laser,
    unseen_directions,
    yaw_from_quaternion,
)
from hypothesis import given
from hypothesis import strategies as st

INF = math.inf
NAN = math.nan
HERE = LaserPose()


def points(result: Scan | Rejected) -> np.ndarray:
    assert isinstance(result, Scan), result
    return result.points()


def test_plus_inf_is_free_and_still_information():
    scan = scan_from_laser([INF] * 8, -math.pi, math.pi / 4, 0.1, 10.0, HERE)
    assert isinstance(scan, Scan)
    assert len(scan.points()) == 0
    assert scan.no_return_is_free


def test_nan_everywhere_is_no_information():
    result = scan_from_laser([NAN] * 8, -math.pi, math.pi / 4, 0.1, 10.0, HERE)
    assert isinstance(result, Rejected) and result.reason == "no_information"


def test_finite_out_of_range_is_dropped_and_not_information():
    # An older driver's "no return" codes: 0.0 and range_max + 1.
    result = scan_from_laser([0.0, 11.0, 0.05], 0.0, 0.1, 0.1, 10.0, HERE)
    assert isinstance(result, Rejected) and result.reason == "no_information"
    p = points(scan_from_laser([0.0, 11.0, 2.0], 0.0, 0.5, 0.1, 10.0, HERE))
    np.testing.assert_allclose(p, [[2.0 * math.cos(1.0), 2.0 * math.sin(1.0)]])


def test_minus_inf_is_an_obstacle_at_range_min():
    p = points(scan_from_laser([NAN, -INF, INF], -0.1, 0.1, 0.25, 10.0, HERE))
    np.testing.assert_allclose(p, [[0.25, 0.0]], atol=1e-12)


def test_no_beams_is_no_information():
    assert isinstance(scan_from_laser([], 0.0, 0.1, 0.1, 10.0, HERE), Rejected)


def test_negative_increment_gives_the_same_points_as_the_forward_sweep():
    rng = np.random.default_rng(3)
    ranges = rng.uniform(0.2, 5.0, 271)
    inc = math.radians(1.0)
    forward = points(scan_from_laser(ranges, -math.radians(135), inc, 0.1, 10.0, HERE))
    backward = points(scan_from_laser(ranges[::-1], math.radians(135), -inc, 0.1, 10.0, HERE))
    order = lambda p: p[np.lexsort((p[:, 1], p[:, 0]))]  # noqa: E731
    np.testing.assert_allclose(order(forward), order(backward[::-1]), atol=1e-9)


@pytest.mark.parametrize("beams", [1, 2, 7, 360, 1081, 4000])
def test_any_beam_count_and_angular_range(beams):
    span = 4.7 if beams > 1 else 0.0
    inc = span / max(beams - 1, 1)
    p = points(scan_from_laser(np.full(beams, 2.0), -span / 2, inc, 0.1, 10.0, HERE))
    assert len(p) == beams
    np.testing.assert_allclose(np.hypot(p[:, 0], p[:, 1]), 2.0)


def test_laser_pose_turns_and_offsets_the_points():
    # A laser 0.2 m behind the centre, looking backwards: 1 m straight ahead of the laser is
    # 1.2 m behind the robot's centre; its left is the robot's right.
    pose = LaserPose(-0.2, 0.0, math.pi)
    p = points(scan_from_laser([1.0, 1.0], 0.0, math.pi / 2, 0.1, 10.0, pose))
    np.testing.assert_allclose(p, [[-1.2, 0.0], [-0.2, -1.0]], atol=1e-12)


def test_upside_down_mirrors_the_laser_sweep():
    # Upside down, the laser's left (+90 deg) is the robot's right.
    up = points(scan_from_laser([1.0], math.pi / 2, 0.1, 0.1, 10.0, LaserPose(0.1, 0.05, 0.0)))
    down = points(
        scan_from_laser([1.0], math.pi / 2, 0.1, 0.1, 10.0, LaserPose(0.1, 0.05, 0.0, True))
    )
    np.testing.assert_allclose(up, [[0.1, 1.05]], atol=1e-12)
    np.testing.assert_allclose(down, [[0.1, -0.95]], atol=1e-12)


@pytest.mark.parametrize(
    ("args", "reason"),
    [
        ((0.0, 0.1, 2.0, 1.0), "range_min > range_max"),
        ((0.0, 0.1, -1.0, 1.0), "negative range_min"),
        ((NAN, 0.1, 0.1, 1.0), "NaN angle_min"),
        ((0.0, INF, 0.1, 1.0), "inf increment"),
        ((0.0, 0.1, 0.1, INF), "inf range_max"),
        ((0.0, 1e300, 0.1, 1.0), "angles overflow"),
    ],
)
def test_malformed_scans_are_rejected(args, reason):
    result = scan_from_laser([1.0, 1.0, 1.0], *args, HERE)
    assert isinstance(result, Rejected) and result.reason == "malformed", reason


def test_too_many_beams_and_non_numbers_are_rejected():
    assert isinstance(scan_from_laser(np.ones(200_000), 0.0, 1e-5, 0.1, 10.0, HERE), Rejected)
    assert isinstance(scan_from_laser(["a", "b"], 0.0, 0.1, 0.1, 10.0, HERE), Rejected)


@given(
    ranges=st.lists(st.floats(allow_nan=True, allow_infinity=True, width=32), max_size=50),
    angle_min=st.floats(allow_nan=True, allow_infinity=True),
    inc=st.floats(allow_nan=True, allow_infinity=True),
    range_min=st.floats(allow_nan=True, allow_infinity=True),
    range_max=st.floats(allow_nan=True, allow_infinity=True),
    upside_down=st.booleans(),
)
def test_any_input_gives_a_scan_or_a_rejection(
    ranges, angle_min, inc, range_min, range_max, upside_down
):
    result = scan_from_laser(
        ranges, angle_min, inc, range_min, range_max, LaserPose(0.1, 0.0, 1.0, upside_down)
    )
    assert isinstance(result, (Scan, Rejected))
    if isinstance(result, Scan):
        p = result.points()
        assert np.all(np.isfinite(p))
        # Every point is within range_max of the laser (at most range_max from its mount).
        assert np.all(np.hypot(p[:, 0] - 0.1, p[:, 1]) <= range_max * (1 + 1e-9))


def test_a_minus_inf_reading_ahead_stops_forward_motion_in_shared_mode():
    """No forward motion into -inf: an object closer than range_min ahead is an obstacle."""
    config = PipelineConfig(get_profile("pioneer3dx"), no_return_is_free=True)
    ranges = np.full(360, INF)
    ranges[178:183] = -INF  # straight ahead
    scan = scan_from_laser(ranges, -math.pi, 2 * math.pi / 360, 0.2, 10.0, HERE)
    assert isinstance(scan, Scan)
    out = step_command(config, 1.0, 0.0, "shared", scan.obstacles(), (0.14, 0.0), 0.05)
    assert out.v_cmd_mps <= 0.0, out
    # The same scan with +inf there instead lets it drive on.
    free = scan_from_laser(np.full(360, INF), -math.pi, 2 * math.pi / 360, 0.2, 10.0, HERE)
    assert isinstance(free, Scan)
    out = step_command(config, 1.0, 0.0, "shared", free.obstacles(), (0.14, 0.0), 0.05)
    assert out.v_cmd_mps == pytest.approx(0.14)


# -- settings -----------------------------------------------------------------------------------


def test_settings_defaults_are_the_pinned_ones():
    s = ros2_settings({}, {})
    assert (s.scan_topic, s.odom_topic, s.cmd_topic, s.cmd_type) == (
        "/scan",
        "/odom",
        "/cmd_vel",
        "twist",
    )
    assert s.namespace == "" and s.laser == LaserPose()


def test_flags_override_the_toml_table():
    table = {"scan": "base_scan", "laser_pose": [0.1, 0.0, 3.0], "cmd_type": "twist-stamped"}
    flags = {"scan": "/front/scan", "laser_pose": "-0.12,0.5,-3.14", "laser_upside_down": True}
    s = ros2_settings(table, flags | {"odom": None})
    assert s.scan_topic == "/front/scan" and s.cmd_type == "twist-stamped"
    assert s.laser == LaserPose(-0.12, 0.5, -3.14, True)
    assert s.odom_topic == "/odom"


@pytest.mark.parametrize(
    ("table", "message"),
    [
        ({"scna": "/scan"}, "unknown [ros2] key"),
        ({"scan": "has space"}, "not a valid ROS 2 topic"),
        ({"cmd": 3}, "must be a string"),
        ({"cmd_type": "twist_stamped"}, "cmd_type"),
        ({"namespace": "robot1/"}, "namespace"),
        ({"laser_pose": "1,2"}, "X,Y,YAW"),
        ({"laser_pose": [1, 2, "x"]}, "laser_pose"),
        ({"laser_pose": "nan,0,0"}, "X,Y,YAW"),
        ({"laser_upside_down": "yes"}, "true or false"),
    ],
)
def test_bad_settings_name_the_key(table, message):
    with pytest.raises(ValueError, match=message.replace("[", r"\[")):
        ros2_settings(table, {})


def test_namespaces_and_relative_topics_are_accepted():
    s = Ros2Settings(scan_topic="front/scan", namespace="/robot1")
    assert s.namespace == "/robot1"
    assert Ros2Settings(namespace="robot1").namespace == "/robot1"  # as rclpy takes it


def test_a_namespace_moves_the_default_topics_into_it():
    """``--ros-namespace /robot1`` alone listens on /robot1/scan (the defaults become relative);
    a topic given explicitly stays as given."""
    s = ros2_settings({}, {"namespace": "/robot1"})
    assert (s.scan_topic, s.odom_topic, s.cmd_topic) == ("scan", "odom", "cmd_vel")
    s = ros2_settings({"namespace": "robot1"}, {"scan": "/front/scan"})
    assert (s.namespace, s.scan_topic, s.odom_topic) == ("/robot1", "/front/scan", "odom")
    assert ros2_settings({}, {"namespace": "/"}).scan_topic == "/scan"


def test_parse_laser_pose_takes_negative_numbers():
    assert parse_laser_pose("-0.1,-0.05,-3.14159") == (-0.1, -0.05, -3.14159)


# -- odometry -----------------------------------------------------------------------------------


@pytest.mark.parametrize("yaw", [0.0, 1.0, -2.5, math.pi - 1e-9])
def test_yaw_quaternion_round_trip(yaw):
    assert yaw_from_quaternion(*quaternion_from_yaw(yaw)) == pytest.approx(yaw)


def test_odometry_is_stamped_with_arrival_and_checked():
    odo = odometry_from_ros(1.0, -2.0, quaternion_from_yaw(0.5), 0.3, -0.1, 123)
    assert odo == Odometry(
        stamp_ns=123,
        x_m=1.0,
        y_m=-2.0,
        theta_rad=pytest.approx(0.5),
        linear_mps=0.3,
        angular_radps=-0.1,
    )
    assert isinstance(odometry_from_ros(NAN, 0.0, (0, 0, 0, 1), 0.0, 0.0, 1), Rejected)
    assert isinstance(odometry_from_ros(0.0, 0.0, (0, 0, 0, 0), 0.0, 0.0, 1), Rejected)


# -- -inf beyond the footprint: the object may be anywhere nearer than range_min ---------------

HALF = (0.2275, 0.1905)  # the Pioneer 3-DX's footprint, half length and width


def test_the_footprint_exit_of_a_beam():
    ahead, left, diagonal = footprint_exit_m(np.array([0.0, math.pi / 2, math.pi / 4]), 0, 0, *HALF)
    assert (ahead, left) == pytest.approx(HALF)
    assert diagonal == pytest.approx(HALF[1] / math.sin(math.pi / 4))
    assert footprint_exit_m(np.array([0.0]), 0.1, 0.0, *HALF)[0] == pytest.approx(0.1275)
    assert footprint_exit_m(np.array([0.0]), 0.5, 0.0, *HALF)[0] == 0.0  # a laser outside it


def test_minus_inf_beyond_the_footprint_adds_a_point_at_its_edge():
    """range_min 0.6 m: the object is somewhere nearer than 0.6 m and the reading stays -inf
    however close it comes, so the nearest place it may be counts too."""
    scan = scan_from_laser([INF, -INF, INF], -0.1, 0.1, 0.6, 10.0, HERE, footprint_half_m=HALF)
    np.testing.assert_allclose(points(scan), [[0.6, 0.0], [HALF[0] + 0.001, 0.0]], atol=1e-12)
    plain = scan_from_laser([INF, -INF, INF], -0.1, 0.1, 0.6, 10.0, HERE)
    np.testing.assert_allclose(points(plain), [[0.6, 0.0]], atol=1e-12)  # DESIGN 11's point
    inside = scan_from_laser([-INF], 0.0, 0.1, 0.1, 10.0, HERE, footprint_half_m=HALF)
    np.testing.assert_allclose(points(inside), [[0.1, 0.0]], atol=1e-12)  # the robot itself


@pytest.mark.parametrize("profile_name", ["pioneer3dx", "jackal"])
@pytest.mark.parametrize("filter_name", ["egc", "ek-egc", "assist", "dwa", "cbf"])
def test_no_filter_drives_on_into_minus_inf_readings_beyond_the_footprint(
    filter_name, profile_name
):
    """The ROS 2 verifier's case: a wall 0.5 m from the laser, range_min 0.6 m, stick forward.
    With the point at range_min alone the Jackal drove into the wall at 1 m/s (every filter
    sent 0.1 m/s here; assist and dwa on the Pioneer too)."""
    profile = get_profile(profile_name)
    ranges = np.full(360, INF)
    ranges[150:211] = -INF  # +-30 deg ahead: closer than range_min
    half = profile.half_size_m
    scan = scan_from_laser(ranges, -math.pi, math.pi / 180, 0.6, 10.0, HERE, footprint_half_m=half)
    assert isinstance(scan, Scan)
    cfg = PipelineConfig(profile, filter=filter_name)
    forward = step_command(cfg, 1.0, 0.0, "shared", scan.obstacles(), (0.0, 0.0), 0.05)
    assert forward.v_cmd_mps <= 0.0, forward
    back = step_command(cfg, -1.0, 0.0, "shared", scan.obstacles(), (0.0, 0.0), 0.05)
    assert back.v_cmd_mps < 0.0, back  # backing away from it is still allowed


def test_blind_directions_of_a_laser():
    full = -math.pi + 2 * math.pi / 360 * np.arange(360)
    assert blind_directions(full) == []
    front_270 = np.linspace(-0.75 * math.pi, 0.75 * math.pi, 1081)
    assert blind_directions(front_270) == ["behind"]
    assert blind_directions(front_270 + math.pi) == ["ahead"]  # mounted backwards
    assert blind_directions(np.linspace(-0.5, 0.5, 100)) == ["left", "behind", "right"]
    assert blind_directions([0.0]) == ["ahead", "left", "behind", "right"]


def _ranges_to_post(
    pose: tuple[float, float, float],
    mount: tuple[float, float],
    angles: np.ndarray,
    post: tuple[float, float, float],
    range_min_m: float,
) -> np.ndarray:
    """A laser at ``mount`` in {R} of a robot at ``pose`` sees one round post: REP 117 ranges
    (``-inf`` nearer than range_min, ``+inf`` for no return)."""
    x, y, th = pose
    px = x + mount[0] * math.cos(th) - mount[1] * math.sin(th)
    py = y + mount[0] * math.sin(th) + mount[1] * math.cos(th)
    cx, cy, r = post
    dx, dy = np.cos(th + angles), np.sin(th + angles)
    ox, oy = px - cx, py - cy
    b = ox * dx + oy * dy
    disc = b * b - (ox * ox + oy * oy - r * r)
    with np.errstate(invalid="ignore"):
        t = -b - np.sqrt(disc)
    hit = (disc >= 0) & (t > 0)
    ranges = np.where(hit, t, INF)
    ranges[hit & (t < range_min_m)] = -INF
    return ranges


def _settled(before: tuple, after: tuple) -> bool:
    """The closed loop reached a fixed point: the pose and the command came out bit for bit as
    they went in. The next cycle's ranges depend on the pose alone and ``step_command`` (no
    memory, no clock) on its inputs alone, so every later cycle would repeat this one exactly:
    the loop may end here without leaving a state unchecked."""
    flat = lambda t: tuple(float(v).hex() for part in t for v in part)  # noqa: E731
    return flat(before) == flat(after)


def _gap_to_footprint(pose, post, half) -> float:
    x, y, th = pose
    cx, cy, r = post
    dx, dy = cx - x, cy - y
    lx = dx * math.cos(th) + dy * math.sin(th)
    ly = -dx * math.sin(th) + dy * math.cos(th)
    return math.hypot(max(abs(lx) - half[0], 0.0), max(abs(ly) - half[1], 0.0)) - r


@pytest.mark.parametrize("filter_name", ["egc", "ek-egc", "assist", "dwa", "cbf"])
@pytest.mark.parametrize("post_x_m", [0.9, 1.9])  # -inf from the start; seen first, then -inf
@pytest.mark.parametrize(
    "mount, y_o",
    [
        ((0.15, 0.0), 0.0),  # inside the footprint
        ((0.30, 0.0), 0.0),  # 4.6 cm beyond the Jackal's front edge (outside verifier, 4 of 4)
        ((0.30, 0.10), 0.0),
        ((0.30, 0.0), 0.3),  # turning left into it
    ],
)
def test_a_stick_held_forward_never_drives_into_a_post_seen_as_minus_inf(
    mount, y_o, post_x_m, filter_name
):
    """Closed loop: a fake base that does exactly what it is told, a laser with a 1 m range_min,
    a post ahead. Once the post is nearer than range_min every beam on it reads -inf and keeps
    reading -inf however close the robot comes; the points at range_min and any point that
    moves with the laser (the old one for a laser outside the footprint sat 1 mm from the
    laser, 4.6 cm ahead of the bumper forever) let the robot creep on into it."""
    profile = get_profile("jackal")
    half = profile.half_size_m
    cfg = PipelineConfig(profile, filter=filter_name)
    angles = -math.pi + 2 * math.pi / 720 * np.arange(720)
    post = (post_x_m, 0.0, 0.2)
    pose, cmd, dt = (0.0, 0.0, 0.0), (0.0, 0.0), 0.05
    laser = LaserPose(*mount)
    for _ in range(160):
        before = (pose, cmd)
        ranges = _ranges_to_post(pose, mount, angles, post, 1.0)
        scan = scan_from_laser(ranges, -math.pi, 2 * math.pi / 720, 1.0, 10.0, laser, 0, half)
        assert isinstance(scan, Scan)
        out = step_command(cfg, 1.0, y_o, "shared", scan.obstacles(), cmd, dt)
        cmd = (out.v_cmd_mps, out.w_cmd_radps)
        x, y, th = pose
        pose = (x + cmd[0] * dt * math.cos(th), y + cmd[0] * dt * math.sin(th), th + cmd[1] * dt)
        assert _gap_to_footprint(pose, post, half) > 0.0, (pose, cmd)
        if _settled(before, (pose, cmd)):
            break


def test_the_command_topic_warning_names_the_type_the_base_wants():
    stamped, plain = "geometry_msgs/msg/TwistStamped", "geometry_msgs/msg/Twist"
    assert cmd_topic_warning("/cmd_vel", "twist", [plain]) is None
    assert cmd_topic_warning("/cmd_vel", "twist", [stamped, plain]) is None
    assert cmd_topic_warning("/cmd_vel", "twist-stamped", [stamped]) is None
    wrong = cmd_topic_warning("/cmd_vel", "twist", [stamped])
    assert wrong is not None and "--ros-cmd-type twist-stamped" in wrong and stamped in wrong
    back = cmd_topic_warning("/r1/cmd_vel", "twist-stamped", [plain])
    assert back is not None and "--ros-cmd-type twist" in back and "/r1/cmd_vel" in back
    odd = cmd_topic_warning("/cmd_vel", "twist", ["std_msgs/msg/String"])
    assert odd is not None and "--ros-cmd-type" not in odd
    nobody = cmd_topic_warning("/cmd_vel", "twist", [])
    assert nobody is not None and nobody.startswith("nobody subscribes to /cmd_vel")


def test_a_short_range_laser_caps_the_speed_to_what_it_can_stop_within():
    """Outside check: range_max 0.6 m, all +inf (free): the Jackal drove at 2 m/s until a wall
    came into view 0.35 m from its bumper; it needs 0.67 m to stop from 2 m/s at 3 m/s^2."""
    profile = get_profile("jackal")
    half = profile.half_size_m
    cfg = PipelineConfig(profile, filter="egc")
    ranges = np.full(360, INF)
    ranges[0] = 0.55  # one reading behind: a scan that saw something (none at all is a stop)
    free = scan_from_laser(ranges, -math.pi, math.pi / 180, 0.05, 0.6, HERE, 0, half)
    assert isinstance(free, Scan)
    cmd = (1.3, 0.0)  # within one period's braking of the cap
    out = step_command(cfg, 1.0, 0.0, "shared", free.obstacles(), cmd, 0.05)
    room = 0.6 - half[0] - 0.03  # reach - footprint's front - the sweep's margin
    stop = out.v_cmd_mps * 0.05 + out.v_cmd_mps**2 / (2 * profile.decel_max_mps2)
    assert stop == pytest.approx(room, abs=1e-9) and out.limiter.value == "sweep"
    far = scan_from_laser(ranges, -math.pi, math.pi / 180, 0.05, 10.0, HERE, 0, half)
    assert isinstance(far, Scan)
    fast = step_command(cfg, 1.0, 0.0, "shared", far.obstacles(), cmd, 0.05)
    assert fast.v_cmd_mps == pytest.approx(1.4)  # a 10 m lidar does not limit it (accel only)
    direct = step_command(cfg, 1.0, 0.0, "direct", free.obstacles(), cmd, 0.05)
    assert direct.v_cmd_mps == pytest.approx(1.4)  # direct mode: no filter, no sweep
    mounted = scan_from_laser(
        ranges, -math.pi, math.pi / 180, 0.05, 0.6, LaserPose(0.2, 0.0), 0, half
    )
    assert isinstance(mounted, Scan)
    ahead = step_command(cfg, 1.0, 0.0, "shared", mounted.obstacles(), cmd, 0.05)
    assert ahead.v_cmd_mps > out.v_cmd_mps  # mounted 0.2 m forward, it sees further ahead
    assert mounted.obstacles().seen_behind_m == pytest.approx(0.4)


@pytest.mark.parametrize("filter_name", ["egc", "ek-egc", "assist", "dwa", "cbf"])
def test_the_zenoh_scan_message_reads_minus_inf_as_the_ros2_driver_does(filter_name):
    """Outside check: on egc/<robot>/scan (the LaserScan layout) -inf was dropped as no
    return: a sector of -inf ahead left the robot at full speed, limiter none."""
    from egc_common.messages import ScanMessage
    from egc_robot.drivers import scan_from_message

    profile = get_profile("pioneer3dx")
    ranges = np.full(360, 5.0, dtype=np.float32)
    ranges[160:201] = -np.inf  # +-20 deg ahead: nearer than range_min
    message = ScanMessage(0, -math.pi, math.pi / 180, 0.3, 10.0, ranges, False)
    scan = scan_from_message(message, profile.half_size_m)
    assert isinstance(scan, Scan)
    cfg = PipelineConfig(profile, filter=filter_name)
    prev = (profile.v_max_mps, 0.0)
    forward = step_command(cfg, 1.0, 0.0, "shared", scan.obstacles(), prev, 0.05)
    assert forward.v_cmd_mps < profile.v_max_mps and forward.limiter.value != "none"
    for _ in range(40):  # closed loop against the same reading: it comes to a stop
        prev = (forward.v_cmd_mps, forward.w_cmd_radps)
        forward = step_command(cfg, 1.0, 0.0, "shared", scan.obstacles(), prev, 0.05)
    assert forward.v_cmd_mps <= 0.0


@pytest.mark.parametrize(
    "ranges",
    [
        [],
        [math.nan] * 90,
        [0.01, 20.0, math.nan, 0.0],  # finite but outside [range_min, range_max]
    ],
    ids=["no beams", "all NaN", "all out of range"],
)
def test_a_zenoh_scan_message_without_information_is_rejected(ranges):
    """As on the ROS 2 driver: such a scan must not keep the sensor fresh (see test_link)."""
    from egc_common.messages import Rejection, RejectReason, ScanMessage
    from egc_robot.drivers import scan_from_message

    message = ScanMessage(0, -1.0, 0.02, 0.05, 10.0, np.array(ranges, np.float32), True)
    rejected = scan_from_message(message, (0.25, 0.2))
    assert isinstance(rejected, Rejection) and rejected.reason is RejectReason.NO_INFORMATION


@pytest.mark.parametrize("reading", [math.inf, -math.inf, 3.0])
def test_one_informative_beam_among_nan_is_a_scan(reading):
    from egc_common.messages import ScanMessage
    from egc_robot.drivers import scan_from_message

    ranges = np.full(90, math.nan, np.float32)
    ranges[45] = reading
    assert isinstance(scan_from_message(ScanMessage(0, -1.0, 0.02, 0.05, 10.0, ranges), None), Scan)


@pytest.mark.parametrize("filter_name", ["egc", "ek-egc", "assist", "dwa", "cbf"])
@pytest.mark.parametrize(
    "fov_deg, mount, ahead",
    [
        (270.0, (0.0, 0.0, 0.0), False),  # facing forward: reversing into the blind cone
        (270.0, (0.15, 0.05, 0.0), False),
        (180.0, (0.2, 0.0, 0.0), False),  # a Pioneer's SICK: nothing at all behind
        (270.0, (0.0, 0.0, math.pi), True),  # mounted backwards: driving forward blind
    ],
)
@pytest.mark.parametrize("y_o", [0.0, 0.4])
def test_the_robot_does_not_drive_into_what_its_laser_does_not_look_at(
    fov_deg, mount, ahead, y_o, filter_name
):
    """Closed loop, a post in the direction no beam looks at, every beam elsewhere +inf (free
    per REP 117), the stick held full towards the post. What the laser did not cover counted
    as free: the sweep found no point and the Jackal backed into the post at full speed (an
    outside check drove a robot into a wall through such a blind cone). Now the speed that way
    is capped to what the laser sees along the axis (nothing), while it still turns in place and
    drives the way it looks."""
    profile = get_profile("jackal")
    half = profile.half_size_m
    cfg = PipelineConfig(profile, filter=filter_name, no_return_is_free=True)
    beams = int(fov_deg) * 2 + 1
    inc = math.radians(fov_deg) / (beams - 1)
    beam = -0.5 * math.radians(fov_deg) + inc * np.arange(beams)
    laser = LaserPose(*mount)
    sign = 1.0 if ahead else -1.0
    post = (sign * 0.9, 0.0, 0.2)
    pose, cmd, dt = (0.0, 0.0, 0.0), (0.0, 0.0), 0.05
    for _ in range(100):
        before = (pose, cmd)
        ranges = _ranges_to_post(pose, mount[:2], mount[2] + beam, post, 0.05)
        scan = scan_from_laser(ranges, beam[0], inc, 0.05, 10.0, laser, 0, half)
        assert isinstance(scan, Scan)
        out = step_command(cfg, sign, y_o, "shared", scan.obstacles(), cmd, dt)
        cmd = (out.v_cmd_mps, out.w_cmd_radps)
        assert sign * cmd[0] <= 1e-12, cmd  # never towards what it cannot see
        x, y, th = pose
        pose = (x + cmd[0] * dt * math.cos(th), y + cmd[0] * dt * math.sin(th), th + cmd[1] * dt)
        assert _gap_to_footprint(pose, post, half) > 0.0, (pose, cmd)
        if _settled(before, (pose, cmd)):
            break
    ranges = np.full(beams, INF)
    ranges[0] = 5.0
    scan = scan_from_laser(ranges, beam[0], inc, 0.05, 10.0, laser, 0, half)
    assert isinstance(scan, Scan)
    turn = step_command(cfg, 0.0, 1.0, "shared", scan.obstacles(), (0.0, 0.0), dt)
    assert turn.w_cmd_radps > 0.0  # turning in place is not travel
    away = step_command(cfg, -sign, 0.0, "shared", scan.obstacles(), (0.0, 0.0), dt)
    assert -sign * away.v_cmd_mps > 0.0  # the way it looks, it drives


def test_blind_sectors_and_what_a_laser_sees_along_the_axis():
    full = np.linspace(-math.pi, math.pi, 720, endpoint=False)
    assert blind_sectors(full) == () and blind_sectors(full[::-1]) == ()
    assert blind_sectors(np.random.default_rng(3).permutation(full)) == ()
    front = np.linspace(-0.75 * math.pi, 0.75 * math.pi, 541)
    ((start, width),) = blind_sectors(front)
    spacing = 1.5 * math.pi / 540
    assert start == pytest.approx(0.75 * math.pi + 0.5 * spacing)
    assert width == pytest.approx(0.5 * math.pi - spacing)
    assert seen_along_axis_m(full, 10.0, 0.2) == (10.2, 9.8)
    assert seen_along_axis_m(front, 10.0) == (10.0, 0.0)
    assert seen_along_axis_m(front + math.pi, 10.0) == (0.0, 10.0)
    assert seen_along_axis_m(front, 10.0, -0.2)[1] == pytest.approx(0.2, abs=0.011)
    # Mounted to the side, the axis behind it stays in view until it crosses -135 degrees.
    assert seen_along_axis_m(front, 10.0, 0.1, 0.15)[1] == pytest.approx(0.05, abs=0.011)
    two_lasers = np.concatenate((front[:100], front[-100:]))  # a gap straight ahead as well
    assert seen_along_axis_m(two_lasers, 10.0) == (0.0, 0.0)
    assert seen_along_axis_m([0.0], 5.0) == (5.0, 0.0)


def test_the_unseen_directions_are_those_of_the_laser_where_it_sits():
    """Outside check: a 270-degree laser at (0.2, 0.2), yawed 45 degrees, kept the robot from
    reversing (nothing seen behind along the axis) but the driver's line did not say so: the
    directions were judged from the origin."""
    beams = np.linspace(-0.75 * math.pi, 0.75 * math.pi, 541)
    half = get_profile("jackal").half_size_m
    laser = LaserPose(0.2, 0.2, 0.25 * math.pi)
    scan = scan_from_laser(
        np.full(541, 5.0), beams[0], beams[1] - beams[0], 0.05, 10.0, laser, 0, half
    )
    assert isinstance(scan, Scan)
    assert blind_directions(scan.angles_rad) == []  # from the origin something looks back
    assert unseen_directions(scan) == ["behind"]
    centred = scan_from_laser(
        np.full(541, 5.0), beams[0], beams[1] - beams[0], 0.05, 10.0, HERE, 0, half
    )
    assert isinstance(centred, Scan) and unseen_directions(centred) == ["behind"]
    full = np.linspace(-math.pi, math.pi, 720, endpoint=False)
    everywhere = scan_from_laser(
        np.full(720, 5.0), -math.pi, full[1] - full[0], 0.05, 10.0, laser, 0, half
    )
    assert isinstance(everywhere, Scan) and unseen_directions(everywhere) == []


@pytest.mark.parametrize("failed", [math.nan, 0.0, -1.0])
@pytest.mark.parametrize("filter_name", ["egc", "ek-egc", "assist", "dwa", "cbf"])
def test_a_wall_whose_beams_all_fail_is_not_free_space(failed, filter_name):
    """An outside fuzz: a wall across a corridor 0.45 m ahead, its 147 beams reading NaN (or 0,
    or -1: below range_min, errors per REP 117), and the robot drove at it at full speed, the
    failed beams simply dropped. A run of beams that told nothing is a direction the laser did
    not see, as the blind cone behind a 270-degree laser: no travel that way."""
    profile = get_profile("pioneer3dx")
    half = profile.half_size_m
    cfg = PipelineConfig(profile, filter=filter_name, no_return_is_free=True)
    beam = -math.pi + (2 * math.pi / 360) * np.arange(360)
    with np.errstate(divide="ignore"):
        side = np.where(np.sin(beam) != 0, 1.5 / np.abs(np.sin(beam)), np.inf)
        wall = np.where(np.cos(beam) > 0, 0.45 / np.cos(beam), np.inf)
    ranges = np.minimum(side, 10.0 + 1.0)  # beyond range_max: no return (free)
    hidden = wall < side
    ranges[hidden] = failed
    scan = scan_from_laser(ranges, beam[0], beam[1] - beam[0], 0.05, 10.0, LaserPose(), 0, half)
    assert isinstance(scan, Scan)
    out = step_command(cfg, 1.0, 0.0, "shared", scan.obstacles(), (0.0, 0.0), 0.05)
    assert out.v_cmd_mps <= 1e-12, out
    # One failed beam straight ahead tells nothing about a wall: the robot drives on.
    one = np.minimum(side, 11.0)
    one[180] = failed
    scan = scan_from_laser(one, beam[0], beam[1] - beam[0], 0.05, 10.0, LaserPose(), 0, half)
    assert isinstance(scan, Scan)
    out = step_command(cfg, 1.0, 0.0, "shared", scan.obstacles(), (0.0, 0.0), 0.05)
    assert out.v_cmd_mps > 0.0
