"""An operator with ``--no-view`` does not load the view (issue 31: rerun and pyarrow made it
~130 MB and ~1 s of a core to start; 67 MB without them), nor, with no camera frame, the
decoders (PyAV and Pillow: 0.81 -> 0.67 s of CPU to import the operator)."""

from __future__ import annotations

import subprocess
import sys

from egc_common.transport import free_tcp_port


def test_an_operator_without_a_view_never_imports_rerun() -> None:
    """A real operator process driving for a second with ``--no-view`` and no robot: at its
    end, none of rerun, pyarrow, av and PIL is among its modules (the probe runs the CLI
    in-process, then looks)."""
    port = free_tcp_port()
    argv = ["operator", "--robot", "x", "--no-view", "--no-status", "--script", "demo"]
    argv += ["--duration", "1", "--zenoh-connect", f"tcp/127.0.0.1:{port}"]
    probe = (
        "import sys\n"
        "from egc_app.cli import main\n"
        f"code = main({argv!r})\n"
        "heavy = sorted({m.split('.')[0] for m in sys.modules} & {'rerun', 'pyarrow', 'av', 'PIL'})\n"
        "print(code, heavy)\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().splitlines()[-1] == "0 []", done.stdout
    assert "operator view disabled (--no-view)" in done.stderr
