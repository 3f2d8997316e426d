"""Fixtures for the integration tests: a free port, child processes, the observer."""

from __future__ import annotations

import pytest
from egc_common.transport import free_tcp_port

from tests.integration.harness import Observer, Processes


@pytest.fixture
def port() -> int:
    return free_tcp_port()


@pytest.fixture
def procs(tmp_path):
    group = Processes(tmp_path)
    try:
        yield group
    finally:
        group.cleanup()


@pytest.fixture
def observer(port, procs):
    """The test's Zenoh peer; depends on ``procs`` so it closes before the processes die."""
    obs = Observer(port)
    try:
        yield obs
    finally:
        obs.close()
