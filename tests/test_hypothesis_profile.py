"""The ``ci`` Hypothesis profile gives every test the same examples in every run (tests/conftest.py)."""

from __future__ import annotations

import os

import pytest


@pytest.mark.skipif(
    os.environ.get("HYPOTHESIS_PROFILE", "ci") != "ci", reason="only the ci profile pins examples"
)
def test_no_module_constants_are_drawn_under_ci() -> None:
    """Hypothesis draws constants from the local modules loaded so far; under ``ci`` it finds
    none, however many this worker has imported (should Hypothesis move that machinery, this
    fails and conftest's patch needs a new home)."""
    import egc_robot.filters.cbf  # noqa: F401  (a local module with many float constants)
    from hypothesis.internal.conjecture import providers

    constants = providers._get_local_constants()
    assert len(constants) == 0
