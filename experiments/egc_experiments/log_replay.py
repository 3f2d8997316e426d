"""A recorded robot log through a filter of the family, offline (DESIGN 11): the engine of
``egc-teleop replay LOG`` (its arguments and output: ``egc_app.replay_cmd``).

LOG is a ROS 1 ``.bag``, a ROS 2 bag directory, or a single ``.db3`` or ``.mcap`` file, read
with the ``rosbags`` library (no ROS install). Each ``sensor_msgs/LaserScan`` goes through the
robot's own pipeline (``egc_robot.pipeline``) with the velocity commanded at the time: the log's
``geometry_msgs/Twist`` or ``TwistStamped`` topic when it has one, else the forward speed and
turn rate derived from successive ``nav_msgs/Odometry`` poses (an odometry twist may be in the
world frame). The pure part (pairing, REP 117, odometry, summary) is ``egc_robot.replay_core``;
this module reads the log, shows progress on stderr, returns the summary and saves the Rerun
recording (``egc_experiments.replay_recording``) on the log's own timeline (``bag_time``, the
recorder's receive time; ``stamp``, the scans' header stamps).

A log that cannot be replayed (missing, not a bag, truncated, without the topics it needs, a
topic of the wrong type, every scan corrupt, nothing readable) is a ``UsageError`` naming the
problem (one line on stderr and exit code 2 from the CLI). A scan no sensor could have sent
(``replay_core.scan_fault``: garbage from a damaged storage file) is skipped and counted
(``scans_corrupt``), with one line on stderr; so is a command record that does not deserialize or holds no real velocity
(``command_messages_corrupt``). A folder without ``metadata.yaml`` that holds one ``.mcap``,
``.db3`` or ``.bag`` file replays that file.

Damaged storage. Whatever the storage layer raises while a pass reads the log (rosbags, apsw,
the MCAP parser: a damaged file makes them raise almost anything) ends that pass where it is,
never the process; a reader may also stop early without raising (an MCAP chunk whose lengths
were overwritten). Either way what was read is replayed, and when the log declares more
messages than were read (its metadata, MCAP statistics or ROS 1 index) one line on stderr says
how many were read of how many, and from when the file is damaged; ``scans_unread``,
``command_messages_unread`` and ``read_error`` in the summary say the same. A pass that read
nothing because the reader failed is a bad log (exit 2).

Stale commands. A Twist is in effect for ``--cmd-timeout-s`` (default 0.5 s, as a base stops
when ``cmd_vel`` falls silent) after it was received; a scan after that is replayed without a
command (``scans_without_command``; ``scans_command_stale`` counts those after a command went
stale), with one line on stderr. Pose-derived velocities keep their own 1 s limit.
"""

from __future__ import annotations

