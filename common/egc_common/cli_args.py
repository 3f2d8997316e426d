"""Command-line conventions shared by every entry point (DESIGN 2).

Coordinates are typed the way people type them: ``--start -12.5,8.5,0`` and ``--goal -2,3``
must work, so a leading minus followed by a digit is a number (also in a comma-separated
list), not an option. argparse's own pattern accepts a single number only.
"""

from __future__ import annotations

import argparse
import re

NEGATIVE_NUMBERS = re.compile(r"^-\d[\d.eE+\-]*(,[\-+]?[\d.eE+\-]+)*$|^-\.\d")


def numbers_are_values(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Make ``parser`` take ``-12.5,8.5,0`` as a value (see the module docstring)."""
    parser._negative_number_matcher = NEGATIVE_NUMBERS  # argparse's hook for this very check
    return parser
