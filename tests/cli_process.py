"""The ``egc-teleop`` console script as tests see it: a real process (DESIGN 2: nothing imports
``egc_app``, tests included; running it is not importing it).

- ``main(argv)`` runs ``python -m egc_app.cli ARGV`` and returns its exit code, with what it
  printed written to this process's ``sys.stdout`` and ``sys.stderr`` (so pytest's ``capsys``
  reads it as it read the console script run in the test's own process).
- ``parse(*argvs)`` puts command lines through the subcommands' real parsers without running
  them (``python -m egc_app.parse_check``, one process for all): per line, the parsed
  arguments as a dict, or the parser's one-line error as a str.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Sequence
from typing import Any

CLI = [sys.executable, "-m", "egc_app.cli"]
TIMEOUT_S = 600.0  # a limit against a hang, not a measure: a batch on a busy machine is slow


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