import collections
import contextlib
import functools
import math
import struct
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from egc_common.errors import UsageError
from egc_robot.replay_core import (
    COMMAND_MAX_AGE_S,
    ODOMETRY_MAX_AGE_S,
    CommandTrack,
    LogScan,
    Pose2D,
    Replayer,
    ScanVerdict,
    VelocitySample,
    pose_fault,
    scan_fault,
    scan_points,
    summarize,
    velocities_from_poses,
    velocity_fault,
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


@dataclass(frozen=True, slots=True)
class Topics:
    """The topics a replay reads: scans, and the command or odometry topic."""

    scan: str
    command: str
    command_type: str  # TWIST, TWIST_STAMPED or ODOMETRY


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

    # Logs without embedded definitions (older .db3) are read with ROS 2 Jazzy's types.
    return AnyReader([path], default_typestore=_jazzy_typestore())


@functools.cache
def _jazzy_typestore() -> Any:
    """ROS 2 Jazzy's types, built once: building them takes longer than opening a short log,
    and AnyReader only reads them (it copies their definitions into a typestore of its own)."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


_TYPESTORES: collections.OrderedDict[str, Any] = collections.OrderedDict()


def _shared_typestore(typestore: Any) -> Any:
    """A typestore with the very same message definitions from an earlier log, if there was
    one (the last few are kept), else ``typestore``. rosbags generates and compiles a
    deserializer per message type and typestore, and each reader builds a typestore of its
    own: replaying several logs in one process (a batch, a test run) compiles them once."""
    key = repr(sorted(typestore.fielddefs.items()))
    if key in _TYPESTORES:
        _TYPESTORES.move_to_end(key)
        return _TYPESTORES[key]
    _TYPESTORES[key] = typestore
    while len(_TYPESTORES) > 8:
        _TYPESTORES.popitem(last=False)
    return typestore


def _why(exc: BaseException) -> str:
    """An exception as one line: its type and message."""
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


@dataclass(slots=True)
class TopicPass:
    """One pass over one topic of the log: how far the reader got, against what the log
    declares (0: the log does not say)."""

    topic: str
    declared: int
    read: int = 0  # records the reader gave, decodable or not
    first_ns: int | None = None
    last_ns: int | None = None
    error: str | None = None  # what the reader raised, if it did

    @property
    def unread(self) -> int:
        return max(0, self.declared - self.read)


def _records(reader: Any, state: TopicPass) -> Iterator[tuple[Any, int, bytes]]:
    """The topic's records as the reader gives them. Whatever the reader raises (a damaged
    storage file makes rosbags, apsw or the MCAP parser raise almost anything) ends the pass,
    noted in ``state``; only the reader's own calls are guarded, never the caller's code."""
    connections = [c for c in reader.connections if c.topic == state.topic]
    try:
        it = iter(reader.messages(connections=connections))
    except Exception as exc:  # the reader's, on a damaged file: see above
        state.error = _why(exc)
        return
    while True:
        try:
            conn, log_ns, raw = next(it)
        except StopIteration:
            return
        except Exception as exc:  # the reader's, on a damaged file: see above
            state.error = _why(exc)
            return
        state.read += 1
        state.first_ns = log_ns if state.first_ns is None else state.first_ns
        state.last_ns = log_ns
        yield conn, log_ns, raw


def _deserialize(reader: Any, conn: Any, raw: bytes) -> tuple[Any, str | None]:
    """The message, or None and why it does not deserialize (a damaged record)."""
    try:
        return reader.deserialize(raw, conn.msgtype), None
    except Exception as exc:  # rosbags' decoder over damaged bytes
        return None, "cannot deserialize: " + _why(exc)


def _stamp_ns(msg: Any) -> int:
    header = getattr(msg, "header", None)
    if header is None:
        return 0
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


@dataclass(slots=True)
class CommandsRead:
    """The command pass: the track, and the records it came from."""

    track: CommandTrack
    state: TopicPass
    corrupt: int
    first_corrupt: tuple[int, str] | None  # index on the topic, why


def _commands(reader: Any, topics: Topics, state: TopicPass, max_age_s: float) -> CommandsRead:
    """The command track (a Twist holds for ``max_age_s``, a pose-derived velocity for
    ``ODOMETRY_MAX_AGE_S``); records that do not deserialize or hold no real velocity or pose
    are skipped and counted."""
    samples: list[VelocitySample] = []
    poses: list[Pose2D] = []
    corrupt = 0
    first: tuple[int, str] | None = None
    for index, (conn, log_ns, raw) in enumerate(_records(reader, state)):
        msg, fault = _deserialize(reader, conn, raw)
        if msg is not None:
            try:
                if topics.command_type == ODOMETRY:
                    p, q = msg.pose.pose.position, msg.pose.pose.orientation
                    yaw = yaw_from_quaternion(q.x, q.y, q.z, q.w)
                    pose = Pose2D(log_ns, _stamp_ns(msg), float(p.x), float(p.y), yaw)
                    fault = pose_fault(pose)
                    if fault is None:
                        poses.append(pose)
                else:
                    twist = msg.twist if topics.command_type == TWIST_STAMPED else msg
                    v, w = float(twist.linear.x), float(twist.angular.z)
                    fault = velocity_fault(v, w)
                    if fault is None:
                        samples.append(VelocitySample(log_ns, v, w))
            except (ValueError, OverflowError, ArithmeticError) as exc:  # garbage floats
                fault = _why(exc)
        if fault is not None:
            corrupt += 1
            first = first or (index, fault)
    if topics.command_type == ODOMETRY:
        track = CommandTrack.of(velocities_from_poses(poses), ODOMETRY_MAX_AGE_S)
    else:
        track = CommandTrack.of(samples, max_age_s)
    return CommandsRead(track, state, corrupt, first)


def _scans(reader: Any, state: TopicPass) -> Iterator[LogScan | str]:
    """The topic's scans; a record whose bytes do not deserialize is the reason, as a str (one
    damaged record is skipped like a corrupt scan, not the end of the replay)."""
    for conn, log_ns, raw in _records(reader, state):
        m, why = _deserialize(reader, conn, raw)
        if m is None:
            yield why or "cannot deserialize"
            continue
        try:
            # A damaged log's ranges may hold signalling NaNs: casting them is no warning
            # here (scan_fault judges the values).
            with np.errstate(invalid="ignore"):
                ranges = np.asarray(m.ranges, dtype=np.float64)
            scan = LogScan(
                log_ns,
                _stamp_ns(m),
                float(m.angle_min),
                float(m.angle_increment),
                float(m.range_min),
                float(m.range_max),
                ranges,
            )
        except (ValueError, TypeError, OverflowError) as exc:
            yield "cannot read its fields: " + _why(exc)
            continue
        yield scan


def _open(path: Path) -> tuple[Any, dict[str, str], dict[str, int]]:
    """The open reader, ``topic -> message type`` and ``topic -> messages declared``; whatever
    opening a damaged file raises is one UsageError line."""
    reader: Any = None
    try:
        reader = _reader(path)
        reader.open()
        reader.typestore = _shared_typestore(reader.typestore)
        types: dict[str, str] = {}
        declared: dict[str, int] = {}
        for c in reader.connections:
            types.setdefault(c.topic, c.msgtype)
            declared[c.topic] = declared.get(c.topic, 0) + max(0, int(c.msgcount or 0))
    except Exception as exc:  # the reader's, on a damaged file
        if reader is not None:
            _close(reader)
        detail = " ".join(str(exc).split()) or type(exc).__name__
        raise UsageError(f"{path}: cannot read this log ({detail})") from None
    return reader, types, declared


def _close(reader: Any) -> None:
    with contextlib.suppress(Exception):  # a damaged file may fail to close too: nothing lost
        reader.close()


def _t_s(ns: int, t0_ns: int) -> str:
    return f"{(ns - t0_ns) / 1e9:.1f}"


def unread_line(
    scans: TopicPass, commands: TopicPass, t0_ns: int, end_ns: int | None
) -> str | None:
    """One stderr line when a pass stopped before the end of the log: how much it read of what
    the log declares, from when the file is damaged, and what the reader raised; None when
    every pass read all it should."""
    short = [p for p in (scans, commands) if p.unread or p.error]
    if not short:
        return None
    parts = []
    for p in (scans, commands):
        if not p.unread:
            continue
        what = "scans" if p is scans else "messages"
        if parts:
            parts.append(f"{p.read} of the {p.declared} {what} on {p.topic!r}")
        else:
            parts.append(
                f"read {p.read} of the {p.declared} {what} the log declares on {p.topic!r}"
            )
    ends = [p.last_ns for p in short if p.last_ns is not None]
    after = min(ends) if ends else t0_ns
    total = ""
    if end_ns is not None and end_ns > after:
        total = f" of {_t_s(end_ns, t0_ns)} s"
    errors = "; ".join(dict.fromkeys(p.error for p in short if p.error))
    reason = f" (the reader: {errors})" if errors else ""
    if parts:
        return (
            f"egc-teleop replay: {' and '.join(parts)}: the file is damaged after "
            f"t = {_t_s(after, t0_ns)} s{total}; the rest was not replayed{reason}"
        )
    topics = " and ".join(repr(p.topic) for p in short)
    return (
        f"egc-teleop replay: reading {topics} stopped at t = {_t_s(after, t0_ns)} s{total}: "
        f"anything after it was not replayed{reason}"
    )


def replay(
    path: Path,
    replayer: Replayer,
    scan_topic: str | None = None,
    cmd_topic: str | None = None,
    record: str | None = None,
    progress: bool | None = None,
    cmd_timeout_s: float = COMMAND_MAX_AGE_S,
) -> dict[str, Any]:
    """Replay the log at ``path`` (``log_file_in`` first for a folder without metadata);
    returns the summary as a JSON-ready dict. A log that cannot be replayed is a UsageError
    naming the problem (module docstring).

    ``progress`` None shows the bar on an interactive stderr only (after a second).
    ``cmd_timeout_s``: how long a Twist stays in effect after it was received.
    """
    reader, types, declared = _open(path)
    try:
        with _problems_named(path):
            return _replay(
                reader,
                types,
                declared,
                path,
                replayer,
                scan_topic,
                cmd_topic,
                record,
                progress,
                cmd_timeout_s,
            )
    finally:
        _close(reader)


def _replay(
    reader: Any,
    types: dict[str, str],
    declared: dict[str, int],
    path: Path,
    replayer: Replayer,
    scan_topic: str | None,
    cmd_topic: str | None,
    record: str | None,
    progress: bool | None,
    cmd_timeout_s: float,
) -> dict[str, Any]:
    from tqdm import tqdm

    topics = choose_topics(types, scan_topic, cmd_topic, path)
    command_pass = TopicPass(topics.command, declared.get(topics.command, 0))
    commands = _commands(reader, topics, command_pass, cmd_timeout_s)
    if command_pass.read == 0:
        if command_pass.error is not None:
            raise UsageError(f"{path}: cannot read this log ({command_pass.error})")
        raise UsageError(f"{path}: topic {topics.command!r} has no messages")
    track = commands.track
    scan_pass = TopicPass(topics.scan, declared.get(topics.scan, 0))
    recorder = None
    if record is not None:
        from egc_experiments.replay_recording import ReplayRecording

        recorder = ReplayRecording(record, path.name, replayer, topics.scan, topics.command)
    verdicts: list[ScanVerdict] = []
    corrupt = 0
    stale = 0
    first_stale_ns: int | None = None
    first_corrupt: tuple[int, str] | None = None  # index on the topic, why
    memory: object | None = None
    bar = tqdm(
        total=scan_pass.declared or None,
        unit="scan",
        file=sys.stderr,
        disable=(not sys.stderr.isatty()) if progress is None else not progress,
        delay=1.0,
        desc=f"replay {path.name}",
    )
    try:
        footprint = replayer.config.profile.footprint
        for index, scan in enumerate(_scans(reader, scan_pass)):
            fault = scan if isinstance(scan, str) else scan_fault(scan)
            if fault is not None or isinstance(scan, str):
                corrupt += 1
                first_corrupt = first_corrupt or (index, fault)
                bar.update()
                continue
            points = scan_points(scan, footprint)
            command = track.at(scan.log_ns)
            if command is None and track.stale_at(scan.log_ns):
                stale += 1
                first_stale_ns = scan.log_ns if first_stale_ns is None else first_stale_ns
            verdict, result, obstacles, memory = replayer.step(scan, points, command, memory)
            verdicts.append(verdict)
            if recorder is not None:
                recorder.on_scan(verdict, result, obstacles)
            bar.update()
    finally:
        bar.close()
        if recorder is not None:
            recorder.close()
    if scan_pass.read == 0 and scan_pass.error is not None:
        raise UsageError(f"{path}: cannot read this log ({scan_pass.error})")
    starts = [p.first_ns for p in (scan_pass, command_pass) if p.first_ns is not None]
    t0_ns = min(starts)
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
    if commands.first_corrupt is not None:
        index, why = commands.first_corrupt
        print(
            f"egc-teleop replay: skipped {commands.corrupt} of {command_pass.read} messages on "
            f"{topics.command!r} as corrupt (undecodable, or no velocity or pose a robot "
            f"has; first, index {index}: {why})",
            file=sys.stderr,
        )
    line = unread_line(scan_pass, command_pass, t0_ns, _end_ns(reader))
    if line is not None:
        print(line, file=sys.stderr)
    kind = {ODOMETRY: "odometry poses", TWIST_STAMPED: "twist-stamped"}.get(
        topics.command_type, "twist"
    )
    max_age_s = ODOMETRY_MAX_AGE_S if topics.command_type == ODOMETRY else cmd_timeout_s
    if stale and topics.command_type != ODOMETRY and first_stale_ns is not None:
        print(
            f"egc-teleop replay: {stale} of {len(verdicts)} scans came over {max_age_s:g} s "
            f"after the latest message on {topics.command!r} (the first at t = "
            f"{_t_s(first_stale_ns, t0_ns)} s): replayed without a command, as a base stops "
            "when cmd_vel falls silent (--cmd-timeout-s sets how long)",
            file=sys.stderr,
        )
    extra = {
        "log": str(path),
        "scan_topic": topics.scan,
        "command_topic": topics.command,
        "command_source": kind,
        "command_messages": command_pass.read - commands.corrupt,
        "command_max_age_s": max_age_s if math.isfinite(max_age_s) else None,
        "scans_without_command": sum(1 for v in verdicts if not v.has_command),
        "scans_command_stale": stale,
        "scans_corrupt": corrupt,
        "command_messages_corrupt": commands.corrupt,
        "scans_unread": scan_pass.unread,
        "command_messages_unread": command_pass.unread,
        "read_error": scan_pass.error or command_pass.error,
    }
    profile = replayer.config.profile
    limits = (profile.v_max_mps, profile.w_max_radps)
    summary = summarize(verdicts, replayer.config.filter, profile.name, extra, limits)
    out = summary.as_dict()
    if out["closest_m"] is not None and not math.isfinite(out["closest_m"]):
        out["closest_m"] = None
    return out


def _end_ns(reader: Any) -> int | None:
    """The log's declared end (its last message's receive time), or None when it does not
    say or the value is garbage."""
    try:
        end = int(reader.end_time)
    except Exception:  # a damaged summary or index
        return None
    return end if end > 0 else None
