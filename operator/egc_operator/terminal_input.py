"""Lines typed on the operator's terminal (DESIGN 15: ``robot NAME``, ``next``, ``list``, ...).

A daemon thread reads lines from a terminal and hands each to ``on_line``; it is started only
when standard input is a terminal (a pipe or a file on stdin may be the joystick file itself,
``--joystick-file /dev/stdin``, and a script has no one typing). An operator started in the
background of its shell (``&``) would be stopped by SIGTTIN at its first read: the signal is
ignored instead, the read fails with EIO while the process is in the background, and the
thread tries again every second, so the commands work once it is brought to the foreground.
End of input (Ctrl-D) ends the thread, not the operator.
"""

from __future__ import annotations

import errno
import logging
import signal
import threading
from collections.abc import Callable
from typing import TextIO

log = logging.getLogger("egc.operator")

_BACKGROUND_RETRY_S = 1.0


class TerminalInput:
    def __init__(self, stream: TextIO, on_line: Callable[[str], None]) -> None:
        self._stream = stream
        self._on_line = on_line
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._read, name="terminal-input", daemon=True)

    @staticmethod
    def wanted(stream: TextIO) -> bool:
        try:
            return stream.isatty()
        except (ValueError, OSError):  # closed
            return False

    def start(self) -> None:
        if threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGTTIN, signal.SIG_IGN)
        self._thread.start()

    def _read(self) -> None:
        while not self._stop.is_set():
            try:
                line = self._stream.readline()
            except OSError as exc:
                if exc.errno == errno.EIO:  # in the background of its shell: wait to be foreground
                    self._stop.wait(_BACKGROUND_RETRY_S)
                    continue
                log.debug("terminal input ends: %s", exc)
                return
            except ValueError:  # the stream was closed
                return
            if not line:  # end of input
                return
            try:
                self._on_line(line)
            except Exception as exc:  # a typed line must never end the operator
                log.warning("typed command failed: %s", exc)

    def stop(self) -> None:
        self._stop.set()
