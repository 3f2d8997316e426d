"""``egc-teleop robots`` (DESIGN 15, pinned) against real robot processes behind a real router.

- Five robots (each its own process, simulated driver, clients of one ``egc-teleop router``)
  are all listed by ``egc-teleop robots --wait 3``, with the pinned JSON keys and each robot's
  own profile and filter from its ``egc/<robot>/info`` queryable.
- A robot killed with SIGKILL (no goodbye: its lease must run out) is gone from a listing
  started 3 s after the kill.
- After the router is killed and started again on the same port, every robot is listed again
  within 10 s, nothing else restarted.
- No robot at all: exit 0, nothing on stdout.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time

import pytest

from tests.integration.test_router import start_router

pytestmark = [pytest.mark.integration, pytest.mark.timeout(150)]

PINNED = {"robot", "state", "driver", "profile", "filter", "camera", "operator"}
ROBOTS = {
    "r1": ("pioneer3dx", "egc"),
    "r2": ("jackal", "dwa"),
    "r3": ("pioneer3dx", "none"),
    "r4": ("jackal", "assist"),
    "r5": ("pioneer3dx", "ek-egc"),
}
ROBOTS_CMD = (sys.executable, "-m", "egc_app.cli", "robots", "--zenoh-mode", "client")


def list_robots(port: int, wait_s: float) -> tuple[list[dict], subprocess.CompletedProcess[str]]:
    done = subprocess.run(
        [*ROBOTS_CMD, "--connect", f"tcp/127.0.0.1:{port}", "--json", "--wait", str(wait_s)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    return [json.loads(line) for line in done.stdout.splitlines()], done


def wait_listed(port: int, wanted: set[str], within_s: float, wait_s: float = 1.0) -> set[str]:
    """Lists again until exactly ``wanted`` is listed or ``within_s`` has passed."""
    deadline = time.monotonic() + within_s
    seen: set[str] = set()
    while time.monotonic() < deadline:
        rows, _ = list_robots(port, wait_s)
        seen = {row["robot"] for row in rows}
        if seen == wanted:
            return seen
    return seen


def test_robots_behind_one_router_are_listed_and_follow_kills_and_router_restarts(port, procs):
    start_router(procs, f"tcp/127.0.0.1:{port}")
    client = ["--zenoh-mode", "client", "--connect", f"tcp/127.0.0.1:{port}"]
    for robot, (profile, filt) in ROBOTS.items():
        procs.start(
            robot,
            "robot",
            "--robot",
            robot,
            "--driver",
            "sim",
            "--profile",
            profile,
            "--filter",
            filt,
            *client,
        )
    deadline = time.monotonic() + 60  # five processes starting on two busy cores
    while not all("ready" in procs.log(robot) for robot in ROBOTS):
        assert time.monotonic() < deadline, {r: procs.log(r)[-300:] for r in ROBOTS}
        time.sleep(0.1)

    rows, done = list_robots(port, 3.0)
    by_robot = {row["robot"]: row for row in rows}
    assert set(by_robot) == set(ROBOTS), done.stdout + done.stderr
    for robot, (profile, filt) in ROBOTS.items():
        row = by_robot[robot]
        assert set(row) >= PINNED, row
        assert (row["profile"], row["filter"], row["driver"]) == (profile, filt, "sim"), row
        assert row["state"] == "IDLE" and row["operator"] is None, row

    procs.children["r3"].send_signal(signal.SIGKILL)
    procs.children["r3"].wait(5)
    time.sleep(3.0)
    rows, done = list_robots(port, 1.0)
    assert {row["robot"] for row in rows} == set(ROBOTS) - {"r3"}, done.stdout

    procs.children["router"].send_signal(signal.SIGKILL)
    procs.children["router"].wait(5)
    time.sleep(1.0)
    restarted = time.monotonic()
    start_router(procs, f"tcp/127.0.0.1:{port}")
    seen = wait_listed(port, set(ROBOTS) - {"r3"}, within_s=10.0)
    assert seen == set(ROBOTS) - {"r3"}, (seen, time.monotonic() - restarted)
    for robot in set(ROBOTS) - {"r3"}:
        assert procs.alive(robot), procs.log(robot)[-500:]


def test_no_robots_is_exit_zero_and_an_empty_list(port, procs):
    start_router(procs, f"tcp/127.0.0.1:{port}")
    rows, done = list_robots(port, 0.5)
    assert rows == [] and done.stdout == ""
    plain = subprocess.run(
        [
            sys.executable,
            "-m",
            "egc_app.cli",
            "robots",
            "--zenoh-mode",
            "client",
            "--connect",
            f"tcp/127.0.0.1:{port}",
            "--wait",
            "0.5",
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert plain.returncode == 0 and plain.stdout == "", plain
    assert "no robots seen" in plain.stderr


def test_bad_wait_is_one_line_and_exit_2():
    done = subprocess.run(
        [sys.executable, "-m", "egc_app.cli", "robots", "--wait", "-1"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr
