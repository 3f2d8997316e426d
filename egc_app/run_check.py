"""``python -m egc_app.run_check``: ``egc-teleop`` command lines run one after another in one
process, each exactly as the console script runs it (``egc_app.cli.main``).

For tests of what a command says and returns when it refuses its arguments (DESIGN 2: one line
on stderr, exit 2, before anything runs), which may not import ``egc_app``: one interpreter
start-up and one import of the subcommands for many command lines, where a process each cost
a second apiece. Tests of a running command (sessions, children, signals) start real processes.

Reads every command line first, one JSON object per line of stdin until its end:
``{"argv": [WORD, ...], "cwd": DIR}`` (the words after ``egc-teleop``), then runs each in
``cwd`` with stdin empty and writes one JSON object per line to stdout as soon as it is done:
``{"code": N, "stdout": TEXT, "stderr": TEXT}``. What a command writes goes to files in place
of its file descriptors 1 and 2, so log lines, native libraries and child processes are caught
as a real process's would be. Logging is reset before each command (each configures its own).
A command that runs on instead of refusing shows as the line that does not come: the caller
keeps the deadline.
"""

from __future__ import annotations

import json
import logging
import os
import sys
import tempfile
from typing import Any

from egc_app.cli import main as egc_teleop


def _reset_logging() -> None:
    root = logging.getLogger()
    for handler in root.handlers[:]:
        root.removeHandler(handler)
        handler.close()
    root.setLevel(logging.WARNING)


def _run(argv: list[str], cwd: str) -> dict[str, Any]:
    """``egc-teleop ARGV`` in ``cwd``, its fd 1 and 2 in temporary files meanwhile."""
    saved = os.getcwd()
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        sys.stdout.flush()
        sys.stderr.flush()
        kept = os.dup(1), os.dup(2)
        os.dup2(out.fileno(), 1)
        os.dup2(err.fileno(), 2)
        try:
            os.chdir(cwd)
            _reset_logging()
            try:
                code = egc_teleop(argv)
            except SystemExit as exc:  # argparse: --help, a bad option
                code = exc.code if isinstance(exc.code, int) else 1 if exc.code else 0
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os.dup2(kept[0], 1)
            os.dup2(kept[1], 2)
            os.close(kept[0])
            os.close(kept[1])
            os.chdir(saved)
        texts = []
        for f in (out, err):
            f.seek(0)
            texts.append(f.read().decode("utf-8", errors="replace"))
    return {"code": code, "stdout": texts[0], "stderr": texts[1]}


def main() -> int:
    cases = [json.loads(line) for line in sys.stdin if line.strip()]
    devnull = os.open(os.devnull, os.O_RDONLY)
    os.dup2(devnull, 0)  # what a command reads from stdin: nothing, as the tests' processes
    os.close(devnull)
    results = os.fdopen(os.dup(1), "w", encoding="utf-8")
    for case in cases:
        result = _run([str(w) for w in case["argv"]], str(case["cwd"]))
        results.write(json.dumps(result) + "\n")
        results.flush()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
