"""The pure part of ``egc-teleop replay`` (``egc_robot.replay_core``): REP 117, velocities from
odometry poses, pairing scans with commands, and the summary."""

from __future__ import annotations

import math

import numpy as np
import pytest
from egc_common.profiles import PIONEER3DX
from egc_robot.replay_core import (
    CommandTrack,
    LogScan,
    Pose2D,
    Replayer,
    ScanVerdict,
    VelocitySample,
    scan_durations_s,
    scan_fault,
    scan_points,
    summarize,
    velocities_from_poses,
    wrap_angle,
    yaw_from_quaternion,
)

S = 1_000_000_000


def scan(ranges, angle_min=0.0, inc=math.pi / 2, rmin=0.1, rmax=5.0, log_ns=0, stamp_ns=0):
    return LogScan(log_ns, stamp_ns, angle_min, inc, rmin, rmax, np.asarray(ranges, float))


def test_rep117_free_unknown_too_close_and_out_of_range():
    # beams at 0, 90, 180, 270, 0, 90 deg: +inf, NaN, -inf, 7.0 (> range_max), 2.0, 0.05
    # (< range_min)
    pts = scan_points(scan([math.inf, math.nan, -math.inf, 7.0, 2.0, 0.05], inc=math.pi / 2))
    xy = pts.xy_m
    assert xy.shape == (2, 2)
    # -inf is an obstacle at range_min (here behind: 180 deg), 2.0 is a reading straight ahead
    assert np.allclose(xy[0], (-0.1, 0.0), atol=1e-12) and np.allclose(xy[1], (2.0, 0.0))
    assert pts.closest_m == pytest.approx(0.1)
    assert not pts.free_if_empty


def test_an_empty_scan_is_free_only_when_every_beam_is_plus_inf():
    free = scan_points(scan([math.inf] * 4))
    assert free.xy_m.shape == (0, 2) and free.free_if_empty and free.closest_m is None
    for unknown in ([math.nan] * 4, [math.inf, math.nan], [9.0, math.inf], []):
        p = scan_points(scan(unknown))
        assert p.xy_m.shape == (0, 2) and not p.free_if_empty


def test_negative_increment_sweeps_clockwise():
    p = scan_points(scan([1.0, 1.0], angle_min=0.0, inc=-math.pi / 2))
    assert np.allclose(p.xy_m, [(1.0, 0.0), (0.0, -1.0)], atol=1e-12)


def pose(i, x, y, yaw, stamp=None, log=None):
    t = i * S // 10
    return Pose2D(t if log is None else log, t if stamp is None else stamp, x, y, yaw)


def test_forward_speed_from_poses_in_a_turned_world_frame():
    yaw = 2.5  # driving "north-west" in the world: the world-frame twist would be meaningless
    poses = [pose(i, 0.05 * i * math.cos(yaw), 0.05 * i * math.sin(yaw), yaw) for i in range(5)]
    out = velocities_from_poses(poses)
    assert len(out) == 4
    assert all(
        s.linear_mps == pytest.approx(0.5) and s.angular_radps == pytest.approx(0) for s in out
    )
    assert [s.log_ns for s in out] == [p.log_ns for p in poses[1:]]


def test_reversing_is_negative_and_arcs_are_exact():
    back = velocities_from_poses(
        [pose(0, 0, 0, 0.3), pose(1, -0.1 * math.cos(0.3), -0.1 * math.sin(0.3), 0.3)]
    )
    assert back[0].linear_mps == pytest.approx(-1.0)
    # a circle of radius 2 m at w = 0.8 rad/s (v = 1.6 m/s), 10 Hz, crossing yaw = +-pi
    r, w = 2.0, 0.8
    th = [math.pi - 0.2 + w * 0.1 * i for i in range(6)]
    poses = [pose(i, r * math.sin(t), -r * math.cos(t), t) for i, t in enumerate(th)]
    poses = [Pose2D(p.log_ns, p.stamp_ns, p.x_m, p.y_m, wrap_angle(p.yaw_rad)) for p in poses]
    for s in velocities_from_poses(poses):
        assert s.linear_mps == pytest.approx(r * w, rel=1e-9)
        assert s.angular_radps == pytest.approx(w, rel=1e-9)


def test_poses_ordered_by_stamp_repeats_and_gaps_give_no_sample():
    # receive order scrambled and two poses sharing one receive time (the Mapping1 pitfall)
    p0, p1, p2 = pose(0, 0.0, 0, 0), pose(1, 0.1, 0, 0), pose(2, 0.2, 0, 0)
    p1 = Pose2D(p2.log_ns, p1.stamp_ns, p1.x_m, p1.y_m, 0.0)
    dup = Pose2D(p2.log_ns + 1, p2.stamp_ns, 0.2, 0.0, 0.0)  # same stamp again
    late = Pose2D(5 * S, 5 * S, 3.0, 0.0, 0.0)  # after a 4.8 s gap
    out = velocities_from_poses([p2, dup, late, p0, p1])
    assert [round(s.linear_mps, 9) for s in out] == [1.0, 1.0]


