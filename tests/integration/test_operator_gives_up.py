"""An operator with ``--duration`` does not outlive it waiting for a peer that never comes
(outside check: with a udp/ endpoint and nothing listening, ``--duration 5`` was ignored and
the process waited until killed, once for 12 minutes)."""

from __future__ import annotations

import subprocess
import sys
import time

import pytest
from egc_common.transport import free_tcp_port

pytestmark = pytest.mark.integration


@pytest.mark.parametrize(
    ("proto", "duration_s"),
    # tcp/: zenoh.open takes ~0.5 s to pass a refused peer, so 0.2 s gives up inside it
    [("udp", "3"), ("tcp", "0.2")],
)
def test_a_peer_that_never_accepts_ends_the_run_at_its_duration(proto: str, duration_s: str):
    """Exit 2 with the reason, not an abort (134, "FATAL: exception not rethrown": the
    interpreter's shutdown tore down the thread still inside zenoh.open)."""
    port = free_tcp_port()
    cmd = [sys.executable, "-m", "egc_app.cli", "operator", "--no-view", "--script", "demo"]
    cmd += ["--zenoh-connect", f"{proto}/127.0.0.1:{port}", "--duration", duration_s]
    t0 = time.monotonic()
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
    took = time.monotonic() - t0
    assert done.returncode == 2, done.stderr
    assert f"gave up after {duration_s} s" in done.stderr and "never accepted" in done.stderr
    assert "exit_on_failure" not in done.stderr and "FATAL" not in done.stderr
    assert took < 20, took  # interpreter start-up and imports, then the duration of waiting
