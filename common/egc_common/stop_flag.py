"""A process's stop request, safe to raise from a signal handler.

``threading.Event.set`` from a SIGINT/SIGTERM handler can deadlock: Python runs the handler in
the main thread between two bytecodes, and when the main thread is inside ``Event.wait`` at that
moment it may hold the event's condition lock, which ``set`` then waits for, forever. A robot
process stopped with SIGTERM hung this way (1 stop in about 200 in a test loop, and once in CI).

:class:`StopFlag` has the part of ``threading.Event``'s interface the processes use (``set``,
``is_set``, ``wait``) and takes no lock: ``set`` stores a bool and writes a byte to a pipe,
``wait`` waits for the pipe to become readable (select). The byte is never read, so every waiter, in any
thread, wakes at once and for good. :func:`stop_on_signals` installs the handlers.
"""

from __future__ import annotations

import os
import select
import signal
from typing import Protocol


class StopRequest(Protocol):
    """What a loop needs of its stop request; ``threading.Event`` and :class:`StopFlag` both
    have it."""

    def is_set(self) -> bool: ...

    def wait(self, timeout: float | None = None) -> bool: ...

    def set(self) -> None: ...


class StopFlag:
    """A latch: once set, set for good. One per process (it holds a pipe's two descriptors)."""

    def __init__(self) -> None:
        self._read_fd, self._write_fd = os.pipe()
        os.set_blocking(self._write_fd, False)
        self._set = False

    def set(self) -> None:
        if self._set:
            return
        self._set = True
        os.write(self._write_fd, b"\0")  # once: a pipe's buffer holds far more than a byte

    def is_set(self) -> bool:
        return self._set

    def wait(self, timeout: float | None = None) -> bool:
        """Whether the flag is set, after waiting up to ``timeout`` seconds (None: for ever)
        for it. A signal during the wait runs its handler and the wait goes on (PEP 475), so a
        handler that sets the flag ends the wait at once."""
        if self._set:
            return True
        if timeout is not None and timeout <= 0:
            return False
        if self._read_fd < _FD_SETSIZE:  # select: microsecond timeouts
            select.select([self._read_fd], [], [], timeout)
        else:  # poll's are whole milliseconds (rounded up)
            poller = select.poll()
            poller.register(self._read_fd, select.POLLIN)
            poller.poll(None if timeout is None else timeout * 1e3)
        return self._set


_FD_SETSIZE = 1024


def stop_on_signals(signals: tuple[int, ...] = (signal.SIGINT, signal.SIGTERM)) -> StopFlag:
    """A new :class:`StopFlag` that these signals set (call from the main thread)."""
    stop = StopFlag()
    for sig in signals:
        signal.signal(sig, lambda *_: stop.set())
    return stop
