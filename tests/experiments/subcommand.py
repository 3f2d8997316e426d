"""An ``egc-teleop`` subcommand run in the test's own process: its real parser (built by the
module's ``configure``) and its ``run``, with what ``egc_app.cli`` adds around them (DESIGN 2,
pinned: a ``UsageError`` is one line ``egc-teleop NAME: error: ...`` on stderr and exit code 2;
the parser's own errors exit 2 with one line too).

For tests about arguments, messages, output files and exit codes, where a new interpreter per
command line (about a second of imports each) would test nothing more. Tests may not import
``egc_app`` (nothing does), so the two lines of its error handling are restated here; each test
file that uses this keeps at least one command line through the real console script
(``tests.cli_process.main``), which holds ``egc_app.cli`` to the same behaviour.
"""

from __future__ import annotations

import signal
import sys
from collections.abc import Sequence
from types import ModuleType

from egc_common.cli_args import CliArgumentParser
from egc_common.errors import UsageError

_SIGNALS = (signal.SIGINT, signal.SIGTERM)


def run_subcommand(module: ModuleType, name: str, argv: Sequence[str]) -> int:
    """``egc-teleop NAME ARGV`` through ``module``'s parser and ``run``; its exit code.

    The signal handlers a run installs (``experiment`` stops cleanly on SIGTERM) are put back
    afterwards, so that they do not outlive the command in the test process.
    """
    handlers = {sig: signal.getsignal(sig) for sig in _SIGNALS}
    parser = CliArgumentParser(prog=f"egc-teleop {name}")
    module.configure(parser)
    try:
        args = parser.parse_args(list(argv))
        return int(module.run(args) or 0)
    except SystemExit as exc:  # the parser's error (exit 2) or --help (exit 0)
        return exc.code if isinstance(exc.code, int) else 1
    except UsageError as exc:
        print(f"egc-teleop {name}: error: {exc}", file=sys.stderr)
        return 2
    finally:
        for sig, handler in handlers.items():
            signal.signal(sig, handler)
