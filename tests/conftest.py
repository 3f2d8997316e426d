"""Hypothesis profiles: CI is derandomized (the same examples every run, so a red build means a
change, not a lucky draw); ``HYPOTHESIS_PROFILE=deep`` explores far more, with fresh randomness.
The whole run stops within ``EGC_SUITE_BUDGET_S`` when that is set (``tests/suite_budget.py``)."""

from __future__ import annotations

import os

import pytest
from hypothesis import settings

from tests import suite_budget

settings.register_profile("ci", derandomize=True, deadline=None)
settings.register_profile("deep", max_examples=3000, deadline=None)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


def pytest_configure(config: pytest.Config) -> None:
    suite_budget.configure(config)
