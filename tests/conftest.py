"""Hypothesis profiles: CI is derandomized (the same examples every run, so a red build means a
change, not a lucky draw); ``HYPOTHESIS_PROFILE=deep`` explores far more, with fresh randomness."""

from __future__ import annotations

import os

from hypothesis import settings

settings.register_profile("ci", derandomize=True, deadline=None)
settings.register_profile("deep", max_examples=3000, deadline=None)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))
