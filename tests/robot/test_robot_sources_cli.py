"""``egc-teleop robot`` with [[source]] / [[lock]] / [[operator]] tables it cannot take: one line
naming the table, entry and key, exit 2, before anything opens (DESIGN 2, 14)."""

from __future__ import annotations

import pytest

from tests import cli_process
from tests.cli_process import Ran
from tests.test_arguments_checked_up_front import assert_refused

NAV = '[[source]]\nname = "nav"\nkind = "ros2"\ntopic = "{topic}"\npriority = 10\n'

CASES = [
    (
        NAV.format(topic="/cmd_vel_nav"),
        "zenoh",
        "source nav is fed by the ROS 2 topic /cmd_vel_nav: it needs --driver ros2",
    ),
    (
        NAV.format(topic="/cmd_vel"),
        "ros2",
        "source nav listens on /cmd_vel, where this robot publishes its own commands",
    ),
    (
        '[[source]]\nname = "nav"\nkind = "zenoh"\npriority = 10\ntimeout = 1\n',
        "zenoh",
        "[[source]] #1 (nav): unknown key timeout (known: name, kind, priority, timeout_s",
    ),
    ('[[operator]]\nid = "sup"\n', "zenoh", "[[operator]] #1 (sup): key priority is missing"),
]


def _argv(driver: str) -> tuple[str, ...]:
    return ("robot", "--driver", driver, "--config", "robot.toml", "--listen", "tcp/127.0.0.1:1")


@pytest.fixture(scope="module")
def ran(tmp_path_factory) -> list[Ran]:
    """Every case's command line, each in a directory holding its robot.toml, in one process
    (``tests.cli_process.run_many``)."""
    cases = []
    for toml, driver, _ in CASES:
        cwd = tmp_path_factory.mktemp("sources")
        (cwd / "robot.toml").write_text(toml)
        cases.append((_argv(driver), cwd))
    return cli_process.run_many(cases)


@pytest.mark.parametrize("case", range(len(CASES)), ids=lambda i: CASES[i][2][:40])
def test_bad_source_tables_are_one_line_and_exit_2(ran, case):
    _, driver, expected = CASES[case]
    assert_refused(ran[case], _argv(driver), expected)
