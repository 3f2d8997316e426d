"""``python -m egc_app.cli_worker``: ``egc-teleop`` command lines run one after another in one
process, each as the console script runs it (``egc_app.cli.main``).

For tests, which may not import ``egc_app`` (DESIGN 2) and which check what a command line
prints, writes and returns (a refusal: one line on stderr and exit 2 before anything runs; a
short replay; ``--help``), not the process around it: a Python start and the imports a
subcommand needs (numpy, rosbags, the filters) cost more than many such command lines, and are
paid here once. Whatever is about the process (sessions, children, signals, a crash,
``os._exit``, what the interpreter prints at exit) still needs ``python -m egc_app.cli``.

Reads one request per line of stdin, a JSON object ``{"argv": [WORD, ...], "cwd": DIR, "stdin":
TEXT}`` (the words after ``egc-teleop``; ``cwd`` and ``stdin`` optional: this process's
directory, an empty stdin), and writes one JSON object per line to stdout as soon as the command
line is done: ``{"code": EXIT_CODE, "stdout": TEXT, "stderr": TEXT}``. What a command line
writes goes to files in place of its file descriptors 1 and 2 (log lines, native libraries and
child processes are caught as a real process's would be), and its descriptor 0 is a file
holding ``stdin``. Logging is reset before each (each configures its own), and a warning shown
for one command line is shown again for the next, as in a fresh process. An exception that
escapes ``main`` is its traceback on stderr and exit code 1, as the console script would end. A
command line that runs on instead of ending shows as the reply that does not come: the caller
keeps the deadline.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import sys
import tempfile
import traceback
import warnings
from collections.abc import Iterator
from typing import IO, Any

from egc_app.cli import main as egc_teleop


def _reset_logging() -> None:
    root = logging.getLogger()
    for handler in root.handlers[:]:
        root.removeHandler(handler)
        handler.close()
    root.setLevel(logging.WARNING)


@contextlib.contextmanager
def _descriptors(stdin: str) -> Iterator[tuple[IO[bytes], IO[bytes]]]:
    """Descriptors 0, 1 and 2 (and sys.stdin on 0) on temporary files for the block: the first
    holding ``stdin``; the other two are yielded, to be read inside the block (they close at
    its end)."""
    with (
        tempfile.TemporaryFile() as given,
        tempfile.TemporaryFile() as out,
        tempfile.TemporaryFile() as err,
    ):
        given.write(stdin.encode())
        given.seek(0)
        sys.stdout.flush()
        sys.stderr.flush()
        kept = [os.dup(fd) for fd in (0, 1, 2)]
        streams = sys.stdin, sys.stdout, sys.stderr
        for f, fd in ((given, 0), (out, 1), (err, 2)):
            os.dup2(f.fileno(), fd)
        sys.stdin = open(0, closefd=False, encoding="utf-8")  # noqa: SIM115 - closed below
        try:
            yield out, err
        finally:
            sys.stdin.close()
            sys.stdin = streams[0]
            sys.stdout.flush()
            sys.stderr.flush()
            for fd, k in enumerate(kept):
                os.dup2(k, fd)
                os.close(k)


def run(argv: list[str], cwd: str | None = None, stdin: str = "") -> dict[str, Any]:
    """One command line, as the console script would run it in ``cwd`` reading ``stdin``."""
    here = os.getcwd()
    with _descriptors(stdin) as (out, err):
        try:
            if cwd is not None:
                os.chdir(cwd)
            _reset_logging()
            # entering it makes every module's warning registry stale (a warning is shown
            # again); leaving it undoes any filter the command line set
            with warnings.catch_warnings():
                try:
                    code = egc_teleop(argv)
                except SystemExit as exc:  # argparse: a bad argument, --help
                    code = exc.code if isinstance(exc.code, int) else 0 if exc.code is None else 1
                    if exc.code is not None and not isinstance(exc.code, int):
                        print(exc.code, file=sys.stderr)
                except BaseException:  # the traceback a user would see, and exit code 1
                    traceback.print_exc()
                    code = 1
        finally:
            os.chdir(here)
        sys.stdout.flush()
        sys.stderr.flush()
        return {"code": code, "stdout": _text(out), "stderr": _text(err)}


def _text(f: IO[bytes]) -> str:
    f.seek(0)
    return f.read().decode("utf-8", errors="replace")


def main() -> int:
    # Requests and replies on descriptors of their own: 0, 1 and 2 are the command lines'.
    requests = os.fdopen(os.dup(0), "r", encoding="utf-8")
    replies = os.fdopen(os.dup(1), "w", encoding="utf-8")
    for line in requests:
        if not line.strip():
            continue
        request = json.loads(line)
        result = run(
            [str(w) for w in request["argv"]], request.get("cwd"), request.get("stdin", "")
        )
        replies.write(json.dumps(result) + "\n")
        replies.flush()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