def test_command_track_holds_the_latest_sample_and_expires_when_asked():
    track = CommandTrack.of([VelocitySample(2 * S, 0.2, 0.0), VelocitySample(1 * S, 0.1, 0.1)])
    assert track.at(S - 1) is None
    assert track.at(S).linear_mps == 0.1 and track.at(2 * S - 1).linear_mps == 0.1
    assert track.at(100 * S).linear_mps == 0.2
    aging = CommandTrack.of(track.samples, max_age_s=1.0)
    assert aging.at(3 * S).linear_mps == 0.2 and aging.at(3 * S + 1) is None


def verdict(i, v_ref, v_cmd, w_ref=0.0, w_cmd=0.0, closest=1.0, has=True, stamp=True):
    t = i * S // 10
    return ScanVerdict(t, t if stamp else 0, has, v_ref, w_ref, v_cmd, w_cmd, "egc", closest)


def test_changed_and_held():
    assert verdict(0, 0.3, 0.295).changed is False and verdict(0, 0.3, 0.28).changed is True
    assert verdict(0, 0.0, 0.0, 0.5, 0.48).changed is True
    assert verdict(0, 0.3, 0.0, 0.5, 0.5).held  # translation stopped, turning allowed: held
    assert verdict(0, 0.0, 0.0, 0.5, 0.0).held  # a turn in place stopped
    assert not verdict(0, 0.3, 0.1).held and not verdict(0, 0.0, 0.0).held
    assert not verdict(0, 0.3, 0.0, has=False).held and not verdict(0, 0.3, 0.0, has=False).changed


def test_summary_keys_and_hold_time():
    vs = [
        verdict(0, 0.3, 0.3, closest=2.0),
        verdict(1, 0.3, 0.0, closest=0.6),
        verdict(2, 0.3, 0.0, closest=0.5),
        verdict(3, 0.3, 0.2, closest=0.7),
        verdict(4, 0.3, 0.0, closest=None),
        verdict(5, 0.0, 0.0, has=False),
    ]
    d = summarize(vs, "egc", "pioneer3dx").as_dict()
    for key in (
        "scans",
        "commands",
        "changed",
        "max_cut_mps",
        "hold_s",
        "closest_m",
        "filter",
        "profile",
    ):
        assert key in d
    assert d["scans"] == 6 and d["commands"] == 5 and d["changed"] == 4
    assert d["max_cut_mps"] == pytest.approx(0.3) and d["closest_m"] == pytest.approx(0.5)
    assert d["hold_s"] == pytest.approx(0.3) and d["holds"] == 2
    assert d["filter"] == "egc" and d["profile"] == "pioneer3dx"
    assert d["duration_s"] == pytest.approx(0.6)


def test_durations_by_stamp_with_gaps_cut_to_the_period():
    vs = [verdict(i, 0.3, 0.0) for i in (0, 1, 2, 50, 51)]  # a 4.8 s gap in the middle
    assert scan_durations_s(vs) == pytest.approx([0.1, 0.1, 0.1, 0.1, 0.1])
    # no stamps: receive times decide
    assert scan_durations_s([verdict(i, 0.3, 0.0, stamp=False) for i in range(3)]) == pytest.approx(
        [0.1] * 3
    )
    assert scan_durations_s([]) == []


def test_quaternion_yaw():
    for yaw in (-3.0, -1.0, 0.0, 0.5, 3.1):
        assert yaw_from_quaternion(0, 0, math.sin(yaw / 2), math.cos(yaw / 2)) == pytest.approx(yaw)


def wall(d, beams=360):
    a = -math.pi + 2 * math.pi * np.arange(beams) / beams
    r = np.full(beams, np.inf)
    ahead = np.abs(a) < 1.0
    r[ahead] = d / np.cos(a[ahead])
    return scan(r, angle_min=-math.pi, inc=2 * math.pi / beams, rmax=8.0)


@pytest.mark.parametrize("filter_name", ["egc", "none"])
def test_the_robots_pipeline_decides(filter_name):
    replayer = Replayer.for_filter(filter_name, PIONEER3DX)
    forward = VelocitySample(0, 0.12, 0.0)
    s = wall(0.6)
    v, result, obstacles, _ = replayer.step(s, scan_points(s), forward)
    assert result is not None and len(obstacles) > 0
    if filter_name == "egc":
        assert v.held and v.changed and v.v_cmd_mps == 0.0
    else:
        assert not v.changed and v.v_cmd_mps == pytest.approx(0.12)
    far = wall(6.0)
    assert not replayer.step(far, scan_points(far), forward)[0].changed
    # every beam +inf is free space (REP 117); every beam NaN is unknown: egc stops
    free = scan([math.inf] * 8, inc=math.pi / 4)
    assert replayer.step(free, scan_points(free), forward)[0].v_cmd_mps == pytest.approx(0.12)
    blind = scan([math.nan] * 8, inc=math.pi / 4)
    assert replayer.step(blind, scan_points(blind), forward)[0].held is (filter_name == "egc")
    # without a command the scan is only measured
    none, res, _, _ = replayer.step(s, scan_points(s), None)
    assert res is None and not none.has_command and none.closest_m == pytest.approx(0.6)


