"""A ROS 2 robot for ``egc-teleop robot --driver ros2``: a fake base and lidar, driven by the test.

``FakeBase`` runs a real rclpy node in a process of its own (``fake_base_process``, whose
docstring says why it is not a thread of the pytest worker) that

- integrates the velocity it receives on ``/cmd_vel`` (Twist or TwistStamped) into a pose,
- publishes ``sensor_msgs/LaserScan`` at 20 Hz (sensor-data QoS) of a world made of one wall
  across the x axis at ``wall_x_m`` (or no wall: all ``+inf``), seen by a laser with a given
  pose in the base frame, optionally mounted upside down, or any ``ranges_override``,
- publishes ``nav_msgs/Odometry``.

This side records every ``/cmd_vel`` with its arrival time in that process
(``time.monotonic_ns()``, comparable with every process's clock on Linux), the base's pose, and
the gaps between its scans longer than two periods (``scan_gaps_ms``), so that a robot that held
for "sensor stale" says whether its lidar went quiet.

Every test holds a ``ROS_DOMAIN_ID`` of its own and keeps discovery on this machine
(``domain_for_test``), so tests and parallel runs cannot hear each other. The process inherits
both from this one's environment.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import random
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import numpy as np

from tests.cli_process import child_env
from tests.integration.harness import ROOT
from tests.ros2.fake_base_process import PERIOD_S, STOP_PATIENCE_S

RANGE_MIN_M = 0.1
DOMAINS = 101  # ROS_DOMAIN_ID 1-101: the ports of each stay in Linux's default range
__all__ = ["STOP_PATIENCE_S", "CmdSample", "FakeBase", "domain_for_test"]


@contextlib.contextmanager
def domain_for_test() -> Iterator[int]:
    """A ROS_DOMAIN_ID in [1, 101] that no other test on this machine holds meanwhile, in this
    run or another: an exclusive lock on ``egc-ros-domain-N.lock`` in the temporary folder, held
    until the block ends (or the process does). Picked from the process id alone, two suites
    running at once could share a domain, and with it each other's /scan and /cmd_vel: in CI
    run 131 a fake base got a moving twist after the robot had stopped, the robot's log showing
    no reason for one."""
    folder = Path(tempfile.gettempdir())
    start = random.randrange(DOMAINS)
    for i in range(DOMAINS):
        domain = 1 + (start + i) % DOMAINS
        lock = (folder / f"egc-ros-domain-{domain}.lock").open("w")
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            lock.close()
            continue
        try:
            yield domain
        finally:
            lock.close()  # the lock goes with it
        return
    raise RuntimeError(f"all {DOMAINS} ROS 2 domains are held by tests on this machine")


@dataclass
class CmdSample:
    rx_ns: int
    linear_mps: float
    angular_radps: float
    frame_id: str | None


class _ScanSwitch:
    """``scans_on``: set() and clear() as on a ``threading.Event``, sent to the base's process."""

    def __init__(self, base: FakeBase) -> None:
        self._base = base
        self._on = True

    def set(self) -> None:
        self._on = True
        self._base._send("scans on")

    def clear(self) -> None:
        self._on = False
        self._base._send("scans off")

    def is_set(self) -> bool:
        return self._on


