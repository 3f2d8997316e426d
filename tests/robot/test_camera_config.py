"""The robot's camera settings (DESIGN 12): defaults by driver, flags over the TOML table, and
one clear line for every bad value."""

from __future__ import annotations

import pytest
from egc_robot.camera_config import CameraConfig, camera_config

NO_FLAGS = {"source": None, "size": None, "fps": None, "codec": None}


def flags(**given):
    return {**NO_FLAGS, **given}


@pytest.mark.parametrize("driver,source", [("sim", "sim"), ("zenoh", "none"), ("ros2", "none")])
def test_defaults_by_driver(driver, source):
    config = camera_config({}, NO_FLAGS, driver)
    assert config == CameraConfig(source, None, 320, 240, 10.0, "h264")
    assert config.enabled == (source != "none")


def test_flags_override_the_table():
    table = {"source": "none", "size": "640x480", "fps": 5, "codec": "jpeg"}
    assert camera_config(table, NO_FLAGS, "sim") == CameraConfig(
        "none", None, 640, 480, 5.0, "jpeg"
    )
    config = camera_config(table, flags(source="sim", size="160x120", fps=2.5), "sim")
    assert config == CameraConfig("sim", None, 160, 120, 2.5, "jpeg")


def test_a_ros2_topic():
    config = camera_config({}, flags(source="ros2:/camera/image_raw"), "ros2")
    assert (config.source, config.topic) == ("ros2", "/camera/image_raw")
    relative = camera_config({"source": "ros2:front/image/compressed"}, NO_FLAGS, "ros2")
    assert relative.topic == "front/image/compressed"


@pytest.mark.parametrize(
    "table,given,driver,words",
    [
        ({}, {"source": "sim"}, "zenoh", "needs --driver sim"),
        ({}, {"source": "ros2:/img"}, "sim", "needs --driver ros2"),
        ({}, {"source": "ros2:"}, "ros2", "not a valid ROS 2 topic"),
        ({}, {"source": "ros2:/bad topic"}, "ros2", "not a valid ROS 2 topic"),
        ({}, {"source": "usb"}, "sim", "sim, none or ros2:TOPIC"),
        ({}, {"source": "sim:x"}, "sim", "sim, none or ros2:TOPIC"),
        ({}, {"size": "320"}, "sim", "WxH"),
        ({}, {"size": "321x240"}, "sim", "even"),
        ({}, {"size": "8000x240"}, "sim", "even, 32-1920"),
        ({}, {"fps": 0.0}, "sim", r"within \[0.5, 30\]"),
        ({}, {"fps": float("nan")}, "sim", "must be a number"),
        ({"fps": "ten"}, {}, "sim", "must be a number"),
        ({"codec": "vp9"}, {}, "sim", "h264, jpeg"),
        ({"sorce": "sim"}, {}, "sim", "unknown keys: sorce"),
        ({"source": 3}, {}, "sim", "must be a string"),
    ],
)
def test_bad_values_are_one_line(table, given, driver, words):
    with pytest.raises(ValueError, match=words) as info:
        camera_config(table, flags(**given), driver)
    assert "\n" not in str(info.value)
