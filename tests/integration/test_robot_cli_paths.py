"""`egc-teleop robot` with an output path it cannot write: one line, exit 2, before anything
opens (outside check: `--record /proc/x.rrd` raised inside the run after the Zenoh session had
opened; the process kept its port, ignored SIGTERM and SIGINT, and only SIGKILL ended it)."""

from __future__ import annotations

import subprocess
import sys

import pytest
from egc_common.transport import free_tcp_port, loopback_endpoint

pytestmark = pytest.mark.integration


def _robot(*args: str) -> subprocess.CompletedProcess[str]:
    cmd = [sys.executable, "-m", "egc_app.cli", "robot", "--robot", "paths"]
    cmd += ["--listen", loopback_endpoint(free_tcp_port()), *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize(
    "option, path, says",
    [
        ("--record", "/proc/egc-x.rrd", "not writable"),
        ("--summary", "/proc/egc-x.json", "not writable"),
        ("--record", "{tmp}/no-such-dir/x.rrd", "does not exist"),
        ("--summary", "/", "is a directory"),
    ],
)
def test_an_unwritable_output_is_one_line_and_exit_2(option, path, says, tmp_path):
    path = path.format(tmp=tmp_path)  # never a real directory left behind by an older robot
    done = _robot(option, path)
    assert done.returncode == 2, done.stderr
    errors = [line for line in done.stderr.splitlines() if "error:" in line]
    assert len(errors) == 1 and says in errors[0] and path in errors[0], done.stderr
    assert "Traceback" not in done.stderr


def test_a_missing_directory_is_not_created(tmp_path):
    target = tmp_path / "no" / "such" / "x.rrd"
    assert _robot("--record", str(target)).returncode == 2
    assert not (tmp_path / "no").exists()


def test_a_driver_that_fails_to_open_leaves_no_process_behind():
    """The session is open when the driver fails (here, a missing world): it is closed, so the
    process exits instead of hanging on Zenoh's threads."""
    done = _robot("--map", "/nonexistent-egc-world.toml")
    assert done.returncode == 2 and "world file not found" in done.stderr


def test_a_file_in_the_way_and_an_empty_path_are_named_as_such(tmp_path):
    """Outside check: a regular file as the directory read 'directory ... does not exist', and
    an empty path 'is a directory'."""
    blocker = tmp_path / "afile"
    blocker.write_text("")
    done = _robot("--record", str(blocker / "x.rrd"))
    assert done.returncode == 2 and "is not a directory" in done.stderr, done.stderr
    done = _robot("--summary", "")
    assert done.returncode == 2 and "an empty path" in done.stderr, done.stderr
