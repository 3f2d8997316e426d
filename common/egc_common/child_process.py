"""Children that do not outlive their parent.

``die_with_parent`` is a ``preexec_fn`` for ``subprocess.Popen``: the child asks the kernel for
SIGTERM when the thread that started it exits (Linux ``PR_SET_PDEATHSIG``), so a parent that is
killed (a demo stopped with SIGKILL, a pytest worker ended by the suite's budget) leaves no
orphans behind. Elsewhere it does nothing.
"""

from __future__ import annotations

import ctypes
import signal

_PR_SET_PDEATHSIG = 1


def die_with_parent() -> None:
    """In the child, before exec: receive SIGTERM when the parent dies (best effort)."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)
    except (OSError, AttributeError):
        pass
