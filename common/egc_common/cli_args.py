"""Command-line conventions shared by every entry point (DESIGN 2).

Coordinates are typed the way people type them: ``--start -12.5,8.5,0`` and ``--goal -2,3``
must work, so a leading minus followed by a digit is a number (also in a comma-separated
list), not an option; so are ``-nan``, ``-inf`` and any comma list after one minus, so that a
mistyped coordinate gets the option's own message, not "expected one argument". argparse's
own pattern accepts a single number only.

Numbers in coordinates, on the command line and in input files, are plain ASCII decimals
(``plain_float``): Python's ``float()`` also takes ``1_000``, full-width digits and other
Unicode digits, which nobody types on purpose. Every value ``plain_float`` reads after a minus
is one ``NEGATIVE_NUMBERS`` lets through as a value, so ``-2,3`` keeps working.

Input files (joystick CSVs, route files) are read with ``read_input_file``: at most a bound of
bytes, so a device, a pipe or a huge file given by mistake costs bounded memory and gets one
line, and a UTF-8 byte-order mark (what some editors write first) is accepted.

Every ``egc-teleop`` process imports this module first, so it imports the robot profiles (and
with them numpy) only when ``PROFILE_HELP`` or ``profile_arg`` is used: ``egc-teleop link``,
``router``, ``bench`` and ``--help`` never load them.
"""

from __future__ import annotations

import argparse
import errno
import os
import re
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

from egc_common.errors import UsageError

# A minus then a digit, a point and a digit, or nan/inf, or a single minus and a comma later:
# a value (so "-3,abc" reaches the option's own check and its message), never an option name.
NEGATIVE_NUMBERS = re.compile(r"^-(\d|\.\d|nan|inf|,)|^-[^-][^=]*,", re.IGNORECASE)


# A plain decimal: sign, digits with at most one point, optional exponent (ASCII only); and the
# words nan and inf(inity), so that the caller's finiteness check can say what is wrong.
PLAIN_NUMBER = re.compile(
    r"[+-]?(?:(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|nan|inf|infinity)", re.ASCII | re.IGNORECASE
)
_SPACE = " \t\r\n\f\v"


def plain_float(text: str) -> float:
    """``text`` (ASCII blanks around it allowed) as a float when it is a plain ASCII decimal
    such as ``-2``, ``.5``, ``3.``, ``1e-3`` (or nan/inf, which callers reject with their own
    finiteness message); ValueError otherwise, also for what ``float()`` alone would take:
    ``1_000``, full-width or other non-ASCII digits."""
    stripped = text.strip(_SPACE)
    if not PLAIN_NUMBER.fullmatch(stripped):
        raise ValueError(f"not a plain decimal number: {text!r}")
    return float(stripped)


MiB = 1024 * 1024


def read_input_file(path: str | Path, what: str, limit_bytes: int) -> str:
    """The text of the input file ``path`` (UTF-8, a leading byte-order mark dropped).

    At most ``limit_bytes`` + 1 bytes are ever read, so /dev/zero, a pipe or a sparse 3 GB file
    costs bounded memory. ValueError with one line naming ``what`` and ``path``: not found, a
    directory, unreadable, larger than the limit (the limit is in the message), not UTF-8.
    """
    p = Path(path)
    try:
        with p.open("rb") as f:
            data = f.read(limit_bytes + 1)
    except FileNotFoundError:
        raise ValueError(f"{what} not found: {p}") from None
    except OSError as exc:
        reason = exc.strerror or os.strerror(exc.errno or errno.EIO)
        raise ValueError(f"cannot read {what} {p}: {reason}") from None
    if len(data) > limit_bytes:
        raise ValueError(
            f"{what} {p}: more than {_size(limit_bytes)}, the most a {what} may have "
            "(is it the right file?)"
        )
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ValueError(
            f"cannot read {what} {p}: not UTF-8 text (byte {exc.start} is {data[exc.start]:#04x})"
        ) from None


def _size(n: int) -> str:
    return f"{n / MiB:g} MiB" if n >= MiB else f"{n} bytes"


def numbers_are_values(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Make ``parser`` take ``-12.5,8.5,0`` as a value (see the module docstring)."""
    parser._negative_number_matcher = NEGATIVE_NUMBERS  # argparse's hook for this very check
    return parser


class CliArgumentParser(argparse.ArgumentParser):
    """The parser of every ``egc-teleop`` subcommand: bad arguments are one clear line on
    stderr and exit code 2 (DESIGN 2), and values that start with a minus and a digit are
    values, not options (``numbers_are_values``). Here, not in the console script, so that a
    subcommand's parser can be built and checked without it (nothing imports ``egc_app``)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        numbers_are_values(self)

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


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


def _profile_help() -> str:
    from egc_common.profiles import PROFILES

    return (
        f"robot profile: a built-in name ({', '.join(sorted(PROFILES))}) or a profile FILE.toml "
        "with a [profile] table (DESIGN 14)"
    )


if TYPE_CHECKING:
    PROFILE_HELP: str  # the --profile option's help, made on first use (module docstring)
else:

    def __getattr__(name: str) -> str:
        if name == "PROFILE_HELP":
            globals()[name] = help_text = _profile_help()
            return help_text
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def profile_arg(text: str) -> str:
    """argparse ``type=`` of every ``--profile NAME|FILE.toml``: the profile is loaded now, so
    an unknown name or a bad file is the parser's one line and exit 2 (naming the key and the
    problem), before anything starts. The text is kept (it is handed on to child processes)."""
    from egc_common.profiles import ProfileError, load_profile

    try:
        load_profile(text)
    except ProfileError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text
