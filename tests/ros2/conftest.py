"""Fixtures for the ROS 2 tests: skipped, with the reason, only when rclpy is not importable.

Each test holds its own ``ROS_DOMAIN_ID`` (``fake_base.domain_for_test``) and localhost-only
discovery, set in this process's environment (the test's own node reads it) and so inherited
by the robot, operator and simulator processes it starts.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest


@pytest.fixture
def ros_domain(monkeypatch) -> Iterator[int]:
    from tests.ros2.fake_base import domain_for_test

    with domain_for_test() as domain:
        monkeypatch.setenv("ROS_DOMAIN_ID", str(domain))
        monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        monkeypatch.delenv("ROS_STATIC_PEERS", raising=False)
        yield domain
