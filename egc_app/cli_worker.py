"""``python -m egc_app.cli_worker``: many ``egc-teleop`` command lines run one after another in
one process, each as ``egc_app.cli.main(argv)`` with its own stdout, stderr and exit code.

For tests, which may not import ``egc_app`` (DESIGN 2) and which check what a command line
prints and returns, not the process around it: a Python start and the imports a subcommand
needs (numpy, rosbags, the filters) cost more than a short replay itself, and are paid here
once. Whatever is about the process (signals, a crash, ``os._exit``, what the interpreter
prints at exit) still needs ``python -m egc_app.cli`` itself.

Reads one request per line of stdin, a JSON object ``{"argv": [WORDS...], "cwd": DIR,
"stdin": TEXT}`` (the words after ``egc-teleop``; ``cwd`` and ``stdin``, what the command line
reads, optional: none is an empty stdin), and writes one JSON object per line to stdout:
``{"code": EXIT_CODE, "stdout": TEXT, "stderr": TEXT}``. An exception that escapes ``main``
is its traceback on ``stderr`` and code 1, as the console script would end. A warning shown
for one command line is shown again for the next, as in a fresh process.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import sys
import traceback
import warnings
from typing import Any

from egc_app.cli import main as cli_main


def run(argv: list[str], cwd: str | None = None, stdin: str = "") -> dict[str, Any]:
    """One command line, as the console script would run it in ``cwd`` with ``stdin``."""
    out, err = io.StringIO(), io.StringIO()
    here, given_stdin = os.getcwd(), sys.stdin
    sys.stdin = io.StringIO(stdin)
    try:
        if cwd is not None:
            os.chdir(cwd)
        with (
            # entering it makes every module's warning registry stale: a warning is shown
            # again; leaving it undoes any filter the command line set
            warnings.catch_warnings(),
            contextlib.redirect_stdout(out),
            contextlib.redirect_stderr(err),
        ):
            try:
                code = cli_main(argv)
            except SystemExit as exc:  # argparse: a bad argument, --help
                code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
                if exc.code is not None and not isinstance(exc.code, int):
                    print(exc.code, file=sys.stderr)
            except BaseException:  # the traceback a user would see, and exit code 1
                traceback.print_exc()
                code = 1
    finally:
        os.chdir(here)
        sys.stdin = given_stdin
    return {"code": code, "stdout": out.getvalue(), "stderr": err.getvalue()}


def main() -> int:
    # Requests and replies get their own copies of stdin and stdout: a command line reads
    # ``sys.stdin`` (the request's text), and whatever uses the file descriptors itself
    # (native code) reads /dev/null and writes to stderr, and cannot garble them.
    requests = os.fdopen(os.dup(sys.stdin.fileno()), "r")
    replies = os.fdopen(os.dup(sys.stdout.fileno()), "w")
    os.dup2(os.open(os.devnull, os.O_RDONLY), sys.stdin.fileno())
    os.dup2(sys.stderr.fileno(), sys.stdout.fileno())
    for line in requests:
        if not line.strip():
            continue
        request = json.loads(line)
        result = run(list(request["argv"]), request.get("cwd"), request.get("stdin", ""))
        replies.write(json.dumps(result) + "\n")
        replies.flush()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
