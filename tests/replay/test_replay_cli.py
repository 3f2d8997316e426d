"""``egc-teleop replay LOG`` end to end (DESIGN 11, issue 14 item 4): the real third-party ROS 1
log ``../shared/bags/Mapping1.bag``, ROS 2 logs written here (MCAP and sqlite3, with a Twist
topic and with odometry only), the summary's pinned keys, the .rrd read back, and bad logs."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
from egc_robot.pipeline import FILTERS
from rosbags.rosbag2 import StoragePlugin, Writer

from tests.cli_process import parse
from tests.cli_worker import main
from tests.replay.logs import (
    PERIOD_NS,
    START_NS,
    TS,
    corridor_log,
    garbled_ranges,
    scan_msg,
    wall_ranges,
)
from tests.view.rrd import read_recording

MAPPING1 = Path(__file__).resolve().parents[2] / ".." / "shared" / "bags" / "Mapping1.bag"
PINNED = ("scans", "commands", "changed", "max_cut_mps", "hold_s", "closest_m", "filter", "profile")

# Command lines run in one long-lived CLI process (``tests.cli_worker``): these tests are about
# what ``egc-teleop replay`` prints, writes and returns; the ones about a process of its own
# start ``python -m egc_app.cli`` (``test_a_real_process_*``, ``*_in_a_real_process_*``).


def replay(capsys, *args: str) -> tuple[int, dict | None, str]:
    code = main(["replay", *args])
    out, err = capsys.readouterr()
    return code, (json.loads(out) if code == 0 else None), err


@pytest.fixture(scope="module")
def mapping1_egc(tmp_path_factory):
    rrd = tmp_path_factory.mktemp("mapping1") / "mapping1.rrd"
    summary = rrd.with_suffix(".json")
    code = main(["replay", str(MAPPING1), "--record", str(rrd), "--summary", str(summary)])
    assert code == 0
    return json.loads(summary.read_text()), rrd


def test_mapping1_summary(mapping1_egc):
    s, _ = mapping1_egc
    assert all(k in s for k in PINNED)
    assert s["filter"] == "egc" and s["profile"] == "pioneer3dx"
    # 1727 scans on /base_scan; no cmd_vel, so the velocity comes from the ground-truth poses
    assert s["scans"] == 1727 and s["scan_topic"] == "/base_scan"
    assert (
        s["command_topic"] == "/base_pose_ground_truth" and s["command_source"] == "odometry poses"
    )
    assert s["commands"] == 1726  # the first scan comes before any pose difference
    assert 0 < s["changed"] <= s["commands"] and s["hold_s"] > 0
    assert 0.9 < s["max_cut_mps"] <= 1.0 + 1e-6  # the robot drives up to 1.0 m/s (README)
    assert s["closest_m"] == pytest.approx(0.1005, abs=1e-3)  # the nearest reading in the log
    assert s["duration_s"] == pytest.approx(172.7, abs=0.2)  # 10 Hz by header stamp
    assert 0 < s["hold_s"] < s["moving_s"] <= s["duration_s"]


def test_mapping1_velocities_come_from_poses_not_the_world_frame_twist(mapping1_egc):
    _, rrd = mapping1_egc
    rec = read_recording(rrd)
    v = np.array([x[0] for x in rec["/velocity/v/recorded"].column("Scalars:scalars")])
    w = np.array([x[0] for x in rec["/velocity/w/recorded"].column("Scalars:scalars")])
    # README: median forward speed 0.46 m/s, up to 1.0 m/s (the twist's linear.x is unrelated)
    assert np.median(v) == pytest.approx(0.46, abs=0.01) and v.max() == pytest.approx(1.0, abs=0.01)
    assert np.abs(w).max() < 1.0
    # the log's own timeline: Stage's sim time, 60.2 s to 232.8 s
    t = rec["/robot/scan"].rows.column("bag_time").cast(pa.int64()).to_pylist()
    assert len(t) == 1727 and t[0] == 60_200_000_000 and t[-1] == 232_800_000_000


def test_mapping1_under_none_changes_nothing(capsys):
    # jackal: the log's speeds (<= 1.0 m/s, <= 0.49 rad/s) are within its limits
    code, s, _ = replay(capsys, str(MAPPING1), "--filter", "none", "--profile", "jackal")
    assert code == 0 and s["filter"] == "none" and s["profile"] == "jackal"
    assert s["changed"] == 0 and s["hold_s"] == 0 and s["max_cut_mps"] == 0
    assert s["scans"] == 1727 and s["closest_m"] == pytest.approx(0.1005, abs=1e-3)


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
@pytest.mark.parametrize("command", ["twist", "twist-stamped", "odometry"])
def test_ros2_log_wall_ahead(tmp_path, capsys, storage, command):
    log = corridor_log(tmp_path / "log", storage, command=command)
    code, s, _ = replay(capsys, str(log))
    assert code == 0 and all(k in s for k in PINNED)
    with_cmd = 30 if command != "odometry" else 29  # odometry: the first pose gives no speed
    assert s["scans"] == 30 and s["commands"] == with_cmd
    assert s["changed"] > 0 and s["hold_s"] > 0 and s["max_cut_mps"] == pytest.approx(0.12)
    assert s["closest_m"] == pytest.approx(0.3, abs=1e-6)  # the wall, last scan
    assert s["command_topic"] == ("/odom" if command == "odometry" else "/cmd_vel")
    assert s["command_source"] == {"odometry": "odometry poses"}.get(command, command)
    code, s, _ = replay(capsys, str(log), "--filter", "none")
    assert code == 0 and s["changed"] == 0 and s["hold_s"] == 0 and s["filter"] == "none"


def test_ros2_storage_file_alone_and_far_wall_passes(tmp_path, capsys):
    log = corridor_log(tmp_path / "far", "sqlite3", wall_m=[7.0] * 20)
    (db3,) = log.glob("*.db3")
    code, s, _ = replay(capsys, str(db3))
    assert code == 0 and s["scans"] == 20 and s["changed"] == 0 and s["hold_s"] == 0
    log = corridor_log(tmp_path / "near", "mcap")
    (mcap,) = log.glob("*.mcap")
    code, s, _ = replay(capsys, str(mcap), "--summary", str(tmp_path / "s.json"))
    assert code == 0 and s["hold_s"] > 0
    assert json.loads((tmp_path / "s.json").read_text()) == s


def test_recording_shows_scans_circles_and_both_velocities_on_the_log_timeline(tmp_path, capsys):
    log = corridor_log(tmp_path / "log", "mcap", command="odometry")
    rrd = tmp_path / "r.rrd"
    code, s, err = replay(capsys, str(log), "--record", str(rrd))
    assert code == 0 and str(rrd) in err
    rec = read_recording(rrd)
    for entity in (
        "/robot/scan",
        "/robot/circles/igc",
        "/robot/circles/egc",
        "/robot/recorded",
        "/robot/filtered",
        "/velocity/v/recorded",
        "/velocity/v/filtered",
        "/velocity/w/recorded",
        "/velocity/w/filtered",
    ):
        assert entity in rec, entity
    scans = rec["/robot/scan"]
    assert len(scans) == 30
    t = scans.rows.column("bag_time").cast(pa.int64()).to_pylist()
    assert t == [START_NS + i * PERIOD_NS for i in range(30)]
    # one point per beam that hit the wall (+inf and NaN beams are not points)
    hits = int(np.sum(np.isfinite(wall_ranges(1.0))))
    assert len(scans.column("Points2D:positions")[0]) == hits
    # recorded: 0.12 m/s from poses in a turned world frame; filtered: stops before the wall
    rv = [x[0] for x in rec["/velocity/v/recorded"].column("Scalars:scalars")]
    fv = [x[0] for x in rec["/velocity/v/filtered"].column("Scalars:scalars")]
    assert len(rv) == len(fv) == 29 and rv == pytest.approx([0.12] * 29)
    assert fv[0] == pytest.approx(0.12) and fv[-1] == 0.0
    # the initial guide circle is centred where the recorded command leads (eq. 6)
    igc = rec["/robot/circles/igc"].column("Ellipses2D:centers")
    assert any(c for c in igc) and all(c[0][1] == pytest.approx(0.0, abs=1e-9) for c in igc if c)
    lane = [x[0] for x in rec["/filter"].column("StateChange:state")]
    assert lane[0] == "no command" and "hold" in lane
    events = [x[0] for x in rec["/events"].column("TextLog:text")]
    assert any("egc holds" in e for e in events)
    hold_rows = sum(1 for v in fv if abs(v) <= 0.01)
    assert s["hold_s"] == pytest.approx(hold_rows * 0.1)


def bad(capsys, *args: str) -> str:
    code = main(["replay", *args])
    out, err = capsys.readouterr()
    assert code == 2 and out == "", (code, out, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("egc-teleop replay: error: "), err
    return lines[0]


def test_bad_logs_one_clear_line(tmp_path, capsys):
    truncated = tmp_path / "truncated.bag"
    truncated.write_bytes(MAPPING1.read_bytes()[:300_000])
    assert "cannot read this log" in bad(capsys, str(truncated))
    text = tmp_path / "notes.bag"
    text.write_text("not a bag\n")
    assert "cannot read this log" in bad(capsys, str(text))
    other = tmp_path / "notes.txt"
    other.write_text("not a bag\n")
    assert "'.txt'" in bad(capsys, str(other))
    assert "no such file" in bad(capsys, str(tmp_path / "missing.bag"))
    empty_dir = tmp_path / "empty"
    empty_dir.mkdir()
    assert "metadata" in bad(capsys, str(empty_dir))
    log = corridor_log(tmp_path / "log", "mcap")
    (mcap,) = log.glob("*.mcap")
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(mcap.read_bytes()[: mcap.stat().st_size // 2])
    assert "cannot read this log" in bad(capsys, str(cut))


def test_topics_missing_or_of_the_wrong_type(tmp_path, capsys):
    log = corridor_log(tmp_path / "log", "sqlite3")
    line = bad(capsys, str(log), "--scan-topic", "/front_scan")
    assert "no topic '/front_scan'" in line and "/scan (sensor_msgs/msg/LaserScan)" in line
    assert "is geometry_msgs/msg/Twist, not" in bad(capsys, str(log), "--scan-topic", "/cmd_vel")
    assert "no topic '/joy'" in bad(capsys, str(log), "--cmd-topic", "/joy")
    # scans only: nothing to take the commanded velocity from
    only_scans = tmp_path / "only_scans"
    with Writer(only_scans, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        c = w.add_connection("/scan", "sensor_msgs/msg/LaserScan", typestore=TS)
        msg = TS.serialize_cdr(scan_msg(START_NS, wall_ranges(1.0)), "sensor_msgs/msg/LaserScan")
        w.write(c, START_NS, msg)
    assert "no geometry_msgs/Twist" in bad(capsys, str(only_scans))
    # a scan topic without a single message
    no_scans = tmp_path / "no_scans"
    with Writer(no_scans, version=9, storage_plugin=StoragePlugin.SQLITE3) as w:
        w.add_connection("/scan", "sensor_msgs/msg/LaserScan", typestore=TS)
        c = w.add_connection("/cmd_vel", "geometry_msgs/msg/Twist", typestore=TS)
        twist = TS.types["geometry_msgs/msg/Twist"]
        v3 = TS.types["geometry_msgs/msg/Vector3"]
        w.write(c, START_NS, TS.serialize_cdr(twist(v3(0.1, 0, 0), v3(0, 0, 0)), twist.__msgtype__))
    assert "has no scans" in bad(capsys, str(no_scans))


def test_bad_arguments(tmp_path, capsys):
    log = corridor_log(tmp_path / "log", "mcap")
    assert main(["replay", str(log), "--filter", "magic"]) == 2
    assert "--filter" in capsys.readouterr().err
    assert "unknown robot profile" in bad(capsys, str(log), "--profile", "roomba")
    assert "folder does not exist" in bad(capsys, str(log), "--record", str(tmp_path / "no/x.rrd"))


def test_a_real_process_prints_no_traceback(tmp_path):
    bag = tmp_path / "half.bag"
    bag.write_bytes(MAPPING1.read_bytes()[: MAPPING1.stat().st_size // 2])
    proc = subprocess.run(
        [sys.executable, "-m", "egc_app.cli", "replay", str(bag)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr.count("\n") == 1 and "Traceback" not in proc.stderr
    assert str(bag) in proc.stderr


def test_filter_choices_follow_the_pipeline():
    parsed = parse(*(["replay", "x.bag", "--filter", name] for name in FILTERS))
    assert [args["filter"] for args in parsed if isinstance(args, dict)] == list(FILTERS), parsed


@pytest.mark.parametrize("name", FILTERS)
def test_every_filter_of_the_family_replays(tmp_path, capsys, name):
    log = corridor_log(tmp_path / "log", "mcap")
    code, s, _ = replay(capsys, str(log), "--filter", name)
    assert code == 0 and s["filter"] == name and s["scans"] == 30 and s["commands"] == 30
    assert set(s["limiters"]) <= {"none", name, "sweep", "limits"}
    if name == "none":
        assert s["changed"] == 0 and s["hold_s"] == 0
    elif name != "dwa":  # dwa lets 0.12 m/s through: the robot could still stop before the wall
        assert s["changed"] > 0


def _at(i: int) -> int:
    return START_NS + i * PERIOD_NS


def test_corrupt_scans_are_skipped_counted_and_named(tmp_path, capsys):
    # Scan 5's angle_min is garbage; scan 12's ranges are random bytes (huge values of either
    # sign, NaNs, a signalling NaN), as a log with bytes written over its middle deserializes.
    garbled = {
        5: scan_msg(_at(5), wall_ranges(2.0), angle_min_rad=1e30),
        12: scan_msg(_at(12), garbled_ranges()),
    }
    log = corridor_log(tmp_path / "garbled", "mcap", scan_at=garbled)
    clean = corridor_log(tmp_path / "clean", "mcap", scan_at={5: None, 12: None})
    rrd = {name: tmp_path / f"{name}.rrd" for name in ("garbled", "clean")}
    code, s, err = replay(capsys, str(log), "--record", str(rrd["garbled"]))
    assert code == 0 and all(k in s for k in PINNED)
    skipped = [line for line in err.splitlines() if not line.startswith("recording saved")]
    assert skipped == [
        "egc-teleop replay: skipped 2 of 30 scans on '/scan' as corrupt (undecodable, or fields "
        "no sensor sends; first, index 5: angle_min 1e+30 rad)"
    ], err
    assert "Warning" not in err
    code, ref, _ = replay(capsys, str(clean), "--record", str(rrd["clean"]))
    assert code == 0 and ref["scans_corrupt"] == 0
    assert s["scans_corrupt"] == 2 and s["scans"] == ref["scans"] == 28
    for key in set(s) | set(ref):
        if key not in ("log", "scans_corrupt"):
            assert s[key] == ref[key], key
    # scan by scan, the others went through the filter exactly as without the garbled ones
    got, want = read_recording(rrd["garbled"]), read_recording(rrd["clean"])
    for entity in ("/velocity/v/filtered", "/velocity/w/filtered", "/velocity/v/recorded"):
        assert got[entity].column("Scalars:scalars") == want[entity].column("Scalars:scalars")


def test_corrupt_scan_in_a_real_process_no_numpy_warning(tmp_path):
    log = corridor_log(tmp_path / "log", "mcap", scan_at={12: scan_msg(_at(12), garbled_ranges())})
    proc = subprocess.run(
        [sys.executable, "-W", "default", "-m", "egc_app.cli", "replay", str(log)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 0 and json.loads(proc.stdout)["scans_corrupt"] == 1
    assert proc.stderr.count("\n") == 1 and "Warning" not in proc.stderr, proc.stderr
    assert "skipped 1 of 30 scans on '/scan' as corrupt" in proc.stderr
    assert "first, index 12: beam " in proc.stderr


def test_every_scan_corrupt_is_a_bad_log(tmp_path, capsys):
    garbled = {i: scan_msg(_at(i), garbled_ranges(seed=i)) for i in range(30)}
    log = corridor_log(tmp_path / "log", "sqlite3", scan_at=garbled)
    line = bad(capsys, str(log))
    assert "every scan is corrupt" in line and "30 of 30 scans on '/scan'" in line
    assert "first, index 0: beam " in line


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_folder_without_metadata_replays_its_only_log_file(tmp_path, capsys, storage):
    log = corridor_log(tmp_path / "log", storage)
    code, ref, _ = replay(capsys, str(log))
    assert code == 0
    (log / "metadata.yaml").unlink()
    (storage_file,) = (f for f in log.iterdir())
    code, s, err = replay(capsys, str(log))
    assert code == 0 and s["log"] == str(storage_file)
    assert err.splitlines() == [
        f"egc-teleop replay: {log} has no metadata.yaml: replaying its only log file, "
        f"{storage_file.name}"
    ]
    assert {k: v for k, v in s.items() if k != "log"} == {
        k: v for k, v in ref.items() if k != "log"
    }


def test_folder_without_metadata_and_several_or_no_log_files(tmp_path, capsys):
    log = corridor_log(tmp_path / "log", "mcap")
    (log / "metadata.yaml").unlink()
    (mcap,) = log.glob("*.mcap")
    (log / "second.db3").write_bytes(b"")
    line = bad(capsys, str(log))
    assert f"{log}: no metadata.yaml and several log files ({mcap.name}, second.db3)" in line
    assert "give one file, or restore metadata.yaml" in line
    assert "Expected metadata file" not in line
    notes = tmp_path / "notes"
    notes.mkdir()
    (notes / "readme.txt").write_text("not a bag\n")
    line = bad(capsys, str(notes))
    assert line.endswith(
        f"{notes}: not a ROS 2 bag (no metadata.yaml) and no .mcap, .db3 or .bag file in it"
    )


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_undecodable_scan_records_are_skipped_not_the_end(tmp_path, capsys, storage):
    """An outside check: one LaserScan record cut short (or with a garbage sequence length)
    ended the replay with exit 2, throwing away every good scan around it."""
    whole = TS.serialize_cdr(scan_msg(_at(7), wall_ranges(2.0)), "sensor_msgs/msg/LaserScan")
    garbage = bytearray(whole)
    garbage[48:56] = b"\xff" * 8  # sequence lengths of billions
    damaged = {7: bytes(whole[:40]), 9: bytes(garbage)}
    log = corridor_log(tmp_path / "damaged", storage, scan_at=damaged)
    clean = corridor_log(tmp_path / "clean", storage, scan_at={7: None, 9: None})
    code, s, err = replay(capsys, str(log))
    assert code == 0, err
    assert "skipped 2 of 30 scans on '/scan' as corrupt" in err
    assert "index 7: cannot deserialize" in err
    code, ref, _ = replay(capsys, str(clean))
    assert s["scans_corrupt"] == 2 and s["scans"] == ref["scans"] == 28
    for key in set(s) | set(ref):
        if key not in ("log", "scans_corrupt"):
            assert s[key] == ref[key], key
