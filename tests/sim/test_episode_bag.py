"""Episodes written as ROS 2 logs (``egc_sim.episode_bag``, ``episode --bag``), read back."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from egc_common.profiles import JACKAL
from egc_common.scan import Scan
from egc_sim.episode_bag import BagError, BagStep, EpisodeBag, check_bag_path
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from tests.cli_process import main


def _scan(n: int = 8, r: float = 2.0) -> Scan:
    return Scan.uniform(np.full(n, r), -math.pi, 2 * math.pi / n, 0.05, 10.0)


def _read(path):
    out: dict[str, list] = {}
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        for conn, t_ns, raw in reader.messages():
            out.setdefault(conn.topic, []).append((t_ns, reader.deserialize(raw, conn.msgtype)))
    return types, out


@pytest.mark.parametrize("name", ["drive.mcap", "drive_bag"])
def test_the_log_holds_scan_odometry_and_the_drivers_command(tmp_path, name):
    path = tmp_path / name
    ranges = np.array([1.0, np.inf, 2.5, 3.0])
    with EpisodeBag(path) as bag:
        for k in range(3):
            bag.write(
                BagStep(
                    k * 50_000_000,
                    Scan.uniform(ranges + k, -math.pi, math.pi / 2, 0.05, 10.0),
                    (1.0 + k, 2.0, 0.5),
                    (0.3, -0.1),
                    (0.4 + k, 0.2),
                )
            )
    assert path.is_file() == name.endswith(".mcap")
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".bag-")]  # no leftovers
    types, msgs = _read(path)
    assert types == {
        "/scan": "sensor_msgs/msg/LaserScan",
        "/odom": "nav_msgs/msg/Odometry",
        "/cmd_vel": "geometry_msgs/msg/Twist",
    }
    assert [t for t, _ in msgs["/scan"]] == [0, 50_000_000, 100_000_000]
    for k, (t, scan) in enumerate(msgs["/scan"]):
        assert scan.header.stamp.sec * 10**9 + scan.header.stamp.nanosec == t
        assert scan.header.frame_id == "laser"
        assert scan.angle_min == pytest.approx(-math.pi)  # float32 on the wire
        assert scan.angle_increment == pytest.approx(math.pi / 2)
        assert scan.angle_max == pytest.approx(math.pi / 2)
        assert np.array_equal(scan.ranges, (ranges + k).astype(np.float32))  # +inf stays
    _, odom = msgs["/odom"][2]
    assert (odom.header.frame_id, odom.child_frame_id) == ("odom", "base_link")
    p, q = odom.pose.pose.position, odom.pose.pose.orientation
    assert (p.x, p.y) == (3.0, 2.0) and 2 * math.atan2(q.z, q.w) == pytest.approx(0.5)
    assert (odom.twist.twist.linear.x, odom.twist.twist.angular.z) == (0.3, -0.1)
    assert [(m.linear.x, m.angular.z) for _, m in msgs["/cmd_vel"]] == [
        (0.4, 0.2),
        (1.4, 0.2),
        (2.4, 0.2),
    ]


def test_a_log_is_never_written_over_an_existing_one(tmp_path):
    (tmp_path / "old.mcap").write_bytes(b"keep me")
    with pytest.raises(BagError, match="exists already"):
        EpisodeBag(tmp_path / "old.mcap")
    assert (tmp_path / "old.mcap").read_bytes() == b"keep me"
    with pytest.raises(BagError, match="folder does not exist"):
        check_bag_path(tmp_path / "nowhere" / "x.mcap")


def test_a_scan_with_uneven_beams_is_refused(tmp_path):
    uneven = Scan(np.array([0.0, 0.1, 0.3]), np.ones(3), 0.05, 10.0)
    with EpisodeBag(tmp_path / "x.mcap") as bag, pytest.raises(BagError, match="evenly"):
        bag.write(BagStep(0, uneven, (0.0, 0.0, 0.0), (0.0, 0.0), (0.0, 0.0)))


def _episode(capsys, *extra: str) -> dict:
    code = main(
        [
            "episode",
            "--map",
            "random:1003",
            "--seed",
            "1003",
            "--operator",
            "careful",
            "--filter",
            "none",
            "--profile",
            "jackal",
            "--max-time",
            "60",
            "--json",
            *extra,
        ]
    )
    out, err = capsys.readouterr()
    assert code == 0, err
    return json.loads(out)


def _replay(capsys, log, summary, *extra: str) -> dict:
    code = main(["replay", str(log), "--profile", "jackal", "--summary", str(summary), *extra])
    err = capsys.readouterr().err
    assert code == 0, err
    return json.loads(summary.read_text())


@pytest.mark.parametrize("name", ["careful.mcap", "careful_bag"])
def test_an_episode_written_and_replayed_matches_the_episode(tmp_path, capsys, name):
    log = tmp_path / name
    episode = _episode(capsys, "--bag", str(log))
    assert episode["outcome"] == "reached" and episode["bag"] == str(log)
    replayed = _replay(capsys, log, tmp_path / "none.json", "--filter", "none")
    # One scan and one command per control cycle, each scan with the command of its cycle.
    assert replayed["scans"] == episode["steps"] == replayed["commands"]
    assert replayed["scans_without_command"] == 0 and replayed["changed"] == 0
    # The nearest reading (from the laser, at the centre) against the footprint's clearance:
    # between clearance + half width and clearance + half diagonal, give or take a beam and a
    # cycle's travel (the clearance is the minimum over every sub-step, the scans per cycle).
    clearance = episode["min_clearance_m"]
    half_w, half_d = 0.5 * JACKAL.width_m, JACKAL.half_diagonal_m
    assert clearance + half_w - 0.02 <= replayed["closest_m"] <= clearance + half_d + 0.06
    assert replayed["duration_s"] == pytest.approx(episode["time_s"], abs=0.1)
    # The same log through EGC: a careful drive on the Jackal is still bent by it.
    egc = _replay(capsys, log, tmp_path / "egc.json", "--filter", "egc")
    assert egc["scans"] == replayed["scans"] and egc["changed"] > 0


def test_episode_bag_errors_are_one_line(tmp_path, capsys):
    taken = tmp_path / "taken.mcap"
    taken.write_bytes(b"")
    code = main(["episode", "--map", "random:1", "--operator", "careful", "--bag", str(taken)])
    err = capsys.readouterr().err
    assert code == 2 and "exists already" in err and len(err.strip().splitlines()) == 1
    code = main(["episode", "--random-worlds", "2", "--bag", str(tmp_path / "b.mcap")])
    err = capsys.readouterr().err
    assert code == 2 and "single episode" in err
