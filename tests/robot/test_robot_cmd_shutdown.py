"""The robot's shutdown goes through every step when one fails (outside check: SIGINT to the
robot and its link at once; Zenoh's session close timed out, "close operation timed out", and
the process ended with a traceback, without its --summary)."""

from __future__ import annotations

import json
import signal
import threading

import zenoh
from egc_common.transport import free_tcp_port, loopback_endpoint

from egc_app import cli, robot_cmd


class _CloseTimesOut:
    def __init__(self, session: zenoh.Session) -> None:
        self._session = session

    def __getattr__(self, name: str) -> object:
        return getattr(self._session, name)

    def close(self) -> None:
        self._session.close()
        raise zenoh.ZError("close operation timed out!")


def test_a_session_close_that_times_out_still_leaves_the_summary(tmp_path, monkeypatch, caplog):
    real_open = robot_cmd.open_session
    monkeypatch.setattr(
        robot_cmd, "open_session", lambda options: _CloseTimesOut(real_open(options))
    )
    real_run = robot_cmd.RobotNode.run

    def run_briefly(node: robot_cmd.RobotNode, stop: threading.Event) -> None:
        threading.Timer(0.5, stop.set).start()  # as SIGINT would, without a signal
        real_run(node, stop)

    monkeypatch.setattr(robot_cmd.RobotNode, "run", run_briefly)
    summary = tmp_path / "robot.json"
    previous = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        argv = ["robot", "--robot", "shut", "--listen", loopback_endpoint(free_tcp_port())]
        code = cli.main([*argv, "--summary", str(summary)])
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    assert code == 0
    assert json.loads(summary.read_text())["cycles_by_state"]
    assert "could not close the Zenoh session: close operation timed out" in caplog.text
