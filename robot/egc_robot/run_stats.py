"""Run statistics the robot reports when it stops (the demo's summary), pure and clock-free.

- distance: path length integrated from odometry poses;
- interventions: control cycles in which the filter (EGC or the footprint sweep) changed the
  operator's command, as ``egc-teleop episode`` counts them; ``intervention_onsets`` counts the
  stretches of such cycles (rising edges);
- collisions: rising edges of the driver's ``collided`` flag;
- command latency: arrival on the robot minus the operator's stamp (the operator's estimate of
  the robot clock, DESIGN 7), for every accepted synchronised command;
- loop delay tau and the operator's view age while driving (percentiles, DESIGN 9);
- time by state and limiter, from the telemetry stamps (cycles are not evenly spaced: an accepted
  command also runs one): ``hold_s`` and ``hold_events`` (entries into HOLD), ``latency_limited_s``
  (the latency governor capped the speed, DESIGN 9), ``first_drive_ns``/``last_stamp_ns``.
"""

from __future__ import annotations

import math
from collections import Counter
from typing import Any

import numpy as np
from egc_common.messages import Odometry, Telemetry

from egc_robot.pipeline import INTERVENING_NAMES

_MAX_LATENCIES = 1_000_000


class RunStats:
    def __init__(self) -> None:
        self.distance_m = 0.0
        self.interventions = 0
        self.intervention_onsets = 0
        self.collisions = 0
        self.cycles = 0
        self.states: Counter[str] = Counter()
        self._latencies_ms: list[float] = []
        self._pose: tuple[float, float] | None = None
        self._collided = False
        self._limiting = False
        self.seconds_by_state: dict[str, float] = {}
        self.hold_events = 0
        self.latency_limited_s = 0.0
        self._previous: Telemetry | None = None
        self._loop_delay_ms: list[float] = []
        self._view_age_ms: list[float] = []

    def on_cycle(self, telemetry: Telemetry) -> None:
        self.cycles += 1
        self.states[telemetry.state] += 1
        previous = self._previous
        if previous is not None and telemetry.stamp_ns >= previous.stamp_ns:
            dt_s = (telemetry.stamp_ns - previous.stamp_ns) / 1e9
            self.seconds_by_state[previous.state] = (
                self.seconds_by_state.get(previous.state, 0.0) + dt_s
            )
            if previous.limiter == "latency":
                self.latency_limited_s += dt_s
        if telemetry.state == "HOLD" and (previous is None or previous.state != "HOLD"):
            self.hold_events += 1
        self._previous = telemetry
        if telemetry.state == "DRIVING" and len(self._loop_delay_ms) < _MAX_LATENCIES:
            if telemetry.loop_delay_ms is not None:
                self._loop_delay_ms.append(telemetry.loop_delay_ms)
            if telemetry.view_age_ms is not None:
                self._view_age_ms.append(telemetry.view_age_ms)
        limiting = telemetry.limiter in INTERVENING_NAMES
        if limiting:
            self.interventions += 1
            if not self._limiting:
                self.intervention_onsets += 1
        self._limiting = limiting

    def on_odometry(self, odometry: Odometry) -> None:
        if self._pose is not None:
            self.distance_m += math.hypot(
                odometry.x_m - self._pose[0], odometry.y_m - self._pose[1]
            )
        self._pose = (odometry.x_m, odometry.y_m)
        if odometry.collided and not self._collided:
            self.collisions += 1
        self._collided = odometry.collided

    def on_latency(self, latency_ns: int) -> None:
        if len(self._latencies_ms) < _MAX_LATENCIES:
            self._latencies_ms.append(latency_ns / 1e6)

    def summary(self) -> dict[str, Any]:
        latency = _percentiles(self._latencies_ms)
        return {
            "distance_m": round(self.distance_m, 3),
            "interventions": self.interventions,
            "intervention_onsets": self.intervention_onsets,
            "collisions": self.collisions,
            "cycles": self.cycles,
            "cycles_by_state": dict(self.states),
            "seconds_by_state": {k: round(v, 3) for k, v in self.seconds_by_state.items()},
            "hold_s": round(self.seconds_by_state.get("HOLD", 0.0), 3),
            "hold_events": self.hold_events,
            "latency_limited_s": round(self.latency_limited_s, 3),
            "command_latency": latency,
            "loop_delay_ms": _percentiles(self._loop_delay_ms),
            "view_age_ms": _percentiles(self._view_age_ms),
        }


def _percentiles(values: list[float]) -> dict[str, float | int | None]:
    arr = np.asarray(values, dtype=np.float64)
    out: dict[str, float | int | None] = {"n": int(arr.size)}
    for name, q in (("p50", 50), ("p90", 90), ("p99", 99), ("max", 100)):
        out[f"{name}_ms"] = float(np.percentile(arr, q)) if arr.size else None
    return out
