"""Replay of a recorded robot log through a filter of the family, as pure functions (DESIGN 11).

``egc-teleop replay`` (its engine ``egc_experiments.log_replay``) reads the log and hands this
module plain values: scans (``LogScan``), the commanded velocity (``VelocitySample``, from a
Twist topic or derived here from odometry poses with ``velocities_from_poses``) and gets back,
per scan, what the robot's own pipeline (``egc_robot.pipeline``) would have sent
(``ScanVerdict``), and for the whole log the summary (``ReplaySummary``). No files, no clocks,
no Rerun here.

Times. A log has two clocks: the recorder's receive time (``log_ns``, one clock for every
topic) and each message's header stamp (``stamp_ns``, the sensor's or the driver's clock).
Scans are paired with the command in effect at their receive time, because a Twist has no
header; odometry is differentiated, and hold time measured, by header stamps, because real logs
give several messages one receive time (``../shared/bags/README.md``). A command is in effect
for at most ``COMMAND_MAX_AGE_S`` after it was received (a base stops when ``cmd_vel`` falls
silent: DESIGN 11's simulated base after 0.5 s, as real bases do), a pose-derived velocity for
``ODOMETRY_MAX_AGE_S``; a scan after that has no command.

Scans follow REP 117: ``+inf`` nothing within range_max (free), ``NaN`` no information
(unknown), ``-inf`` an object closer than range_min (an obstacle at range_min); finite readings
outside [range_min, range_max] are dropped. A scan whose every beam is ``+inf`` is free space;
any other scan without a valid reading is unknown, which the filters treat as a reason to stop
(DESIGN 5.9).

A scan whose fields no sensor could have sent (``scan_fault``: a non-finite or absurd angle or
range limit, range_min above range_max, a finite negative reading, or a finite one far beyond
any sensor's reach) is a damaged log, not a reading: the IO layer skips and counts it.
"""

from __future__ import annotations

import bisect
import itertools
import math
import statistics
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import numpy.typing as npt
from egc_common.footprint import Footprint
from egc_common.profiles import RobotProfile
from egc_common.scan import (
    ObstaclePoints,
    obstacle_points,
    seen_along_axis_of_scan,
    too_close_points,
)

from egc_robot import pipeline
from egc_robot.pipeline import PipelineConfig, PipelineResult

FloatArray = npt.NDArray[np.float64]

CHANGED_MPS = 0.01  # DESIGN 11: a command is "changed" when filtered v or w differs by more
MOVING = 0.01  # |v| (m/s) or |w| (rad/s) above this is a moving command
MAX_GAP_S = 1.0  # a gap between scans (or poses) longer than this is not driving time
ODOMETRY_MAX_AGE_S = 1.0  # a pose-derived velocity older than this is not known any more
COMMAND_MAX_AGE_S = 0.5  # a base stops when cmd_vel is silent this long (DESIGN 11's sim base)
_NS = 1_000_000_000
# Sanity bounds for ``scan_fault``: far beyond any real laser, well short of garbage floats.
MAX_REACH_M = 1e6  # no sensor's range_max, nor a reading, is longer
MAX_REACH_FACTOR = 1000.0  # no reading is longer than this many times range_max
MAX_TURN_RAD = 4.0 * math.pi  # no scan starts, or sweeps, beyond two full turns
MAX_SPEED = 1e3  # no command, in m/s or rad/s, is faster: a damaged record's garbage float


@dataclass(frozen=True, slots=True, eq=False)
class LogScan:
    """One ``sensor_msgs/LaserScan`` from a log, in the laser frame (taken as {R})."""

    log_ns: int  # the recorder's receive time
    stamp_ns: int  # header stamp; 0 when the log left it unset
    angle_min_rad: float
    angle_increment_rad: float
    range_min_m: float
    range_max_m: float
    ranges_m: FloatArray


@dataclass(frozen=True, slots=True)
class Pose2D:
    """One odometry pose in its (world) frame."""

    log_ns: int
    stamp_ns: int
    x_m: float
    y_m: float
    yaw_rad: float


@dataclass(frozen=True, slots=True)
class VelocitySample:
    """The velocity commanded (or driven) from ``log_ns`` on, in {R}."""

    log_ns: int
    linear_mps: float
    angular_radps: float


@dataclass(frozen=True, slots=True)
class ScanPoints:
    """A scan's points in {R} after REP 117, and whether an empty scan means free space."""

    xy_m: FloatArray  # (N, 2)
    free_if_empty: bool
    closest_m: float | None  # nearest valid reading, None when there is none
    range_max_m: float = math.inf  # the laser's reach: nothing beyond it was seen
    # How far it sees straight ahead and behind (range_max, or less through a blind sector:
    # ``egc_common.scan.seen_along_axis_m``).
    seen_ahead_m: float = math.inf
    seen_behind_m: float = math.inf


