"""Fixtures for the operator view and black box tests."""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import replace
from typing import Any

import numpy as np
import pytest
import rerun as rr
from egc_common.messages import Telemetry


@pytest.fixture(autouse=True)
def strict_rerun() -> Iterator[None]:
    """Make Rerun raise on a bad log call instead of printing a warning."""
    before = rr.strict_mode()
    rr.set_strict_mode(True)
    yield
    rr.set_strict_mode(before)


BASE = Telemetry(
    seq=1,
    stamp_ns=2_000_000_000,
    state="DRIVING",
    mode="shared",
    v_ref=0.14,
    w_ref=0.1,
    v_cmd=0.1,
    w_cmd=0.2,
    w_si=0.8,
    region="conditional",
    side="left",
    limiter="egc",
    igc=(0.5, 0.05, 0.3),
    agc=(0.45, 0.2, 0.35),
    egc=(0.48, 0.12, 0.5),
    r_rc=0.5,
    scan_xy=np.array([[1.0, 0.5], [1.0, -0.5], [2.0, 0.0]], np.float32),
    pose=(1.0, 2.0, 0.5),
    cmd_age_ms=20.0,
    scan_age_ms=30.0,
    operator="op1",
    profile="pioneer3dx",
    rejected=0,
    cycle=1,
)


def telemetry(i: int, **overrides: Any) -> Telemetry:
    """Cycle ``i`` of a synthetic run: 50 ms cycles, a pose moving 5 cm per cycle."""
    values: dict[str, Any] = {
        "seq": i,
        "cycle": i,
        "stamp_ns": BASE.stamp_ns + i * 50_000_000,
        "v_ref": 0.14,
        "v_cmd": 0.14 * math.cos(i / 10.0) ** 2,
        "w_cmd": 0.3 * math.sin(i / 10.0),
        "pose": (0.05 * i, 0.0, 0.0),
        "scan_xy": np.array([[1.0 + 0.01 * i, 0.5], [1.0, -0.5], [2.0, 0.0]], np.float32),
    }
    values.update(overrides)
    return replace(BASE, **values)
