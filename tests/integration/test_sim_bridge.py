"""``egc-teleop sim`` as a remote driver: pinned scan and odometry out, base commands in, and
the base's own watchdog (it stops without commands, as a real base's firmware does)."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
from egc_common import keys
from egc_common.messages import (
    BaseCommand,
    MapMessage,
    Odometry,
    ScanMessage,
    decode_map,
    decode_odometry,
    decode_scan,
)
from egc_common.transport import ZenohOptions, command_publisher, loopback_endpoint, open_session
from egc_sim.worlds import load_world

from tests.integration.harness import ROBOT

pytestmark = [pytest.mark.integration, pytest.mark.timeout(60)]


def test_bridge_drives_reports_and_stops_on_its_own_watchdog(port, procs):
    session = open_session(ZenohOptions(listen=(loopback_endpoint(port),)))
    lock = threading.Lock()
    scans: list[ScanMessage] = []
    odom: list[tuple[int, Odometry]] = []

    def on_scan(sample):
        s = decode_scan(sample.payload.to_bytes())
        assert isinstance(s, ScanMessage), s
        with lock:
            scans.append(s)

    def on_odom(sample):
        o = decode_odometry(sample.payload.to_bytes())
        assert isinstance(o, Odometry), o
        with lock:
            odom.append((time.monotonic_ns(), o))

    subs = [
        session.declare_subscriber(keys.scan(ROBOT), on_scan),
        session.declare_subscriber(keys.base_odom(ROBOT), on_odom),
    ]
    publisher = command_publisher(session, keys.base_cmd(ROBOT))
    try:
        procs.start("sim", "sim", "--robot", ROBOT, "--connect", loopback_endpoint(port))
        deadline = time.monotonic() + 15
        while time.monotonic() < deadline and not (scans and odom):
            time.sleep(0.05)
        assert scans and odom, procs.log("sim")
        start_x = odom[-1][1].x_m
        for seq in range(1, 51):  # 1 s at 0.1 m/s
            publisher.put(BaseCommand(time.monotonic_ns(), seq, 0.1, 0.0).encode())
            time.sleep(0.02)
        stopped_sending = time.monotonic_ns()
        with lock:
            moving = odom[-1][1]
        assert moving.linear_mps == pytest.approx(0.1, abs=0.01)
        assert moving.x_m - start_x > 0.05

        # --base-timeout-s 0.5, then the simulated base brakes at 0.5 m/s^2 from 0.1 m/s. When
        # it stood is the odometry's own stamp (the simulator's CLOCK_MONOTONIC, as the test's),
        # not the message's arrival here (issue 32).
        def halted() -> int | None:
            with lock:
                return next(
                    (
                        o.stamp_ns
                        for _, o in odom
                        if o.stamp_ns > stopped_sending and o.linear_mps == 0
                    ),
                    None,
                )

        deadline = time.monotonic() + 10
        while halted() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        stood = halted()
        assert stood is not None, "the base did not stop"
        assert (stood - stopped_sending) / 1e6 <= 500 + 200 + 100
        with lock:
            scan = scans[-1]
        assert scan.ranges_m.size == 360 and scan.range_max_m > scan.range_min_m
        # the static map for the operator view, answered on egc/<robot>/map
        replies = list(session.get(keys.world_map(ROBOT), timeout=5.0))
        world = decode_map(replies[0].ok.payload.to_bytes())
        assert isinstance(world, MapMessage), world
        hallway = load_world("hallway")
        np.testing.assert_array_equal(world.blocked, np.flipud(hallway.occupancy))
        assert world.goal == hallway.goal and world.resolution_m == hallway.resolution_m
        assert procs.stop("sim") == 0, procs.log("sim")
    finally:
        for sub in subs:
            sub.undeclare()
        session.close()
