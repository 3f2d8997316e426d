"""The ``egc-teleop`` console script as tests see it: a real process (DESIGN 2: nothing imports
``egc_app``, tests included; running it is not importing it).

- ``main(argv)`` runs ``python -m egc_app.cli ARGV`` and returns its exit code, with what it
  printed written to this process's ``sys.stdout`` and ``sys.stderr`` (so pytest's ``capsys``
  reads it as it read the console script run in the test's own process).
- ``parse(*argvs)`` puts command lines through the subcommands' real parsers without running
  them (``python -m egc_app.parse_check``, one process for all): per line, the parsed
  arguments as a dict, or the parser's one-line error as a str.
- ``run_many(cases)`` runs command lines that should refuse their arguments, all in one process
  (``python -m egc_app.cli_worker``), each as the console script runs it: per line, its exit
  code and what it wrote (``Ran``). One interpreter and one import of the subcommands for all.
- ``child_env(**extra)``: this process's environment plus a few variables, for a child.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

CLI = [sys.executable, "-m", "egc_app.cli"]
TIMEOUT_S = 600.0  # a limit against a hang, not a measure: a batch on a busy machine is slow


def child_env(**extra: str) -> dict[str, str]:
    """This process's environment plus ``extra``: for a child that needs a variable of its own
    (the compiled-bytecode setting every child inherits is made once, in ``tests/conftest.py``)."""
    return dict(os.environ) | extra


def main(argv: Sequence[str], timeout_s: float = TIMEOUT_S) -> int:
    """``egc-teleop ARGV`` in its own process, from the test's working directory."""
    proc = subprocess.run(
        [*CLI, *argv],
        capture_output=True,
        text=True,
        timeout=timeout_s,
        cwd=os.getcwd(),
        stdin=subprocess.DEVNULL,
    )
    sys.stdout.write(proc.stdout)
    sys.stderr.write(proc.stderr)
    return proc.returncode


def parse(*argvs: Sequence[str]) -> list[dict[str, Any] | str]:
    """Each command line (the words after ``egc-teleop``) through its subcommand's parser."""
    proc = subprocess.run(
        [sys.executable, "-m", "egc_app.parse_check"],
        input="".join(json.dumps(list(argv)) + "\n" for argv in argvs),
        capture_output=True,
        text=True,
        timeout=TIMEOUT_S,
        check=True,
    )
    results = [json.loads(line) for line in proc.stdout.splitlines()]
    assert len(results) == len(argvs), proc.stderr
    return [r["args"] if "args" in r else r["error"] for r in results]


@dataclass(frozen=True)
class Ran:
    """What one command line of ``run_many`` did."""

    code: int
    stdout: str
    stderr: str

    @property
    def err_lines(self) -> list[str]:
        return self.stderr.strip().splitlines()


def run_many(
    cases: Sequence[tuple[Sequence[str], Path]], timeout_s: float = 300.0, **env: str
) -> list[Ran]:
    """Each ``(argv, cwd)``: ``egc-teleop ARGV`` run in ``cwd`` (``python -m egc_app.cli_worker``,
    one process for all, stdin empty, ``env`` added to the environment). A command that runs on
    instead of refusing is stopped at ``timeout_s``: it, and each command after it (not run),
    gets exit code -1 and a line saying so, so every test that reads them fails at once, naming
    it."""
    lines = "".join(json.dumps({"argv": list(a), "cwd": str(c)}) + "\n" for a, c in cases)
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "egc_app.cli_worker"],
            input=lines,
            capture_output=True,
            text=True,
            timeout=timeout_s,
            env=child_env(**env),
        )
    except subprocess.TimeoutExpired as exc:
        out = exc.stdout.decode() if isinstance(exc.stdout, bytes) else exc.stdout or ""
        done = [Ran(**json.loads(line)) for line in out.splitlines()]
        hung = list(cases[len(done)][0])
        said = f"egc-teleop {hung} still ran after {timeout_s} s instead of refusing its arguments"
        return done + [Ran(-1, "", said)] * (len(cases) - len(done))
    results = [Ran(**json.loads(line)) for line in proc.stdout.splitlines()]
    assert proc.returncode == 0 and len(results) == len(cases), proc.stderr
    return results
