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
  (the latency governor capped the speed, DESIGN 9), ``first_drive_ns``/``last_stamp_ns``;
- the view plane (DESIGN 12, pinned keys): ``downlink_kbps`` ``{"p50", "max"}`` of what the robot
  sent per second (telemetry and camera; the first second of the run left out, the sum of a
  sliding one-second window sampled once a second), ``camera_age_ms`` like ``view_age_ms`` from
  the operators' reports (``{"n", "p50_ms", ...}``; n 0 without a camera), ``telemetry_sent``
  and ``telemetry_bytes_mean`` (bytes a message), ``operator_lost`` (liveliness of the operator
  in control lost: the session was lost, DESIGN 8); ``view_timeline``: per second of the robot's
  monotonic clock (``t_s``, the same clock as every process's on this machine), the largest
  ``view_age_ms`` reported while driving and its median (``view_age_p50_ms``: the telemetry
  period's sawtooth is in the largest), the view plane's kbit/s, the budget (``budget_kbps``),
  the camera's frames sent (``cam_frames``), the smallest ``camera_age_ms`` reported (the
  newest frame's age at best) and the largest command latency (``cmd_age_ms``) in that second
  (at most an hour of it): how the budget followed a link that changed (DESIGN 12);
- the fixed-rate loop's timing: ``loop_period_ms`` and ``loop_late_ms`` (percentiles of how
  late each fixed-rate cycle started after its deadline, waiting for the node's lock
  included), and ``loop_overrun_p99`` (``loop_late_ms`` p99 over the period: above 0.5 the
  loop missed its period by more than half in more than 1 % of its cycles; ``bench fleet``).

Memory is fixed when the robot starts, however long it runs: each series keeps at most
``SERIES_CAP`` samples in a buffer allocated (and touched) up front (``_Series``: every value
while it fits, then every other one, evenly in time), with its count and maximum exact; the
timeline is a preallocated table of an hour of seconds. A soak with lists that grew with every
command grew the robot by 34 MB an hour; series that grew to a 100,000-sample cap and a
timeline of per-second dicts, by 6-7 MB in its first hour (issue 31).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable
from typing import Any, Protocol

import numpy as np
from egc_common.messages import Odometry

from egc_robot.pipeline import INTERVENING_NAMES

_MAX_TIMELINE_S = 3600
_TIMELINE_LEAD_S = 2  # seconds kept before the first one seen: sources' stamps interleave
_TIMELINE_KEYS = (
    "view_age_ms",
    "view_age_p50_ms",
    "kbps",
    "budget_kbps",
    "cam_frames",
    "camera_age_ms",
    "cmd_age_ms",
)
_COLUMN = {key: i for i, key in enumerate(_TIMELINE_KEYS)}
# Samples kept per series: 128 kB each; 5.5 min of 50 Hz commands exact, then >= 8,192 samples
# evenly spread over the run (a p99 from 80 samples above it at the least).
SERIES_CAP = 16_384


class CycleRecord(Protocol):
    """What ``RunStats.on_cycle`` reads of a cycle: a ``Telemetry`` or the controller's
    ``CycleFacts`` (the same names)."""

    @property
    def stamp_ns(self) -> int: ...
    @property
    def state(self) -> str: ...
    @property
    def limiter(self) -> str: ...
    @property
    def loop_delay_ms(self) -> float | None: ...
    @property
    def view_age_ms(self) -> float | None: ...


class _Series:
    """Samples for percentiles in bounded memory: all of them up to ``cap``; past it, every
    other kept sample is dropped and only every 2nd (then 4th, ...) new one is kept, so the
    kept ones stay evenly spread over the run. ``n`` and ``max`` are exact."""

    def __init__(self, cap: int = SERIES_CAP) -> None:
        self._cap = max(2, cap)
        self._buf = np.full(self._cap, np.nan)  # written now: the pages are resident from the start
        self._len = 0
        self._stride = 1
        self._skipped = 0
        self.n = 0
        self.max = -math.inf

    def add(self, value: float) -> None:
        self.n += 1
        self.max = max(self.max, value)
        self._skipped += 1
        if self._skipped < self._stride:
            return
        self._skipped = 0
        if self._len == self._cap:
            kept = self._buf[: self._len : 2]
            self._len = kept.size
            self._buf[: self._len] = kept
            self._stride *= 2
        self._buf[self._len] = value
        self._len += 1

    @property
    def values(self) -> np.ndarray:
        return self._buf[: self._len]


class _Timeline:
    """``view_timeline``'s table: a row per second of the robot's clock from just before the
    first one seen, for ``_MAX_TIMELINE_S`` seconds, a column per key; NaN where nothing was
    recorded. Allocated (and touched) up front, so an hour of it costs no memory later."""

    def __init__(self) -> None:
        self._rows = np.full((_TIMELINE_LEAD_S + _MAX_TIMELINE_S, len(_TIMELINE_KEYS)), np.nan)
        self._first_s: int | None = None

    def put(
        self,
        now_ns: int,
        key: str,
        value: float,
        combine: Callable[[float, float], float] | None = None,
    ) -> bool:
        """Record ``value`` under ``key`` in ``now_ns``'s second, combined with what is there
        (``max``, ``min``; None: replace); False when that second is outside the table."""
        second = now_ns // 1_000_000_000
        if self._first_s is None:
            self._first_s = second - _TIMELINE_LEAD_S
        row = second - self._first_s
        if not 0 <= row < self._rows.shape[0]:
            return False
        column = _COLUMN[key]
        old = float(self._rows[row, column])
        self._rows[row, column] = value if combine is None or old != old else combine(old, value)
        return True

    def entries(self) -> list[dict[str, float]]:
        """The seconds with anything recorded, in order: ``{"t_s": second, key: value, ...}``."""
        if self._first_s is None:
            return []
        out: list[dict[str, float]] = []
        for row in np.flatnonzero(~np.isnan(self._rows).all(axis=1)):
            entry: dict[str, float] = {"t_s": int(self._first_s + row)}
            for key, value in zip(_TIMELINE_KEYS, self._rows[row].tolist(), strict=True):
                if value == value:
                    entry[key] = int(value) if key == "cam_frames" else value
            out.append(entry)
        return out


class RunStats:
    def __init__(self) -> None:
        self.distance_m = 0.0
        self.interventions = 0
        self.intervention_onsets = 0
        self.collisions = 0
        self.cycles = 0
        self.states: Counter[str] = Counter()
        self._latencies_ms = _Series()
        self._pose: tuple[float, float] | None = None
        self._collided = False
        self._limiting = False
        self.seconds_by_state: dict[str, float] = {}
        self.hold_events = 0
        self.latency_limited_s = 0.0
        self._previous: CycleRecord | None = None
        self._loop_delay_ms = _Series()
        self._view_age_ms = _Series()
        self._camera_age_ms = _Series()
        self._downlink_kbps = _Series()
        self._rate_second: int | None = None
        self._camera_frames: int | None = None
        self._ages_second: int | None = None
        self._ages: list[float] = []
        self.telemetry_sent = 0
        self.telemetry_bytes = 0
        self.operator_lost = 0
        self._timeline = _Timeline()
        self._loop_late_ms = _Series()
        self._loop_period_ns: int | None = None

    def on_cycle(self, telemetry: CycleRecord) -> None:
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
        if telemetry.state == "DRIVING":
            if telemetry.loop_delay_ms is not None:
                self._loop_delay_ms.add(telemetry.loop_delay_ms)
            if telemetry.view_age_ms is not None:
                self._view_age_ms.add(telemetry.view_age_ms)
                if self._timeline.put(
                    telemetry.stamp_ns, "view_age_ms", telemetry.view_age_ms, max
                ):
                    self._second_ages(telemetry.stamp_ns).append(telemetry.view_age_ms)
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

    def on_camera_age(self, age_ms: float, now_ns: int | None = None) -> None:
        """An accepted command's ``camera_age_ms`` (DESIGN 12), received at ``now_ns``."""
        self._camera_age_ms.add(float(age_ms))
        if now_ns is not None:
            self._timeline.put(now_ns, "camera_age_ms", float(age_ms), min)

    def on_view_rate(
        self,
        now_ns: int,
        kbps: float,
        budget_kbps: float | None = None,
        camera_frames: int | None = None,
    ) -> None:
        """The view plane's kbit/s over the last second, sampled once a second (the first second,
        a partial window, is left out); the budget then and the camera's frames sent so far."""
        second = now_ns // 1_000_000_000
        if self._rate_second is None:
            self._rate_second = second + 1
            self._camera_frames = camera_frames
        elif second > self._rate_second:
            self._rate_second = second
            self._downlink_kbps.add(kbps)
            if self._timeline.put(now_ns, "kbps", round(kbps, 1)):
                if budget_kbps is not None:
                    self._timeline.put(now_ns, "budget_kbps", round(budget_kbps, 1))
                if camera_frames is not None and self._camera_frames is not None:
                    self._timeline.put(now_ns, "cam_frames", camera_frames - self._camera_frames)
            self._camera_frames = camera_frames

    def _second_ages(self, now_ns: int) -> list[float]:
        """This second's view ages; the last second's median goes to its timeline entry."""
        second = now_ns // 1_000_000_000
        if self._ages_second != second:
            self._flush_ages()
            self._ages_second = second
        return self._ages

    def _flush_ages(self) -> None:
        if self._ages_second is not None and self._ages:
            median = float(np.median(self._ages))
            self._timeline.put(self._ages_second * 1_000_000_000, "view_age_p50_ms", median)
        self._ages.clear()

    def on_telemetry_sent(self, nbytes: int) -> None:
        self.telemetry_sent += 1
        self.telemetry_bytes += nbytes

    def on_operator_lost(self) -> None:
        self.operator_lost += 1

    def on_loop_start(self, late_ns: int, period_ns: int) -> None:
        """A fixed-rate cycle started ``late_ns`` after its deadline (period ``period_ns``)."""
        self._loop_period_ns = period_ns
        self._loop_late_ms.add(max(0, late_ns) / 1e6)

    def on_latency(self, latency_ns: int, now_ns: int | None = None) -> None:
        """An accepted command's latency (its age on arrival), received at ``now_ns``."""
        self._latencies_ms.add(latency_ns / 1e6)
        if now_ns is not None:
            self._timeline.put(now_ns, "cmd_age_ms", round(latency_ns / 1e6, 1), max)

    def summary(self) -> dict[str, Any]:
        self._flush_ages()
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
            "camera_age_ms": _percentiles(self._camera_age_ms),
            "downlink_kbps": _rate_summary(self._downlink_kbps),
            "telemetry_sent": self.telemetry_sent,
            "telemetry_bytes_mean": round(self.telemetry_bytes / self.telemetry_sent, 1)
            if self.telemetry_sent
            else None,
            "operator_lost": self.operator_lost,
            **self._loop_summary(),
            "view_timeline": self._timeline.entries(),
        }

    def _loop_summary(self) -> dict[str, Any]:
        late = _percentiles(self._loop_late_ms)
        period_ms = None if self._loop_period_ns is None else self._loop_period_ns / 1e6
        p99 = late["p99_ms"]
        overrun = None if p99 is None or not period_ms else round(float(p99) / period_ms, 3)
        return {"loop_period_ms": period_ms, "loop_late_ms": late, "loop_overrun_p99": overrun}


def _rate_summary(series: _Series) -> dict[str, float | None]:
    """DESIGN 12's ``downlink_kbps``: ``{"p50", "max"}`` kbit/s (None before a whole second)."""
    if not series.n:
        return {"p50": None, "max": None}
    p50 = float(np.percentile(series.values, 50))
    return {"p50": round(p50, 1), "max": round(series.max, 1)}


def _percentiles(series: _Series) -> dict[str, float | int | None]:
    arr = series.values
    out: dict[str, float | int | None] = {"n": series.n}
    for name, q in (("p50", 50), ("p90", 90), ("p99", 99)):
        out[f"{name}_ms"] = float(np.percentile(arr, q)) if arr.size else None
    out["max_ms"] = series.max if series.n else None
    return out
