"""Bad arguments: one line on stderr and exit 2, before anything runs (DESIGN 2; README).

An outside "fresh user" check found output paths checked only when the run was over
(``demo --json /nonexist/x.json`` ran the whole demo, then a FileNotFoundError traceback and no
summary; ``episode --random-worlds 3 --out DIR`` an IsADirectoryError; ``replay --summary DIR``
the same), and bad demo arguments reported by whichever child process started first (two to four
lines, exit 1, the robot's stop summary among them). Each refusal is the console script's own
``main`` in a directory of its own, all of them in one process (``tests.cli_process.run_many``:
one start-up for all); a deadline guards the ones that, unfixed, would start a demo or a batch
(its children's output would be caught as a real process's is). The demo that runs is a real
``egc-teleop`` process.
"""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from tests import cli_process
from tests.cli_process import Ran
from tests.replay.logs import corridor_log


def egc(*argv: str, cwd: Path, timeout_s: float = 120.0) -> tuple[int, list[str], str]:
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "egc_app.cli", *argv],
            capture_output=True,
            text=True,
            timeout=timeout_s,
            cwd=cwd,
            stdin=subprocess.DEVNULL,
        )
    except subprocess.TimeoutExpired:
        pytest.fail(f"{argv}: still running after {timeout_s} s instead of refusing its arguments")
    return proc.returncode, proc.stderr.strip().splitlines(), proc.stdout


def assert_refused(ran: Ran, argv: tuple[str, ...], expected: str) -> None:
    err = ran.err_lines
    assert ran.code == 2, err
    assert len(err) == 1, err  # one line: the demo's own, no child's
    assert err[0].startswith(f"egc-teleop {argv[0]}: error: ") and expected in err[0], err
    assert ran.stdout == ""  # refused before anything ran: no summary (the line above: no child's)


DEMO = ("demo", "--no-view", "--duration", "1")


DEMO_REFUSED = [
    (("--json", "/nonexist/x.json"), "--json /nonexist/x.json: directory /nonexist does not"),
    (("--json", "."), "--json .: is a directory"),
    (("--json", "/proc/x.json"), "--json /proc/x.json: not writable"),
    (("--world", "nosuch"), "cannot load world 'nosuch': unknown world 'nosuch'"),
    (
        ("--profile", "foo"),
        "unknown robot profile 'foo' (known: husky, jackal, pioneer3dx, turtlebot4",
    ),
    (("--script", "nosuch"), "unknown script 'nosuch' (known: demo)"),
    (("--up", "delay=abc"), "--up 'delay=abc': delay='abc' is not a number"),
    (("--down", "jitter=-1"), "--down 'jitter=-1'"),
    (("--scenario", "nosuch.toml"), "--scenario: scenario file nosuch.toml does not exist"),
    (("--up", "delay=5", "--scenario", "s.toml"), "--scenario gives both directions"),
    (("--up", "loss=5"), "loss is not possible on a TCP link"),
]


@pytest.mark.parametrize(("extra", "expected"), DEMO_REFUSED)
def test_demo_refuses_bad_arguments_before_any_child_starts(ran, extra, expected):
    argv = (*DEMO, *extra)
    result, cwd = ran[argv]
    assert_refused(result, argv, expected)
    assert list(cwd.iterdir()) == []  # no file created on the way (the --json probe either)


def test_demo_script_list_lists_the_scripts_as_the_operator_does(ran):
    result, _ = ran[("demo", "--script", "list")]
    assert (result.code, result.err_lines, result.stdout.split()) == (0, [], ["demo"])


@pytest.mark.integration
@pytest.mark.timeout(90)
def test_demo_with_udp_takes_loss_and_writes_its_json(tmp_path):
    # The checks refuse only what the children would: a good link and --json still run.
    code, err, out = egc(
        *DEMO, "--transport", "udp", "--up", "loss=5,reorder=1", "--json", "s.json",
        cwd=tmp_path, timeout_s=60,
    )  # fmt: skip
    assert code == 0, err
    assert "demo summary" in out
    assert '"distance_m"' in (tmp_path / "s.json").read_text()


EPISODE_OUT = [
    (("--out", "/nonexist/r.jsonl"), "--out /nonexist/r.jsonl: directory /nonexist does not"),
    (("--out", "."), "--out .: is a directory"),
    (("--out", "/proc/r.jsonl"), "--out /proc/r.jsonl: not writable"),
]
BATCHES = [("--random-worlds", "3"), ("--batch", "suite.jsonl")]
SUITE = '{"map": "random:1"}\n{"map": "random:2"}\n'


def episode_batch(batch: tuple[str, ...], extra: tuple[str, ...]) -> tuple[str, ...]:
    return ("episode", *batch, "--max-time", "2", "--jobs", "1", *extra)


@pytest.mark.parametrize(("extra", "expected"), EPISODE_OUT)
@pytest.mark.parametrize("batch", BATCHES)
def test_episode_batch_checks_out_before_running(ran, batch, extra, expected):
    argv = episode_batch(batch, extra)
    result, cwd = ran[argv]
    assert_refused(result, argv, expected)
    assert sorted(p.name for p in cwd.iterdir()) == ["suite.jsonl"]


EPISODE_OUT_ALONE = ("episode", "--map", "hallway", "--max-time", "1", "--out", "x.jsonl")


def test_episode_out_without_a_batch_is_an_error_not_ignored(ran):
    result, _ = ran[EPISODE_OUT_ALONE]
    assert_refused(result, EPISODE_OUT_ALONE, "--out writes a batch's JSON lines")


REPLAY_OUT = [
    ("--summary", ".", "--summary .: is a directory"),
    ("--record", ".", "--record .: is a directory"),
    ("--summary", "/proc/x.json", "--summary /proc/x.json: not writable"),
]


def replay(option: str, path: str) -> tuple[str, ...]:
    return ("replay", "log", option, path)  # ./log: the corridor log, in each case's directory


@pytest.mark.parametrize(("option", "path", "expected"), REPLAY_OUT)
def test_replay_checks_its_outputs_before_replaying(ran, option, path, expected):
    argv = replay(option, path)
    result, _ = ran[argv]
    assert_refused(result, argv, expected)


@pytest.fixture(scope="module")
def ran(tmp_path_factory) -> dict[tuple[str, ...], tuple[Ran, Path]]:
    """Every command line of this module but the demo that runs, each in a new directory
    (prepared as its test says), all run at once: what each did, and its directory."""

    def nothing(cwd: Path) -> None:
        pass

    def suite(cwd: Path) -> None:
        (cwd / "suite.jsonl").write_text(SUITE)

    def log(cwd: Path) -> None:
        corridor_log(cwd / "log", "mcap")

    prepared: list[tuple[tuple[str, ...], Callable[[Path], None]]] = [
        *(((*DEMO, *extra), nothing) for extra, _ in DEMO_REFUSED),
        (("demo", "--script", "list"), nothing),
        *((episode_batch(b, extra), suite) for b in BATCHES for extra, _ in EPISODE_OUT),
        (EPISODE_OUT_ALONE, nothing),
        *((replay(option, path), log) for option, path, _ in REPLAY_OUT),
    ]
    cases = []
    for argv, prepare in prepared:
        cwd = tmp_path_factory.mktemp("cwd")
        prepare(cwd)
        cases.append((argv, cwd))
    results = cli_process.run_many(cases)
    return {argv: (result, cwd) for (argv, cwd), result in zip(cases, results, strict=True)}
