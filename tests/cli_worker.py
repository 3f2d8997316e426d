"""``egc-teleop`` command lines run in one long-lived process (``python -m egc_app.cli_worker``),
for tests about what a command line prints, writes and returns: the interpreter's start and the
subcommand's imports are paid once per pytest process, not once per command line.

``main(argv)`` (the shared worker's ``CliWorker.main``) is ``tests.cli_process.main`` without a
process of its own: the exit code returned, what it printed written to this process's ``sys.stdout`` and ``sys.stderr`` (for
``capsys``). Tests about the process itself (signals, crashes, warnings printed at exit, a
traceback on a real stderr) start ``python -m egc_app.cli`` as before.
"""

from __future__ import annotations

import atexit
import json
import os
import subprocess
import sys
from collections.abc import Sequence

WORKER = [sys.executable, "-m", "egc_app.cli_worker"]


class CliWorker:
    """One ``egc_app.cli_worker`` process, started on the first command line."""

    def __init__(self) -> None:
        self._proc: subprocess.Popen[str] | None = None

    def main(self, argv: Sequence[str], stdin: str = "") -> int:
        """``egc-teleop ARGV`` in the worker, from the test's working directory, reading
        ``stdin``."""
        proc = self._proc
        if proc is None or proc.poll() is not None:
            proc = self._proc = subprocess.Popen(
                WORKER,
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                text=True,
                bufsize=1,
            )
        assert proc.stdin is not None and proc.stdout is not None
        proc.stdin.write(
            json.dumps({"argv": list(argv), "cwd": os.getcwd(), "stdin": stdin}) + "\n"
        )
        proc.stdin.flush()
        reply = proc.stdout.readline()
        assert reply, f"the CLI worker exited ({proc.wait()}) on {list(argv)}"
        result = json.loads(reply)
        sys.stdout.write(result["stdout"])
        sys.stderr.write(result["stderr"])
        return int(result["code"])

    def close(self) -> None:
        if self._proc is not None:
            assert self._proc.stdin is not None
            self._proc.stdin.close()
            try:
                self._proc.wait(timeout=60)
            except subprocess.TimeoutExpired:
                self._proc.kill()
                self._proc.wait()
            self._proc = None


_SHARED = CliWorker()
main = _SHARED.main
atexit.register(_SHARED.close)
