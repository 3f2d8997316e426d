"""The robot TOML's [[source]], [[lock]] and [[operator]] tables (DESIGN 14): what parses, and
one line naming the table, entry and key for what does not."""

from __future__ import annotations

import tomllib

import pytest
from egc_robot.source_config import mux_config, operator_priorities
from egc_robot.source_mux import LockSpec, SourceSpec

RECIPE = """
[[source]]
name = "nav"
kind = "ros2"
priority = 10
timeout_s = 0.5
topic = "/cmd_vel_nav"

[[source]]
name = "joystick"
kind = "operator"
priority = 100
timeout_s = 0.5

[[source]]
name = "dock"
kind = "zenoh"
priority = 50

[[lock]]
name = "pause"
priority = 200
timeout_s = 1.0
kind = "ros2"
topic = "/pause"

[[lock]]
name = "heartbeat"
priority = 300

[[operator]]
id = "supervisor"
priority = 100
"""


def test_the_recipe_parses_with_defaults():
    cfg = tomllib.loads(RECIPE)
    mux = mux_config(cfg["source"], cfg["lock"])
    assert mux is not None
    assert mux.sources == (  # highest priority first
        SourceSpec("joystick", "operator", 100, 0.5),
        SourceSpec("dock", "zenoh", 50, 0.5),
        SourceSpec("nav", "ros2", 10, 0.5, "/cmd_vel_nav", "twist"),
    )
    # highest priority first, like the sources
    assert mux.locks == (LockSpec("heartbeat", 300, 0.5), LockSpec("pause", 200, 1.0, "/pause"))
    assert mux.operator_source == mux.sources[0]
    assert operator_priorities(cfg["operator"]) == (("supervisor", 100),)


def test_no_source_tables_means_no_sources():
    assert mux_config(None, None) is None
    assert operator_priorities(None) == ()


def _error(text: str) -> str:
    cfg = tomllib.loads(text)
    with pytest.raises(ValueError) as info:
        mux_config(cfg.get("source"), cfg.get("lock"))
        operator_priorities(cfg.get("operator"))
    message = str(info.value)
    assert "\n" not in message
    return message


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        (
            '[[source]]\nname = "nav"\nkind = "zenoh"\npriority = 1\ntopik = "/x"',
            "[[source]] #1 (nav): unknown key topik",
        ),
        (
            '[[source]]\nname = "nav"\nkind = "zenoh"',
            "[[source]] #1 (nav): key priority is missing",
        ),
        ('[[source]]\nkind = "zenoh"\npriority = 1', "[[source]] #1: key name is missing"),
        (
            '[[source]]\nname = "nav"\nkind = "ros"\npriority = 1',
            "[[source]] #1 (nav): key kind must be one of operator, zenoh, ros2, got 'ros'",
        ),
        (
            '[[source]]\nname = "nav"\nkind = "ros2"\npriority = 1',
            "[[source]] #1 (nav): key topic is missing",
        ),
        (
            '[[source]]\nname = "nav"\nkind = "ros2"\npriority = 1\ntopic = "cmd vel"',
            "key topic 'cmd vel' is not a valid ROS 2 topic name",
        ),
        (
            '[[source]]\nname = "nav"\nkind = "zenoh"\npriority = 1\ntopic = "/x"',
            "[[source]] #1 (nav): key topic is for kind ros2 only",
        ),
        (
            '[[source]]\nname = "nav"\nkind = "ros2"\npriority = 1\ntopic = "/x"\n'
            'cmd_type = "stamped"',
            "key cmd_type must be one of twist, twist-stamped",
        ),
        (
            '[[source]]\nname = "nav"\nkind = "zenoh"\npriority = "10"',
            "[[source]] #1 (nav): key priority must be an integer, got '10'",
        ),
        (
            '[[source]]\nname = "nav"\nkind = "zenoh"\npriority = 1\ntimeout_s = -1',
            "[[source]] #1 (nav): key timeout_s must be a number of seconds in (0, 3600]",
        ),
        (
            '[[source]]\nname = "nav/1"\nkind = "zenoh"\npriority = 1',
            "[[source]] #1 (nav/1): key name 'nav/1' must be 1-64 characters",
        ),
        (
            '[[source]]\nname = "a"\nkind = "zenoh"\npriority = 1\n'
            '[[source]]\nname = "b"\nkind = "zenoh"\npriority = 1',
            "sources a and b have the same priority 1",
        ),
        ('[[lock]]\nname = "pause"\npriority = 1', "[[lock]] tables need [[source]] tables"),
        (
            '[[source]]\nname = "a"\nkind = "zenoh"\npriority = 1\n'
            '[[lock]]\nname = "pause"\npriority = 1\nkind = "ros2"',
            "[[lock]] #1 (pause): key topic is missing",
        ),
        ("source = 3", "source must be an array of tables ([[source]])"),
    ],
)
def test_mistakes_are_one_line_naming_the_key(text, expected):
    assert expected in _error(text)


def test_operator_mistakes_name_the_entry():
    with pytest.raises(
        ValueError, match=r"\[\[operator\]\] #2 \(sup\): operator sup is listed twice"
    ):
        operator_priorities([{"id": "sup", "priority": 1}, {"id": "sup", "priority": 2}])
    with pytest.raises(ValueError, match=r"\[\[operator\]\] #1 \(sup\): key priority is missing"):
        operator_priorities([{"id": "sup"}])
