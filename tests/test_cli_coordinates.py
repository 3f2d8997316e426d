"""DESIGN 2: coordinates are typed the way people type them; a leading minus is a number.

``egc-teleop episode --start -12.5,8.5,0 --goal 13.0,1.7`` (the README's own example) failed
with "expected one argument": argparse took ``-12.5,8.5,0`` for an option. One test per option
that takes coordinates, in every subcommand that has one, and the negative cases that must stay
errors.
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

import pytest
from egc_common.transport import free_port

from tests import cli_process

CASES = [
    ("robot", "--start", "-12.5,8.5,0", "start"),
    ("episode", "--start", "-12.5,8.5,-1.57", "start"),
    ("episode", "--goal", "-2,3", "goal"),
    ("episode", "--goal", "-2.5,-3e-1", "goal"),
    ("sim", "--start", "-1,-2,-3", "start"),
]


MISTYPED = [
    ("episode", "--goal", "-3,abc", "goal"),
    ("episode", "--goal", "-nan,4", "goal"),
    ("episode", "--goal", "-INF,4", "goal"),
    ("episode", "--start", "-x,1,0", "start"),
    ("episode", "--goal", "-,1", "goal"),
    ("robot", "--laser-pose", "-1,2,nan", "laser_pose"),
]
UNKNOWN_OPTION = ("episode", "--start", "-x")


@functools.cache
def parsed() -> dict[tuple[str, ...], dict[str, Any] | str]:
    """Every command line of this module through the subcommands' real parsers, in one process
    (``tests.cli_process.parse``: nothing imports egc_app, DESIGN 2)."""
    lines = [(c, o, v) for c, o, v, _ in (*CASES, *MISTYPED)] + [UNKNOWN_OPTION]
    return dict(zip(lines, cli_process.parse(*lines), strict=True))


def parsed_value(command: str, option: str, value: str, dest: str) -> Any:
    args = parsed()[(command, option, value)]
    assert isinstance(args, dict), args
    return args[dest]


@pytest.mark.parametrize(("command", "option", "value", "dest"), CASES)
def test_negative_coordinates_are_values(command, option, value, dest):
    assert parsed_value(command, option, value, dest) == value


def test_the_operator_model_process_takes_negative_coordinates_too():
    from egc_experiments.operator_model import build_parser

    base = ["--zenoh-connect", "tcp/h:1", "--operator", "goal", "--world", "hallway"]
    args = build_parser().parse_args([*base, "--start", "-1,2,0", "--goal", "-2,3"])
    assert (args.start, args.goal) == ("-1,2,0", "-2,3")


def test_an_unknown_option_that_looks_like_a_word_is_still_an_error():
    error = parsed()[UNKNOWN_OPTION]
    assert isinstance(error, str) and "expected one argument" in error, error


@pytest.mark.parametrize(("command", "option", "value", "dest"), MISTYPED)
def test_a_mistyped_coordinate_reaches_its_own_check(command, option, value, dest):
    # An outside check: these said "expected one argument", not what is wrong with them.
    assert parsed_value(command, option, value, dest) == value


NAMED = [
    (("episode", "--map", "hallway", "--goal", "-3,abc"), "--goal X,Y must be 2"),
    (("episode", "--map", "hallway", "--goal", "-nan,4"), "finite numbers, got '-nan,4'"),
    (("robot", "--laser-pose", "-1,2,nan"), "laser pose must be X,Y,YAW"),
]


@pytest.mark.parametrize(("argv", "message"), NAMED)
def test_and_its_message_names_the_problem(argv, message):
    result = refused()[argv]
    assert result.code == 2
    err = result.err_lines
    assert len(err) == 1 and message in err[0]


# Numbers in coordinates are plain ASCII decimals (egc_common.cli_args.plain_float): float()
# alone also takes 1_000 and full-width digits, which nobody types on purpose. An outside check
# found the operator's --goal/--route strict but these options still on float().
NOT_PLAIN = ["1_000", "\uff11", "1\uff10"]  # underscore; full-width 1; 1 then full-width 0
NOT_PLAIN_CASES = [
    (("episode", "--map", "hallway", "--start", "{},0,0"), "--start X,Y,YAW must be 3"),
    (("episode", "--map", "hallway", "--goal", "-2,{}"), "--goal X,Y must be 2"),
    (("sim", "--start", "-1,{},0"), "--start must be X,Y,YAW"),
    (("robot", "--laser-pose", "-0.1,0,{}"), "laser pose must be X,Y,YAW"),
    # The robot reads --start once its session is open: a free port, not the default 7447.
    (("robot", "--start", "-1,{},0", "--listen", "PORT"), "--start must be X,Y,YAW"),
]


def with_bad(argv: tuple[str, ...], bad: str) -> tuple[str, ...]:
    return tuple(a.format(bad) for a in argv)


def listen_port(word: str) -> str:
    return f"tcp/127.0.0.1:{free_port('tcp')}" if word == "PORT" else word


@functools.cache
def refused() -> dict[tuple[str, ...], cli_process.Ran]:
    """Every command line of this module that must be refused, run at once, each as the console
    script runs it (``tests.cli_process.run_many``: a value taken for a number would start a
    robot or a simulator that runs on: its deadline makes that a failure, not a hang)."""
    argvs = [argv for argv, _ in NAMED]
    argvs += [with_bad(argv, bad) for argv, _ in NOT_PLAIN_CASES for bad in NOT_PLAIN]
    cases = [(tuple(map(listen_port, argv)), Path.cwd()) for argv in argvs]
    results = cli_process.run_many(cases)
    return dict(zip(argvs, results, strict=True))


@pytest.mark.parametrize("bad", NOT_PLAIN)
@pytest.mark.parametrize(("argv", "message"), NOT_PLAIN_CASES)
def test_coordinates_are_plain_decimals(argv, message, bad):
    result = refused()[with_bad(argv, bad)]
    assert result.code == 2
    err = result.err_lines
    assert len(err) == 1 and message in err[0] and bad in err[0], err


def test_negative_and_plain_coordinates_still_parse():
    from egc_experiments.episode import parse_goal, parse_start
    from egc_robot.ros2_core import parse_laser_pose
    from egc_sim.bridge import parse_pose

    assert parse_start("-12.5,8.5,-1.57") == (-12.5, 8.5, -1.57)
    assert parse_goal(" -2.5,-3e-1") == (-2.5, -0.3)
    assert parse_pose("-1,-.5,+3.") == (-1.0, -0.5, 3.0)
    assert parse_laser_pose("-0.1,-0.05,-3.14159") == (-0.1, -0.05, -3.14159)
