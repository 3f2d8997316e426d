"""Errors shared by the command-line front ends."""


class UsageError(Exception):
    """A bad argument value found after parsing: the CLI prints one line and exits with 2."""