@pytest.mark.parametrize("d", [0.5, 0.62, 0.7, 0.9, 1.5])
@pytest.mark.parametrize("w", [-0.4, 0.0, 0.3])
def test_each_scan_stands_alone_no_acceleration_ramp(d, w):
    """The robot state is the recorded command, yet no acceleration limit applies: egc gives
    what the stateless pipeline call gives, a stop included."""
    from egc_robot.pipeline import filter_velocity

    replayer = Replayer.for_filter("egc", PIONEER3DX)
    s = wall(d)
    points = scan_points(s)
    v, *_ = replayer.step(s, points, VelocitySample(0, 0.12, w))
    ref = filter_velocity(replayer.config, 0.12, w, "shared", points.xy_m, None, 0.0)
    assert (v.v_cmd_mps, v.w_cmd_radps) == pytest.approx(
        (ref.v_cmd_mps, ref.w_cmd_radps), abs=1e-12
    )
    assert v.limiter == ref.limiter.value


def test_scan_fault_accepts_what_sensors_send():
    # REP 117's encodings, "no return" as range_max + 1 or a little more, readings below
    # range_min (the blind zone), negative increments, a single beam, an empty scan
    rep117 = [math.inf, -math.inf, math.nan, 6.0, 5.0 + 1.0, 0.0, 0.05, 4999.0]
    assert scan_fault(scan(rep117)) is None
    assert scan_fault(scan([1.0] * 720, angle_min=math.pi, inc=-2 * math.pi / 720)) is None
    assert scan_fault(scan([1.0], inc=0.0)) is None and scan_fault(scan([])) is None
    assert scan_fault(scan([0.2, 0.3 + 1.0], rmin=0.0, rmax=0.3)) is None  # a short-range one
    assert scan_fault(scan([2.0, 3.0], rmin=2.0, rmax=2.0)) is None  # degenerate, not absurd


@pytest.mark.parametrize(
    ("fields", "why"),
    [
        ({"angle_min": math.nan}, "angle_min nan"),
        ({"angle_min": 1e30}, "angle_min 1e+30"),
        ({"inc": math.inf}, "angle_increment inf"),
        ({"inc": 3.0e9}, "angle_increment 3e+09"),
        ({"inc": 2.0}, "angle_increment 2 rad over 8 beams"),  # 14 rad: beyond two turns
        ({"inc": 0.0}, "angle_increment 0 over 8 beams"),
        ({"rmin": math.nan}, "range_min nan"),
        ({"rmin": -0.5}, "range_min -0.5"),
        ({"rmax": math.inf}, "range_max inf"),
        ({"rmax": 0.0}, "range_max 0"),
        ({"rmax": 2e38}, "range_max 2e+38"),
        ({"rmin": 6.0}, "range_min 6 m above range_max 5 m"),
    ],
)
def test_scan_fault_names_absurd_fields(fields, why):
    fault = scan_fault(scan([1.0] * 8, **fields))
    assert fault is not None and fault.startswith(why), fault


def test_scan_fault_finite_negative_or_unreachable_readings():
    # range_max 5 m: 5000 m is the limit (1000 x range_max)
    assert scan_fault(scan([1.0, -0.01, 2.0])) == "beam 1 reads -0.01 m, negative"
    assert scan_fault(scan([1.0, 2.0, 5001.0])).startswith("beam 2 reads 5e+03 m, beyond")
    assert scan_fault(scan([1.97e38, -6.6e37])).startswith("beam 1 reads -6.6e+37 m")
    # a long-range sensor: 1e6 m is the limit whatever range_max says
    assert scan_fault(scan([2e5], rmax=900.0)) is None
    assert scan_fault(scan([2e6], rmax=900.0)).startswith("beam 0 reads 2e+06 m, beyond")


def test_scan_fault_raises_no_numpy_warning_on_signalling_nans():
    raw = np.array([0x7F800001, 0xFF800001, 0x3F800000], dtype=np.uint32).view(np.float32)
    with np.errstate(all="raise"):  # a warning would be an exception here
        with np.errstate(invalid="ignore"):
            ranges = raw.astype(np.float64)
        assert scan_fault(scan(ranges)) is None  # NaNs (of any kind) are "no information"
        assert scan_fault(scan(np.append(ranges, -3.0))) == "beam 3 reads -3 m, negative"
