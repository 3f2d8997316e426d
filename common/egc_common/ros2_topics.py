"""The ROS 2 topic defaults of DESIGN 11 (pinned), shared by ``robot --driver ros2`` and
``sim --ros2`` so that both ends of a ROS 2 link agree on them."""

from __future__ import annotations

DEFAULT_SCAN_TOPIC = "/scan"
DEFAULT_ODOM_TOPIC = "/odom"
DEFAULT_CMD_TOPIC = "/cmd_vel"


def default_topic(default: str, namespace: str) -> str:
    """The pinned default (``/scan``) or, in a namespace, the same name relative to it
    (``scan``, so ``/robot1/scan``), as ROS 2 users expect a namespace to move the defaults."""
    return default.lstrip("/") if namespace and namespace != "/" else default
