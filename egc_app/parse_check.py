"""``python -m egc_app.parse_check``: ``egc-teleop`` command lines through the subcommands' real
parsers, without running them.

Reads one command line per line of stdin, as a JSON array of the words after ``egc-teleop``
(``["episode", "--start", "-12.5,8.5,0"]``), and writes one JSON object per line to stdout:
``{"command": NAME, "args": {DEST: VALUE, ...}}`` when it parses (values JSON can not hold are
given as their ``str``), ``{"error": LINE}`` with the parser's one line when it does not.

For documentation and tests, which may not import ``egc_app`` (DESIGN 2: nothing imports the
console script): a command line in a README parses, a coordinate with a leading minus is taken
as a value. A subcommand's module may define ``check_arguments_alone(args)``: the checks of the
arguments on their own that it makes before anything else (``--goal`` without ``--robot``), run
here too; a ``UsageError`` from it is the line's error. Whatever the subcommand would check once
it runs (files, ports, maps) is not checked here.
"""

from __future__ import annotations

import contextlib
import importlib
import io
import json
import sys
from typing import Any

from egc_common.cli_args import CliArgumentParser
from egc_common.errors import UsageError

from egc_app.cli import SUBCOMMANDS


def _parse(words: list[str]) -> dict[str, Any]:
    if not words or words[0] not in SUBCOMMANDS:
        return {"error": f"not an egc-teleop subcommand: {words[:1]!r}"}
    name = words[0]
    parser = CliArgumentParser(prog=f"egc-teleop {name}")
    module = importlib.import_module(SUBCOMMANDS[name][0])
    module.configure(parser)
    said = io.StringIO()
    try:
        with contextlib.redirect_stderr(said), contextlib.redirect_stdout(said):
            args = parser.parse_args(words[1:])
    except SystemExit as exc:
        if not exc.code:
            return {"error": "the parser printed its help and exited 0"}
        lines = said.getvalue().strip().splitlines()
        return {"error": lines[-1] if lines else f"the parser exited {exc.code}"}
    check = getattr(module, "check_arguments_alone", None)
    if check is not None:
        try:
            check(args)
        except UsageError as exc:
            return {"error": f"egc-teleop {name}: error: {exc}"}
    return {"command": name, "args": vars(args)}


def main() -> int:
    for line in sys.stdin:
        if not line.strip():
            continue
        words = json.loads(line)
        if not isinstance(words, list) or not all(isinstance(w, str) for w in words):
            result: dict[str, Any] = {"error": f"expected a JSON array of strings: {line!r}"}
        else:
            result = _parse(words)
        print(json.dumps(result, default=str), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
