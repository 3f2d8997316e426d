"""``Ros2Driver.close()`` and the executor's thread (issue 31): the node is destroyed only once
that thread is out; a thread held inside a callback leaves the node alone (a segfault otherwise).

The 200-cycle check under load is ``bench/bench_ros2_teardown.py``.
"""

from __future__ import annotations

import logging
import threading

import pytest

pytest.importorskip("rclpy", reason="ROS 2's rclpy is not installed (pip install -e '.[ros2]')")

from egc_robot import ros2_driver
from egc_robot.ros2_core import Ros2Settings

from tests.ros2.fake_base import FakeBase

pytestmark = pytest.mark.timeout(120)


def test_close_leaves_the_node_alone_while_a_callback_holds_the_executor_thread(
    ros_domain, monkeypatch, caplog
):
    monkeypatch.setattr(ros2_driver, "_STOP_PATIENCE_S", 0.5)
    base = FakeBase()
    driver = ros2_driver.Ros2Driver(Ros2Settings())
    inside, release = threading.Event(), threading.Event()

    def held_cycle() -> None:  # a scan's cycle that does not return
        inside.set()
        release.wait(60)

    driver.set_scan_listener(held_cycle)
    try:
        assert inside.wait(30), "no scan reached the driver"
        # Its cycle held, the driver has sent nothing yet: a twist sent before discovery has
        # matched the base's subscription to the driver's /cmd_vel is lost (CI run 50, load 9).
        base.wait_for(
            "the driver's /cmd_vel to match the base",
            lambda: driver._publisher.get_subscription_count() > 0,
            30.0,
        )
        with caplog.at_level(logging.ERROR, logger="egc.robot.ros2"):
            driver.close()
        assert "executor thread did not stop" in caplog.text
        assert driver._node.get_name() == ros2_driver.NODE_NAME  # not destroyed under it
        # The last zero twist went out all the same (DESIGN 11).
        base.wait_for(
            "the last zero twist", lambda: [c for c in base.commands() if c.linear_mps == 0.0]
        )
    finally:
        release.set()
        if driver._spinner.stop(30.0):
            driver._executor.shutdown()
            driver._node.destroy_node()
        driver._context.try_shutdown()
        base.close()


def test_close_destroys_the_node_once_the_executor_thread_is_out(ros_domain, caplog):
    base = FakeBase()
    driver = ros2_driver.Ros2Driver(Ros2Settings())
    seen = threading.Event()
    driver.set_scan_listener(seen.set)
    try:
        assert seen.wait(30), "no scan reached the driver"
    finally:
        with caplog.at_level(logging.ERROR, logger="egc.robot.ros2"):
            driver.close()
        base.close()
    assert "did not stop" not in caplog.text
    with pytest.raises(Exception, match="destruction was requested"):
        driver._node.get_name()
