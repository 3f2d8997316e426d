"""``egc-teleop replay LOG``: a recorded robot log through a filter of the family (DESIGN 11).

    egc-teleop replay LOG [--filter NAME] [--profile NAME] [--scan-topic T] [--cmd-topic T]
                          [--record FILE.rrd] [--summary FILE.json]

LOG is a ROS 1 ``.bag``, a ROS 2 bag directory, or a single ``.db3`` or ``.mcap`` file, read
with the ``rosbags`` library (no ROS install). Each ``sensor_msgs/LaserScan`` goes through the
robot's own pipeline (``egc_robot.pipeline``) with the velocity commanded at the time: the log's
``geometry_msgs/Twist`` or ``TwistStamped`` topic when it has one, else the forward speed and
turn rate derived from successive ``nav_msgs/Odometry`` poses (an odometry twist may be in the
world frame). The pure part (pairing, REP 117, odometry, summary) is ``egc_robot.replay_core``;
this module reads the log, shows progress on stderr, prints the summary JSON on stdout (and
writes it to ``--summary``) and saves the Rerun recording (``--record``) on the log's own
timeline (``bag_time``, the recorder's receive time; ``stamp``, the scans' header stamps).

A log that cannot be replayed (missing, not a bag, truncated, without the topics it needs, a
topic of the wrong type, every scan corrupt) is one line on stderr naming the problem and exit
code 2. A scan no sensor could have sent (``replay_core.scan_fault``: garbage from a damaged
storage file) is skipped and counted (``scans_corrupt``), with one line on stderr. A folder
without ``metadata.yaml`` that holds one ``.mcap``, ``.db3`` or ``.bag`` file replays that file.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import struct
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from egc_common.errors import UsageError
from egc_common.profiles import PROFILES, get_profile
from egc_robot.pipeline import FILTERS
from egc_robot.replay_core import (
    ODOMETRY_MAX_AGE_S,
    CommandTrack,
    LogScan,
    Pose2D,
    Replayer,
    ScanVerdict,
    VelocitySample,
    scan_fault,
    scan_points,
    summarize,
    velocities_from_poses,
    yaw_from_quaternion,
)

LASER_SCAN = "sensor_msgs/msg/LaserScan"
TWIST = "geometry_msgs/msg/Twist"
TWIST_STAMPED = "geometry_msgs/msg/TwistStamped"
ODOMETRY = "nav_msgs/msg/Odometry"
COMMAND_TYPES = (TWIST, TWIST_STAMPED)
DEFAULT_SCAN_TOPIC = "/scan"
DEFAULT_CMD_TOPIC = "/cmd_vel"
DEFAULT_ODOM_TOPIC = "/odom"
LOG_SUFFIXES = (".mcap", ".db3", ".bag")  # files a folder without metadata.yaml may hold


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "log", metavar="LOG", help="ROS 1 .bag, ROS 2 bag directory, .db3 or .mcap file"
    )
    parser.add_argument(
        "--filter",
        default="egc",
        choices=FILTERS,
        metavar="NAME",
        help=f"filter to replay: {', '.join(FILTERS)} (default: egc)",
    )
    parser.add_argument(
        "--profile",
        default="pioneer3dx",
        metavar="NAME",
        help=f"robot profile: {', '.join(sorted(PROFILES))} (default: pioneer3dx)",
    )
    parser.add_argument(
        "--scan-topic",
        metavar="T",
        help="LaserScan topic (default: the log's only one, or /scan)",
    )
    parser.add_argument(
        "--cmd-topic",
        metavar="T",
        help="Twist, TwistStamped or Odometry topic giving the commanded velocity (default: "
        "/cmd_vel or the log's only Twist topic, else its odometry differentiated)",
    )
    parser.add_argument("--record", metavar="FILE.rrd", help="save a Rerun recording")
    parser.add_argument("--summary", metavar="FILE.json", help="also write the summary here")


@dataclass(frozen=True, slots=True)
class Topics:
    """The topics a replay reads: scans, and the command or odometry topic."""

    scan: str
    command: str
    command_type: str  # TWIST, TWIST_STAMPED or ODOMETRY


def run(args: argparse.Namespace) -> int:
    try:
        profile = get_profile(args.profile)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    try:
        replayer = Replayer.for_filter(args.filter, profile)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    path = Path(args.log)
    if not path.exists():
        raise UsageError(f"{path}: no such file or directory")
    path = log_file_in(path)
    for out in (args.record, args.summary):
        if out is not None and not Path(out).resolve().parent.is_dir():
            raise UsageError(f"{out}: its folder does not exist")
    with _problems_named(path):
        summary = replay(path, replayer, args.scan_topic, args.cmd_topic, args.record)
    text = json.dumps(summary, indent=2)
    if args.summary:
        Path(args.summary).write_text(text + "\n")
    try:
        print(text, flush=True)
    except BrokenPipeError:  # the reader left (``| head``): no traceback, no second error at exit
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    if args.record:
        print(
            f"recording saved: {args.record} (open it with: rerun {args.record})", file=sys.stderr
        )
    return 0


def log_file_in(path: Path) -> Path:
    """``path`` itself, unless it is a folder without ``metadata.yaml`` (a ROS 2 bag whose
    metadata was lost, or a folder holding a log): then its only ``.mcap``, ``.db3`` or
    ``.bag`` file, said on stderr; UsageError when it holds none or several."""
    if not path.is_dir() or (path / "metadata.yaml").exists():
        return path
    found = sorted(p for p in path.iterdir() if p.is_file() and p.suffix.lower() in LOG_SUFFIXES)
    if not found:
        raise UsageError(
            f"{path}: not a ROS 2 bag (no metadata.yaml) and no .mcap, .db3 or .bag file in it"
        )
    if len(found) > 1:
        names = ", ".join(p.name for p in found)
        raise UsageError(
            f"{path}: no metadata.yaml and several log files ({names}): give one file, or "
            "restore metadata.yaml to replay them as one bag"
        )
    print(
        f"egc-teleop replay: {path} has no metadata.yaml: replaying its only log file, "
        f"{found[0].name}",
        file=sys.stderr,
    )
    return found[0]


@contextlib.contextmanager
def _problems_named(path: Path) -> Iterator[None]:
    """Turns whatever a bad log raises while it is read into one UsageError line."""
    try:
        yield
    except _LOG_ERRORS as exc:
        detail = " ".join(str(exc).split()) or type(exc).__name__
        raise UsageError(f"{path}: cannot read this log ({detail})") from None


def _log_errors() -> tuple[type[BaseException], ...]:
    from rosbags.highlevel import AnyReaderError
    from rosbags.rosbag1 import ReaderError as Reader1Error
    from rosbags.rosbag2 import ReaderError as Reader2Error
    from rosbags.typesys import TypesysError

    # Truncated files surface as struct, EOF, decompression or sqlite errors from the storage
    # layers; a log is data, so any of these is a bad log, not a bug here.
    return (
        AnyReaderError,
        Reader1Error,
        Reader2Error,
        TypesysError,
        OSError,
        EOFError,
        struct.error,
        ValueError,
        KeyError,
        IndexError,
    )


_LOG_ERRORS = _log_errors()


def choose_topics(
    topics: dict[str, str], scan_topic: str | None, cmd_topic: str | None, log: Path
) -> Topics:
    """Pick the scan and command topics from ``topic -> message type``; UsageError names the
    problem (missing topic, wrong type, several candidates)."""
    listing = ", ".join(f"{t} ({m})" for t, m in sorted(topics.items())) or "none"
    if scan_topic is not None:
        scan = _named(topics, scan_topic, (LASER_SCAN,), log, listing)
    else:
        scan = _only(topics, (LASER_SCAN,), DEFAULT_SCAN_TOPIC, "--scan-topic", log, listing)
        if scan is None:
            raise UsageError(f"{log}: no sensor_msgs/LaserScan topic (topics: {listing})")
    if cmd_topic is not None:
        command = _named(topics, cmd_topic, (*COMMAND_TYPES, ODOMETRY), log, listing)
    else:
        command = _only(topics, COMMAND_TYPES, DEFAULT_CMD_TOPIC, "--cmd-topic", log, listing)
        if command is None:
            command = _only(topics, (ODOMETRY,), DEFAULT_ODOM_TOPIC, "--cmd-topic", log, listing)
        if command is None:
            raise UsageError(
                f"{log}: no geometry_msgs/Twist or TwistStamped and no nav_msgs/Odometry topic "
                f"to take the commanded velocity from (topics: {listing})"
            )
    return Topics(scan, command, topics[command])


def _named(
    topics: dict[str, str], name: str, types: tuple[str, ...], log: Path, listing: str
) -> str:
    if name not in topics:
        raise UsageError(f"{log}: no topic {name!r} (topics: {listing})")
    if topics[name] not in types:
        wanted = " or ".join(types)
        raise UsageError(f"{log}: topic {name!r} is {topics[name]}, not {wanted}")
    return name


def _only(
    topics: dict[str, str],
    types: tuple[str, ...],
    default: str,
    flag: str,
    log: Path,
    listing: str,
) -> str | None:
    found = sorted(t for t, m in topics.items() if m in types)
    if not found:
        return None
    if len(found) == 1:
        return found[0]
    if default in found:
        return default
    raise UsageError(
        f"{log}: several {' or '.join(types)} topics ({', '.join(found)}): pick one with {flag}"
    )


def _reader(path: Path) -> Any:
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    # Logs without embedded definitions (older .db3) are read with ROS 2 Jazzy's types.
    return AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY))


def _stamp_ns(msg: Any) -> int:
    header = getattr(msg, "header", None)
    if header is None:
        return 0
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def _commands(reader: Any, topics: Topics) -> tuple[CommandTrack, int]:
    """The command track and the number of messages it came from."""
    connections = [c for c in reader.connections if c.topic == topics.command]
    samples: list[VelocitySample] = []
    poses: list[Pose2D] = []
    count = 0
    for conn, log_ns, raw in reader.messages(connections=connections):
        msg = reader.deserialize(raw, conn.msgtype)
        count += 1
        if topics.command_type == ODOMETRY:
            p, q = msg.pose.pose.position, msg.pose.pose.orientation
            yaw = yaw_from_quaternion(q.x, q.y, q.z, q.w)
            poses.append(Pose2D(log_ns, _stamp_ns(msg), p.x, p.y, yaw))
        else:
            twist = msg.twist if topics.command_type == TWIST_STAMPED else msg
            samples.append(VelocitySample(log_ns, twist.linear.x, twist.angular.z))
    if topics.command_type == ODOMETRY:
        return CommandTrack.of(velocities_from_poses(poses), ODOMETRY_MAX_AGE_S), count
    return CommandTrack.of(samples), count


def _scans(reader: Any, topic: str) -> Iterator[LogScan | str]:
    """The topic's scans; a record whose bytes do not deserialize is the reason, as a str (one
    damaged record is skipped like a corrupt scan, not the end of the replay)."""
    connections = [c for c in reader.connections if c.topic == topic]
    for conn, log_ns, raw in reader.messages(connections=connections):
        try:
            m = reader.deserialize(raw, conn.msgtype)
        except _LOG_ERRORS as exc:
            yield "cannot deserialize: " + (" ".join(str(exc).split()) or type(exc).__name__)
            continue
        # A damaged log's ranges may hold signalling NaNs: casting them is no warning here
        # (scan_fault judges the values).
        with np.errstate(invalid="ignore"):
            ranges = np.asarray(m.ranges, dtype=np.float64)
        yield LogScan(
            log_ns,
            _stamp_ns(m),
            float(m.angle_min),
            float(m.angle_increment),
            float(m.range_min),
            float(m.range_max),
            ranges,
        )


def replay(
    path: Path,
    replayer: Replayer,
    scan_topic: str | None = None,
    cmd_topic: str | None = None,
    record: str | None = None,
    progress: bool | None = None,
) -> dict[str, Any]:
    """Replay the log at ``path``; returns the summary as a JSON-ready dict.

    ``progress`` None shows the bar on an interactive stderr only (after a second).
    """
    from tqdm import tqdm

    with _reader(path) as reader:
        types: dict[str, str] = {}
        for c in reader.connections:
            types.setdefault(c.topic, c.msgtype)
        topics = choose_topics(types, scan_topic, cmd_topic, path)
        total = sum(c.msgcount for c in reader.connections if c.topic == topics.scan)
        track, command_messages = _commands(reader, topics)
        if command_messages == 0:
            raise UsageError(f"{path}: topic {topics.command!r} has no messages")
        recorder = None
        if record is not None:
            from egc_app.replay_record import ReplayRecording

            recorder = ReplayRecording(record, path.name, replayer, topics.scan, topics.command)
        verdicts: list[ScanVerdict] = []
        corrupt = 0
        first_corrupt: tuple[int, str] | None = None  # index on the topic, why
        memory: object | None = None
        bar = tqdm(
            total=total or None,
            unit="scan",
            file=sys.stderr,
            disable=(not sys.stderr.isatty()) if progress is None else not progress,
            delay=1.0,
            desc=f"replay {path.name}",
        )
        try:
            footprint = replayer.config.profile.half_size_m
            for index, scan in enumerate(_scans(reader, topics.scan)):
                fault = scan if isinstance(scan, str) else scan_fault(scan)
                if fault is not None or isinstance(scan, str):
                    corrupt += 1
                    first_corrupt = first_corrupt or (index, fault)
                    bar.update()
                    continue
                points = scan_points(scan, footprint)
                command = track.at(scan.log_ns)
                verdict, result, obstacles, memory = replayer.step(scan, points, command, memory)
                verdicts.append(verdict)
                if recorder is not None:
                    recorder.on_scan(verdict, result, obstacles)
                bar.update()
        finally:
            bar.close()
            if recorder is not None:
                recorder.close()
    if first_corrupt is not None:
        index, why = first_corrupt
        what = f"{corrupt} of {corrupt + len(verdicts)} scans on {topics.scan!r}"
        if not verdicts:
            raise UsageError(
                f"{path}: every scan is corrupt, nothing to replay ({what}; "
                f"first, index {index}: {why})"
            )
        print(
            f"egc-teleop replay: skipped {what} as corrupt (undecodable, or fields no "
            f"sensor sends; first, index {index}: {why})",
            file=sys.stderr,
        )
    if not verdicts:
        raise UsageError(f"{path}: topic {topics.scan!r} has no scans")
    kind = {ODOMETRY: "odometry poses", TWIST_STAMPED: "twist-stamped"}.get(
        topics.command_type, "twist"
    )
    extra = {
        "log": str(path),
        "scan_topic": topics.scan,
        "command_topic": topics.command,
        "command_source": kind,
        "command_messages": command_messages,
        "scans_without_command": sum(1 for v in verdicts if not v.has_command),
        "scans_corrupt": corrupt,
    }
    summary = summarize(verdicts, replayer.config.filter, replayer.config.profile.name, extra)
    out = summary.as_dict()
    if out["closest_m"] is not None and not math.isfinite(out["closest_m"]):
        out["closest_m"] = None
    return out
