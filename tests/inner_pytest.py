"""A pytest run inside a test: a small suite in a folder of its own, with one of this
repository's plugins for the whole run (``tests/suite_budget.py``, ``tests/worker_crash.py``)
configured as ``tests/conftest.py`` configures it, run as a process of its own."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def run_suite(
    folder: Path, plugin: str, files: dict[str, str], args: list[str], env: dict[str, str]
) -> subprocess.CompletedProcess[str]:
    """``files`` (name: source, dedented) in ``folder`` beside a conftest that configures
    ``tests.<plugin>``, run by ``pytest ARGS -q`` with ``env`` added to this environment."""
    (folder / "conftest.py").write_text(
        f"from tests import {plugin}\n\n\n"
        "def pytest_configure(config):\n"
        f"    {plugin}.configure(config)\n"
    )
    for name, source in files.items():
        (folder / name).write_text(textwrap.dedent(source))
    path = f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"
    return subprocess.run(
        [sys.executable, "-m", "pytest", *args, "-p", "no:cacheprovider", "-q", str(folder)],
        cwd=folder,
        env={**os.environ, **env, "PYTHONPATH": path},
        capture_output=True,
        text=True,
        timeout=240,
    )