@dataclass(frozen=True, slots=True)
class ScanVerdict:
    """What the filter made of the command in effect when one scan arrived."""

    log_ns: int
    stamp_ns: int
    has_command: bool
    v_ref_mps: float
    w_ref_radps: float
    v_cmd_mps: float
    w_cmd_radps: float
    limiter: str  # egc_robot.pipeline.Limiter value ("none" without a command)
    closest_m: float | None

    @property
    def changed(self) -> bool:
        """Filtered v or w differs from the recorded command by more than 0.01 (DESIGN 11)."""
        return self.has_command and (
            abs(self.v_cmd_mps - self.v_ref_mps) > CHANGED_MPS
            or abs(self.w_cmd_radps - self.w_ref_radps) > CHANGED_MPS
        )

    @property
    def held(self) -> bool:
        """The filter stopped a moving command: a translating command lost its translation, or
        a turn in place was stopped."""
        if not self.has_command:
            return False
        if abs(self.v_ref_mps) > MOVING:
            return abs(self.v_cmd_mps) <= MOVING
        return abs(self.w_ref_radps) > MOVING and abs(self.w_cmd_radps) <= MOVING


@dataclass(frozen=True, slots=True)
class ReplaySummary:
    """The summary of one replay; ``as_dict`` gives the JSON with DESIGN 11's pinned keys."""

    filter: str
    profile: str
    scans: int
    commands: int  # scans that had a command in effect (each went through the filter)
    changed: int
    max_cut_mps: float  # largest |v_ref - v_cmd|
    max_cut_radps: float  # largest |w_ref - w_cmd|
    # DESIGN 13: mean over commands of |dv| / v_max + |dw| / w_max (None: limits not given)
    mean_cut: float | None
    hold_s: float  # log time during which the filter would have stopped a moving command
    holds: int  # separate stretches of holding
    closest_m: float | None  # nearest valid reading over the whole log
    duration_s: float  # log time covered by the scans
    moving_s: float  # log time during which the recorded command moved the robot
    limiters: dict[str, int] = field(default_factory=dict)  # what limited each command
    extra: dict[str, Any] = field(default_factory=dict)  # log facts from the IO layer

    @property
    def changed_share(self) -> float:
        """DESIGN 13: changed / commands (0 without commands)."""
        return self.changed / self.commands if self.commands else 0.0

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready: the pinned keys (DESIGN 11: ``scans``, ``commands``, ``changed``,
        ``max_cut_mps``, ``hold_s``, ``closest_m``, ``filter``, ``profile``; DESIGN 13:
        ``changed_share``, ``mean_cut``) and a few more."""
        out: dict[str, Any] = {
            "scans": self.scans,
            "commands": self.commands,
            "changed": self.changed,
            "changed_share": round(self.changed_share, 6),
            "mean_cut": None if self.mean_cut is None else round(self.mean_cut, 6),
            "max_cut_mps": round(self.max_cut_mps, 6),
            "hold_s": round(self.hold_s, 6),
            "closest_m": None if self.closest_m is None else round(self.closest_m, 6),
            "filter": self.filter,
            "profile": self.profile,
            "max_cut_radps": round(self.max_cut_radps, 6),
            "holds": self.holds,
            "duration_s": round(self.duration_s, 6),
            "moving_s": round(self.moving_s, 6),
            "limiters": dict(sorted(self.limiters.items())),
        }
        out.update(self.extra)
        return out


def wrap_angle(a_rad: float) -> float:
    """An angle in [-pi, pi)."""
    return (a_rad + math.pi) % (2.0 * math.pi) - math.pi


def yaw_from_quaternion(x: float, y: float, z: float, w: float) -> float:
    """Yaw (rotation about z) of a unit quaternion, rad."""
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def scan_points(
    scan: LogScan, footprint_half_m: Footprint | tuple[float, float] | None = None
) -> ScanPoints:
    """REP 117 ranges to points in {R}: finite readings within [range_min, range_max], plus
    ``-inf`` readings as obstacles at range_min (and, given the footprint's half length and
    width, just outside the footprint: ``egc_common.scan.too_close_points``); ``+inf``, ``NaN``
    and finite readings outside the range are dropped."""
    r = np.asarray(scan.ranges_m, dtype=np.float64)
    angles = scan.angle_min_rad + scan.angle_increment_rad * np.arange(r.size, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(r) & (r >= scan.range_min_m) & (r <= scan.range_max_m)
    too_close = np.isneginf(r)
    keep = valid | too_close
    rr_m = np.where(too_close, scan.range_min_m, r)[keep]
    a = angles[keep]
    xy = np.empty((rr_m.size, 2), dtype=np.float64)
    xy[:, 0] = rr_m * np.cos(a)
    xy[:, 1] = rr_m * np.sin(a)
    if footprint_half_m is not None and too_close.any():
        near = too_close_points(angles[too_close], scan.range_min_m, 0.0, 0.0, footprint_half_m)
        xy = np.concatenate((xy, near))
    free = rr_m.size == 0 and r.size > 0 and bool(np.all(np.isposinf(r)))
    closest = float(rr_m.min()) if rr_m.size else None
    ahead_m, behind_m = seen_along_axis_of_scan(
        angles, r, float(scan.range_min_m), float(scan.range_max_m)
    )
    return ScanPoints(xy, free, closest, float(scan.range_max_m), ahead_m, behind_m)


def scan_fault(scan: LogScan) -> str | None:
    """Why ``scan`` cannot have come from a sensor, or None when it could.

    A damaged log (bytes overwritten in a storage file without checksums) deserializes into
    a scan whose numbers are garbage floats. Faults: angle_min or angle_increment not finite,
    or beyond two turns (the beams together as well); several beams at one angle; range_min or
    range_max not finite, negative, range_max zero or over ``MAX_REACH_M``; range_min above
    range_max; a finite negative reading; a finite reading over ``MAX_REACH_FACTOR`` times
    range_max or over ``MAX_REACH_M``. REP 117's encodings stay valid: ``+inf``, ``-inf``,
    ``NaN``, and finite "no return" values just past range_max (range_max + 1 and the like).
    """
    a0, inc = scan.angle_min_rad, scan.angle_increment_rad
    rmin, rmax = scan.range_min_m, scan.range_max_m
    n = int(np.size(scan.ranges_m))
    if not (math.isfinite(a0) and abs(a0) <= MAX_TURN_RAD):
        return f"angle_min {a0:.3g} rad"
    if not (math.isfinite(inc) and abs(inc) * max(n - 1, 1) <= MAX_TURN_RAD):
        return f"angle_increment {inc:.3g} rad over {n} beams"
    if n > 1 and inc == 0.0:
        return f"angle_increment 0 over {n} beams"
    if not (math.isfinite(rmin) and rmin >= 0.0):
        return f"range_min {rmin:.3g} m"
    if not (math.isfinite(rmax) and 0.0 < rmax <= MAX_REACH_M):
        return f"range_max {rmax:.3g} m"
    if rmin > rmax:
        return f"range_min {rmin:.3g} m above range_max {rmax:.3g} m"
    r = np.asarray(scan.ranges_m, dtype=np.float64).ravel()
    reach_m = min(MAX_REACH_FACTOR * rmax, MAX_REACH_M)
    with np.errstate(invalid="ignore"):
        finite = np.isfinite(r)
        negative = finite & (r < 0.0)
        far = finite & (r > reach_m)
    if negative.any():
        i = int(np.argmax(negative))
        return f"beam {i} reads {r[i]:.3g} m, negative"
    if far.any():
        i = int(np.argmax(far))
        return f"beam {i} reads {r[i]:.3g} m, beyond any reach (range_max {rmax:.3g} m)"
    return None


def velocity_fault(linear_mps: float, angular_radps: float) -> str | None:
    """Why a recorded command cannot have been sent to a base, or None when it could: a
    component not finite or over ``MAX_SPEED`` (m/s or rad/s), what a damaged record gives."""
    for name, value in (("linear.x", linear_mps), ("angular.z", angular_radps)):
        if not (math.isfinite(value) and abs(value) <= MAX_SPEED):
            return f"{name} {value:.3g}"
    return None


def pose_fault(pose: Pose2D) -> str | None:
    """Why an odometry pose cannot have come from a robot, or None when it could: a position
    or yaw not finite, or a position beyond ``MAX_REACH_M`` from the origin."""
    for name, value in (("x", pose.x_m), ("y", pose.y_m), ("yaw", pose.yaw_rad)):
        if not math.isfinite(value) or (name != "yaw" and abs(value) > MAX_REACH_M):
            return f"pose {name} {value:.3g}"
    return None


def velocities_from_poses(
    poses: Sequence[Pose2D], max_gap_s: float = MAX_GAP_S
) -> list[VelocitySample]:
    """Forward speed and turn rate in {R} from successive odometry poses, by header stamp.

    An odometry message's twist may be in the world frame (Stage's ground truth is), so the
    velocity comes from the poses: between two poses the robot is taken to drive one arc, whose
    chord points along the mean heading; the forward speed is the arc length (chord projected on
    the mean heading, lengthened from chord to arc) over the stamp difference, signed (negative
    when reversing), and the turn rate the wrapped yaw change over it. Poses are ordered by
    stamp (the log's receive order breaks ties and stands in for missing stamps); repeated
    stamps and gaps longer than ``max_gap_s`` give no sample. Each sample takes effect at the
    receive time of the later pose.
    """
    ordered = sorted(poses, key=lambda p: (p.stamp_ns or p.log_ns, p.log_ns))
    out: list[VelocitySample] = []
    for a, b in itertools.pairwise(ordered):
        dt_s = ((b.stamp_ns or b.log_ns) - (a.stamp_ns or a.log_ns)) / _NS
        if not 0.0 < dt_s <= max_gap_s:
            continue
        dyaw = wrap_angle(b.yaw_rad - a.yaw_rad)
        heading = a.yaw_rad + 0.5 * dyaw
        along = (b.x_m - a.x_m) * math.cos(heading) + (b.y_m - a.y_m) * math.sin(heading)
        half = 0.5 * dyaw
        arc_per_chord = half / math.sin(half) if abs(half) > 1e-9 else 1.0
        out.append(
            VelocitySample(max(a.log_ns, b.log_ns), along * arc_per_chord / dt_s, dyaw / dt_s)
        )
    out.sort(key=lambda s: s.log_ns)
    return out


@dataclass(frozen=True, slots=True)
class CommandTrack:
    """The commanded velocity over log time: each sample holds until the next one, or for at
    most ``max_age_ns`` when set (a base stops when its commands stop: ``COMMAND_MAX_AGE_S``)."""

    log_ns: tuple[int, ...]
    samples: tuple[VelocitySample, ...]
    max_age_ns: int | None = None

    @staticmethod
    def of(samples: Sequence[VelocitySample], max_age_s: float | None = None) -> CommandTrack:
        ordered = tuple(sorted(samples, key=lambda s: s.log_ns))
        age = None if max_age_s is None or math.isinf(max_age_s) else int(max_age_s * _NS)
        return CommandTrack(tuple(s.log_ns for s in ordered), ordered, age)

    def latest(self, log_ns: int) -> VelocitySample | None:
        """The latest sample at or before ``log_ns``, however old, or None."""
        i = bisect.bisect_right(self.log_ns, log_ns) - 1
        return self.samples[i] if i >= 0 else None

    def at(self, log_ns: int) -> VelocitySample | None:
        """The sample in effect at ``log_ns`` (the latest at or before it, if it is not older
        than ``max_age_ns``), or None."""
        sample = self.latest(log_ns)
        if sample is None or self.stale(sample, log_ns):
            return None
        return sample

    def stale_at(self, log_ns: int) -> bool:
        """A sample came before ``log_ns`` but is too old to be in effect at it."""
        sample = self.latest(log_ns)
        return sample is not None and self.stale(sample, log_ns)

    def stale(self, sample: VelocitySample, log_ns: int) -> bool:
        return self.max_age_ns is not None and log_ns - sample.log_ns > self.max_age_ns


@dataclass(frozen=True, slots=True)
class Replayer:
    """The robot's pipeline for one filter and profile, applied to one scan at a time.

    Built once per replay (``Replayer.for_filter``). Stateless filters give the same answer
    for a scan whatever came before; a filter with memory (``assist``) gets its memory back
    through ``step``'s return value, and the scan's receive time as its clock.
    """

    config: PipelineConfig  # an empty scan is unknown: stop
    config_free: PipelineConfig  # an empty scan is free space (REP 117: every beam +inf)

    @staticmethod
    def for_filter(
        filter_name: str, profile: RobotProfile, horizon_s: float | None = None
    ) -> Replayer:
        config = PipelineConfig(profile=profile, filter=filter_name, horizon_s=horizon_s)
        return Replayer(config, replace(config, no_return_is_free=True))

    def step(
        self,
        scan: LogScan,
        points: ScanPoints,
        command: VelocitySample | None,
        memory: object | None = None,
    ) -> tuple[ScanVerdict, PipelineResult | None, ObstaclePoints, object | None]:
        """One scan through the pipeline with the command in effect; without a command the scan
        is only measured. Returns the verdict, the pipeline's result (None without a command),
        the obstacle points it saw and the filter's memory for the next scan."""
        obstacles = obstacle_points(
            points.xy_m, seen_ahead_m=points.seen_ahead_m, seen_behind_m=points.seen_behind_m
        )
        if command is None:
            verdict = ScanVerdict(
                scan.log_ns, scan.stamp_ns, False, 0.0, 0.0, 0.0, 0.0, "none", points.closest_m
            )
            return verdict, None, obstacles, memory
        config = self.config_free if points.free_if_empty else self.config
        v, w = command.linear_mps, command.angular_radps
        result = _filter_velocity(config, v, w, obstacles, scan.log_ns, memory)
        verdict = ScanVerdict(
            scan.log_ns,
            scan.stamp_ns,
            True,
            v,
            w,
            result.v_cmd_mps,
            result.w_cmd_radps,
            result.limiter.value,
            points.closest_m,
        )
        return verdict, result, obstacles, result.memory


def _filter_velocity(
    config: PipelineConfig,
    v_mps: float,
    w_radps: float,
    obstacles: ObstaclePoints,
    now_ns: int,
    memory: object | None,
) -> PipelineResult:
    """``pipeline.filter_velocity`` in shared mode for one scan.

    The robot is taken to be moving as recorded: the pipeline's robot state (which it takes
    from the previous command) is the recorded command itself, and the acceleration limits are
    off (an infinite period: each scan stands alone, and a filter that would stop the robot
    shows as a stop, not as the first step of a ramp). No via point: logs have none.
    """
    return pipeline.filter_velocity(
        config,
        v_mps,
        w_radps,
        "shared",
        obstacles,
        (v_mps, w_radps),
        math.inf,
        goal_xy_m=None,
        now_ns=now_ns,
        memory=memory,
    )


def scan_durations_s(verdicts: Sequence[ScanVerdict], max_gap_s: float = MAX_GAP_S) -> list[float]:
    """How long each scan stood: until the next scan by header stamp (receive time when stamps
    are missing or go backwards), gaps over ``max_gap_s`` cut to the median period; the last
    scan stands for the median period."""
    if not verdicts:
        return []
    stamps = [v.stamp_ns for v in verdicts]
    use_stamps = all(s > 0 for s in stamps) and all(b >= a for a, b in itertools.pairwise(stamps))
    times = stamps if use_stamps else [v.log_ns for v in verdicts]
    gaps = [max(0, b - a) / _NS for a, b in itertools.pairwise(times)]
    positive = [g for g in gaps if 0.0 < g <= max_gap_s]
    period = statistics.median(positive) if positive else 0.0
    return [g if g <= max_gap_s else period for g in gaps] + [period]


def summarize(
    verdicts: Sequence[ScanVerdict],
    filter_name: str,
    profile_name: str,
    extra: dict[str, Any] | None = None,
    limits: tuple[float, float] | None = None,
) -> ReplaySummary:
    """The replay's summary over every scan's verdict, in log order. ``limits``: the
    profile's (v_max, w_max), which scale ``mean_cut`` (DESIGN 13)."""
    durations = scan_durations_s(verdicts)
    with_cmd = [v for v in verdicts if v.has_command]
    hold_s = 0.0
    moving_s = 0.0
    holds = 0
    holding = False
    for verdict, dt in zip(verdicts, durations, strict=True):
        if verdict.has_command and (
            abs(verdict.v_ref_mps) > MOVING or abs(verdict.w_ref_radps) > MOVING
        ):
            moving_s += dt
        if verdict.held:
            hold_s += dt
            holds += 0 if holding else 1
        holding = verdict.held
    closest = [v.closest_m for v in verdicts if v.closest_m is not None]
    mean_cut = None
    if limits is not None:
        v_max, w_max = limits
        cuts = [
            abs(v.v_ref_mps - v.v_cmd_mps) / v_max + abs(v.w_ref_radps - v.w_cmd_radps) / w_max
            for v in with_cmd
        ]
        mean_cut = float(sum(cuts) / len(cuts)) if cuts else 0.0
    return ReplaySummary(
        filter=filter_name,
        profile=profile_name,
        scans=len(verdicts),
        commands=len(with_cmd),
        changed=sum(1 for v in with_cmd if v.changed),
        max_cut_mps=max((abs(v.v_ref_mps - v.v_cmd_mps) for v in with_cmd), default=0.0),
        max_cut_radps=max((abs(v.w_ref_radps - v.w_cmd_radps) for v in with_cmd), default=0.0),
        mean_cut=mean_cut,
        hold_s=hold_s,
        holds=holds,
        closest_m=min(closest) if closest else None,
        duration_s=sum(durations),
        moving_s=moving_s,
        limiters=dict(Counter(v.limiter for v in with_cmd)),
        extra=dict(extra or {}),
    )
