"""Which clock ``time.monotonic_ns()`` reads, so that two processes can tell they share it.

On Linux, CLOCK_MONOTONIC belongs to the running kernel: every process of one host, network
namespaces included, reads the same clock, and the kernel's boot id names it. The robot sends
this id with its clock replies (``messages.encode_clock_reply``); an operator with the same id
needs no offset estimate at all (``ClockSync.add(..., same_clock=True)``). Elsewhere: None.
"""

from __future__ import annotations

from pathlib import Path

_BOOT_ID = Path("/proc/sys/kernel/random/boot_id")


def monotonic_clock_id() -> str | None:
    try:
        boot = _BOOT_ID.read_text(encoding="ascii").strip()
    except (OSError, UnicodeDecodeError):
        return None
    return f"linux-boot:{boot}" if boot else None
