"""Hypothesis profiles: CI is derandomized (the same examples every run, so a red build means a
change, not a lucky draw); ``HYPOTHESIS_PROFILE=deep`` explores far more, with fresh randomness.
The whole run stops within ``EGC_SUITE_BUDGET_S`` when that is set (``tests/suite_budget.py``),
and soon after a pytest-xdist worker crashes (``tests/worker_crash.py``).
Every process the suite starts keeps its compiled bytecode (``_children_keep_their_bytecode``)."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import pytest
from hypothesis import settings

from tests import suite_budget, worker_crash


def _children_keep_their_bytecode() -> None:
    """With ``PYTHONDONTWRITEBYTECODE`` set (as on the shared machines and in CI) every process
    the suite started (robots, operators, routers, the xdist workers) compiled every module it
    imported from source, every time: 37 % of a robot's start-up (0.73 s -> 0.46 s of CPU with
    the bytecode kept). A user's installed ``egc-teleop`` keeps its bytecode, so the children
    here keep theirs too, under ``PYTHONPYCACHEPREFIX`` (nothing is written next to the
    sources). Set here, in this process's environment, before any child starts, every child
    inherits it, in ``make test`` and a bare ``pytest`` alike. What runs is the same code: a
    .pyc is used only while its source's modification time and size match."""
    if os.environ.pop("PYTHONDONTWRITEBYTECODE", None) is not None:
        pycache = Path(tempfile.gettempdir()) / f"egc-teleop-pycache-{os.getuid()}"
        os.environ.setdefault("PYTHONPYCACHEPREFIX", str(pycache))


_children_keep_their_bytecode()

settings.register_profile("ci", derandomize=True, deadline=None)
settings.register_profile("deep", max_examples=3000, deadline=None)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


def _same_examples_whatever_was_imported() -> None:
    """Derandomized is not yet deterministic: Hypothesis (6.1xx) also draws constants found in
    the source of every local module loaded so far, so a test's examples depended on what else
    its xdist worker had imported before it (a cbf property test failed in one whole-suite run
    and passed alone). Under ``ci`` no module's constants are drawn; ``deep`` keeps them."""
    from hypothesis.internal.conjecture import providers

    empty = getattr(providers, "_local_constants", None)
    if hasattr(providers, "_get_local_constants") and empty is not None:
        providers._get_local_constants = lambda: empty  # type: ignore[attr-defined]


if os.environ.get("HYPOTHESIS_PROFILE", "ci") == "ci":
    _same_examples_whatever_was_imported()


def pytest_configure(config: pytest.Config) -> None:
    suite_budget.configure(config)
    worker_crash.configure(config)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The longest tests (marked ``browser`` or ``slow``) first, each group in its collected
    order: with ``--dist worksteal`` the run then ends on short tests that both workers share,
    not on one worker finishing a minute-long test while the other waits (the two screenshot
    tests, collected last, made that tail)."""
    items.sort(
        key=lambda item: (
            0 if item.get_closest_marker("browser") else 1 if item.get_closest_marker("slow") else 2
        )
    )