class FakeBase:
    def __init__(
        self,
        cmd_type: str = "twist",
        wall_x_m: float | None = None,
        laser_yaw_rad: float = 0.0,
        upside_down: bool = False,
        range_min_m: float = RANGE_MIN_M,
    ) -> None:
        self.scans_on = _ScanSwitch(self)
        self.x_m = 0.0
        self.max_x_m = 0.0
        self.cmds: list[CmdSample] = []
        self.scans_published = 0
        self.scan_gaps_ms: list[float] = []
        self._subscribers = 0
        self._errors: list[str] = []
        self._closed: str | None = None
        self._ranges_override: np.ndarray | None = None
        self._lock = threading.Lock()
        settings = {
            "cmd_type": cmd_type,
            "wall_x_m": wall_x_m,
            "laser_yaw_rad": laser_yaw_rad,
            "upside_down": upside_down,
            "range_min_m": range_min_m,
        }
        self._stderr: IO[bytes] = tempfile.TemporaryFile()  # noqa: SIM115 (closed by close())
        self._proc = subprocess.Popen(
            [sys.executable, "-m", "tests.ros2.fake_base_process", json.dumps(settings)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=self._stderr,
            text=True,
            cwd=ROOT,
            env=child_env(PYTHONFAULTHANDLER="1"),
        )
        assert self._proc.stdout is not None
        ready = self._proc.stdout.readline()  # its node exists; its threads start right after
        if ready.strip() != "ready":
            self._proc.kill()
            self._proc.wait()
            raise AssertionError(f"the fake base did not start: {ready!r}\n{self._stderr_tail()}")
        self._reader = threading.Thread(
            target=self._read, args=(self._proc.stdout,), name="fake-base-reader", daemon=True
        )
        self._reader.start()

    def _send(self, line: str) -> None:
        assert self._proc.stdin is not None
        self._proc.stdin.write(line + "\n")
        self._proc.stdin.flush()

    def _read(self, lines: Any) -> None:
        for line in lines:
            kind, _, rest = line.rstrip("\n").partition(" ")
            words = rest.split()
            with self._lock:
                if kind == "cmd":
                    frame = None if words[3] == "-" else words[3]
                    self.cmds.append(
                        CmdSample(int(words[0]), float(words[1]), float(words[2]), frame)
                    )
                elif kind == "tick":
                    self.x_m = float(words[0])
                    self.max_x_m = max(self.max_x_m, self.x_m)
                    self.scans_published = int(words[1])
                    self._subscribers = int(words[2])
                elif kind == "gap":
                    self.scan_gaps_ms.append(float(words[0]))
                elif kind == "error":
                    self._errors.append(rest)
                elif kind == "closed":
                    self._closed = rest

    def _stderr_tail(self) -> str:
        self._stderr.seek(0)
        return self._stderr.read()[-3000:].decode(errors="replace")

    @property
    def ranges_override(self) -> np.ndarray | None:
        return self._ranges_override

    @ranges_override.setter
    def ranges_override(self, ranges: np.ndarray | None) -> None:
        """Every scan from now on (None: the wall again)."""
        self._ranges_override = ranges
        self._send(f"ranges {json.dumps(None if ranges is None else ranges.tolist())}")

    def commands(self, since_ns: int = 0) -> list[CmdSample]:
        with self._lock:
            return [c for c in self.cmds if c.rx_ns >= since_ns]

    def wait_for(self, what: str, predicate: Any, timeout_s: float = 20.0) -> Any:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            value = predicate()
            if value:
                return value
            time.sleep(0.01)
        last = self.commands()[-3:]
        raise AssertionError(
            f"timed out after {timeout_s} s waiting for {what}; last: {last}; {self.health()}"
        )

    def health(self) -> str:
        """What the base itself did: how far it went, its scans and their gaps."""
        with self._lock:
            return (
                f"the fake base drove to x {self.max_x_m:.3f} m at most and published "
                f"{self.scans_published} scans; gaps between them over {2 * PERIOD_S * 1e3:.0f} "
                f"ms: {[round(g) for g in self.scan_gaps_ms]}"
            )

    def wait_connected(self, timeout_s: float = 30.0) -> None:
        """Until the robot's node hears our scans and we hear its /cmd_vel (ROS 2 discovery)."""
        self.wait_for(
            "the robot's node to match our topics",
            lambda: self._subscribers > 0 and self.commands(),
            timeout_s,
        )
        time.sleep(0.2)  # a few scans on their way

    def wait_driving(self, timeout_s: float = 30.0) -> int:
        """Arrival time of the first command moving forward."""
        sample = self.wait_for(
            "a forward /cmd_vel",
            lambda: next((c for c in self.commands() if c.linear_mps > 0.0), None),
            timeout_s,
        )
        return int(sample.rx_ns)

    def close(self) -> None:
        """The base's threads out, then its process ends (no node destroyed: see
        ``fake_base_process``). A thread still inside, or a process that did not end, fails the
        test."""
        if self._proc.poll() is None:
            try:
                self._send("close")
                self._proc.stdin.close()  # type: ignore[union-attr]
            except OSError:
                pass
            try:
                self._proc.wait(STOP_PATIENCE_S * 2 + 10)
            except subprocess.TimeoutExpired:
                self._proc.kill()
                self._proc.wait()
        self._reader.join(5)
        code, closed = self._proc.returncode, self._closed
        tail = self._stderr_tail()
        self._stderr.close()
        assert code == 0 and closed == "ok", (
            f"the fake base's process ended with {code}, its threads {closed or 'never said'}:"
            f"\n{tail}"
        )
        assert not self._errors, f"the fake base's executor failed: {self._errors}"
