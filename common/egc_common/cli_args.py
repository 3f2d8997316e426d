"""Command-line conventions shared by every entry point (DESIGN 2).

Coordinates are typed the way people type them: ``--start -12.5,8.5,0`` and ``--goal -2,3``
must work, so a leading minus followed by a digit is a number (also in a comma-separated
list), not an option; so are ``-nan``, ``-inf`` and any comma list after one minus, so that a
mistyped coordinate gets the option's own message, not "expected one argument". argparse's
own pattern accepts a single number only.
"""

from __future__ import annotations

import argparse
import errno
import os
import re
from pathlib import Path

from egc_common.errors import UsageError

# A minus then a digit, a point and a digit, or nan/inf, or a single minus and a comma later:
# a value (so "-3,abc" reaches the option's own check and its message), never an option name.
NEGATIVE_NUMBERS = re.compile(r"^-(\d|\.\d|nan|inf|,)|^-[^-][^=]*,", re.IGNORECASE)


def numbers_are_values(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Make ``parser`` take ``-12.5,8.5,0`` as a value (see the module docstring)."""
    parser._negative_number_matcher = NEGATIVE_NUMBERS  # argparse's hook for this very check
    return parser


def check_writable(path: str | Path, option: str) -> None:
    """Raise UsageError unless ``path`` can be written: its directory exists (it is not
    created) and a file can be created there (or the existing file opened for writing).

    Every output file of every command is checked this way before anything starts, so a typo
    is one line now, not a traceback when the run ends (or a directory made at the root).
    Opening the file is the one reliable check: root passes ``os.access`` where /proc and
    read-only mounts refuse the file.
    """
    if isinstance(path, str) and not path:
        raise UsageError(f"{option}: an empty path")
    target = Path(path)
    parent = target.parent
    if target.is_dir():
        raise UsageError(f"{option} {path}: is a directory")
    if parent.exists() and not parent.is_dir():
        raise UsageError(f"{option} {path}: {parent} is not a directory")
    if not parent.is_dir():
        raise UsageError(f"{option} {path}: directory {parent} does not exist (create it first)")
    existed = target.exists()
    try:
        with target.open("ab"):
            pass
    except OSError as exc:
        reason = exc.strerror or os.strerror(exc.errno or errno.EIO)
        raise UsageError(f"{option} {path}: not writable ({reason})") from None
    if not existed:
        target.unlink(missing_ok=True)
