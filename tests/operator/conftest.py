"""Fixtures of the operator tests."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
import zenoh
from egc_common.transport import ZenohOptions, open_session


@pytest.fixture
def session() -> Iterator[zenoh.Session]:
    """One in-process Zenoh session (no network): the node and the test's robot share it."""
    s = open_session(ZenohOptions())
    yield s
    s.close()
