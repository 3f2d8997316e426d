"""A crashed pytest-xdist worker ends the whole run after the other workers' current tests.

With ``--max-worker-restart=0`` (pyproject) pytest-xdist reports the crashed worker's test as
failed, with its name, and replaces no worker; but the other workers still ran every test left in
their queues. In CI run 74 a worker segfaulted at 80% of the suite: the failure was printed at
once, the run ended 6.5 minutes later, and 464 tests never ran anyway (issue 31).

Here the reporting process (the xdist controller) writes a flag file when a worker goes down
with an error and asks xdist to stop (its ``shouldstop``, as ``--maxfail`` does). Every worker
looks for that file after each test and, when it is there, stops after that test: the run ends
with the crashed test's name, pytest's summary of what failed, and exit status 2 (interrupted).
The flag file reaches the workers through ``workerinput``, xdist's way to hand them settings.
"""

from __future__ import annotations

import contextlib
import shutil
import tempfile
from collections.abc import Generator
from pathlib import Path
from typing import Any

import pytest

FLAG_KEY = "egc_worker_crash_flag"


class Controller:
    """In the reporting process: hands the flag's path to each worker; raises it on a crash."""

    def __init__(self, config: pytest.Config) -> None:
        self._config = config
        self._dir = Path(tempfile.mkdtemp(prefix="egc-worker-crash-"))
        self.flag = self._dir / "crashed"

    @pytest.hookimpl(optionalhook=True)
    def pytest_configure_node(self, node: Any) -> None:
        node.workerinput[FLAG_KEY] = str(self.flag)

    @pytest.hookimpl(optionalhook=True)
    def pytest_testnodedown(self, node: Any, error: object | None) -> None:
        if error is None:  # a worker that finished its queue
            return
        why = f"worker {node.gateway.id} crashed ({error}); the others stopped after their test"
        with contextlib.suppress(OSError):
            self.flag.write_text(why)
        dsession = self._config.pluginmanager.getplugin("dsession")
        if dsession is not None and not getattr(dsession, "shouldstop", True):
            dsession.shouldstop = why

    def pytest_unconfigure(self) -> None:
        shutil.rmtree(self._dir, ignore_errors=True)


class Worker:
    """In an xdist worker: stop after the current test once another worker has crashed."""

    def __init__(self, flag: Path) -> None:
        self._flag = flag

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_protocol(self, item: pytest.Item) -> Generator[None, None, None]:
        yield
        if self._flag.exists():
            with contextlib.suppress(OSError):
                item.session.shouldstop = self._flag.read_text() or "a worker crashed"


def configure(config: pytest.Config) -> None:
    """Register the side of this process: a worker, or the process that reports."""
    workerinput = getattr(config, "workerinput", None)
    if workerinput is None:
        config.pluginmanager.register(Controller(config), "egc-worker-crash")
    elif FLAG_KEY in workerinput:
        config.pluginmanager.register(Worker(Path(workerinput[FLAG_KEY])), "egc-worker-crash")
