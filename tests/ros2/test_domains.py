"""``domain_for_test``: a ROS_DOMAIN_ID is held by one test at a time on this machine, whichever
run it belongs to (CI run 131: two suites at once shared a domain)."""

from __future__ import annotations

import pytest

pytest.importorskip("rclpy", reason="ROS 2's rclpy is not installed (pip install -e '.[ros2]')")

from tests.ros2 import fake_base


def test_a_held_domain_is_not_given_out_again(monkeypatch):
    with fake_base.domain_for_test() as first:
        # The next pick starts at the held one: it must pass it over.
        monkeypatch.setattr(fake_base.random, "randrange", lambda n: first - 1)
        with fake_base.domain_for_test() as second:
            assert second != first and 1 <= second <= fake_base.DOMAINS
    with fake_base.domain_for_test() as again:  # released at the end of its block
        assert again == first
