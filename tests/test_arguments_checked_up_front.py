"""Bad arguments: one line on stderr and exit 2, before anything runs (DESIGN 2; README).

An outside "fresh user" check found output paths checked only when the run was over
(``demo --json /nonexist/x.json`` ran the whole demo, then a FileNotFoundError traceback and no
summary; ``episode --random-worlds 3 --out DIR`` an IsADirectoryError; ``replay --summary DIR``
the same), and bad demo arguments reported by whichever child process started first (two to four
lines, exit 1, the robot's stop summary among them). Each case is a real ``egc-teleop`` process;
a timeout guards the ones that, unfixed, would start a demo or a batch.
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.replay.logs import corridor_log


def egc(*argv: str, cwd: Path, timeout_s: float = 120.0) -> tuple[int, list[str], str, float]:
    t0 = time.monotonic()
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
    return proc.returncode, proc.stderr.strip().splitlines(), proc.stdout, time.monotonic() - t0


def assert_refused(argv: tuple[str, ...], expected: str, cwd: Path) -> None:
    code, err, out, _ = egc(*argv, cwd=cwd)
    assert code == 2, err
    assert len(err) == 1, err  # one line: the demo's own, no child's
    assert err[0].startswith(f"egc-teleop {argv[0]}: error: ") and expected in err[0], err
    assert out == ""  # refused before anything ran: no summary (the single line above: no child's)


DEMO = ("demo", "--no-view", "--duration", "1")


@pytest.mark.parametrize(
    ("extra", "expected"),
    [
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
    ],
)
def test_demo_refuses_bad_arguments_before_any_child_starts(tmp_path, extra, expected):
    assert_refused((*DEMO, *extra), expected, tmp_path)
    assert list(tmp_path.iterdir()) == []  # no file created on the way (the --json probe either)


def test_demo_script_list_lists_the_scripts_as_the_operator_does(tmp_path):
    code, err, out, _ = egc("demo", "--script", "list", cwd=tmp_path)
    assert (code, err, out.split()) == (0, [], ["demo"])


@pytest.mark.integration
@pytest.mark.timeout(90)
def test_demo_with_udp_takes_loss_and_writes_its_json(tmp_path):
    # The checks refuse only what the children would: a good link and --json still run.
    code, err, out, _ = egc(
        *DEMO, "--transport", "udp", "--up", "loss=5,reorder=1", "--json", "s.json",
        cwd=tmp_path, timeout_s=60,
    )  # fmt: skip
    assert code == 0, err
    assert "demo summary" in out
    assert '"distance_m"' in (tmp_path / "s.json").read_text()


@pytest.mark.parametrize(
    ("extra", "expected"),
    [
        (("--out", "/nonexist/r.jsonl"), "--out /nonexist/r.jsonl: directory /nonexist does not"),
        (("--out", "."), "--out .: is a directory"),
        (("--out", "/proc/r.jsonl"), "--out /proc/r.jsonl: not writable"),
    ],
)
@pytest.mark.parametrize("batch", [("--random-worlds", "3"), ("--batch", "suite.jsonl")])
def test_episode_batch_checks_out_before_running(tmp_path, batch, extra, expected):
    (tmp_path / "suite.jsonl").write_text('{"map": "random:1"}\n{"map": "random:2"}\n')
    assert_refused(
        ("episode", *batch, "--max-time", "2", "--jobs", "1", *extra), expected, tmp_path
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["suite.jsonl"]


def test_episode_out_without_a_batch_is_an_error_not_ignored(tmp_path):
    argv = ("episode", "--map", "hallway", "--max-time", "1", "--out", "x.jsonl")
    assert_refused(argv, "--out writes a batch's JSON lines", tmp_path)


@pytest.mark.parametrize(
    ("option", "path", "expected"),
    [
        ("--summary", ".", "--summary .: is a directory"),
        ("--record", ".", "--record .: is a directory"),
        ("--summary", "/proc/x.json", "--summary /proc/x.json: not writable"),
    ],
)
def test_replay_checks_its_outputs_before_replaying(tmp_path, option, path, expected):
    log = corridor_log(tmp_path / "log", "mcap")
    assert_refused(("replay", str(log), option, path), expected, tmp_path)
