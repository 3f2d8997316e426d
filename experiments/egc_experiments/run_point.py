"""One point of an experiment grid and the keys of its result line (DESIGN 10, pinned keys).

Both experiment modes take a ``RunPoint`` and return a dict with at least ``RESULT_KEYS``:
``simulated`` (one process, simulated clock) and ``emulated`` (real processes over Zenoh through
``egc-teleop link``). The two must agree within the tolerances their agreement test states.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any, Final

TRANSPORTS: Final = ("tcp", "udp")
MODES: Final = ("direct", "shared")

# DESIGN 10: every line of runs.jsonl has at least these keys.
RESULT_KEYS: Final = (
    "world",
    "operator",
    "filter",
    "mode",
    "transport",
    "delay_ms",
    "jitter_ms",
    "loss",
    "burst",
    "seed",
    "outcome",
    "reached",
    "collided",
    "time_s",
    "path_m",
    "min_clearance_m",
    "mean_speed_mps",
    "hold_s",
    "hold_events",
    "interventions",
    "cmd_age_p50_ms",
    "cmd_age_p99_ms",
    "stale_rejected",
)


@dataclass(frozen=True, slots=True)
class RunPoint:
    """Everything that defines one run; ``key()`` identifies it in ``runs.jsonl`` (resume).

    ``loss`` is a percentage (0-100) of packets lost; ``burst`` the mean burst length of
    Gilbert-Elliott loss (0 or 1: independent losses). ``outages`` are (start_s, duration_s).
    ``link_aware`` switches the robot's link-aware driving (DESIGN 8 resume, DESIGN 9 governor,
    per-mode command age) on or off, so that the sweep can compare both;
    ``latency_turn_cap`` false leaves the governor's turn-rate cap out (the speed cap alone).
    ``rate_kbps``: the link's rate limit in each direction, kbit/s, with the relay's deep
    buffer behind it (DESIGN 10 ``rate=``, 12); 0: none.
    """

    world: str
    operator: str
    filter: str = "egc"
    mode: str = "shared"
    transport: str = "tcp"
    delay_ms: float = 0.0
    jitter_ms: float = 0.0
    dist: str = "normal"
    loss: float = 0.0
    burst: float = 0.0
    outages: tuple[tuple[float, float], ...] = ()
    rate_kbps: float = 0.0
    seed: int = 0
    link_aware: bool = True
    latency_turn_cap: bool = True
    profile: str = "pioneer3dx"
    start: tuple[float, float, float] | None = None
    goal: tuple[float, float] | None = None
    max_time_s: float = 60.0
    stall_time_s: float = 30.0  # no 0.1 m of progress for this long: the run ends "stalled"
    extra: dict[str, Any] = field(default_factory=dict, compare=False, hash=False)

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ValueError(f"mode must be one of {', '.join(MODES)}, got {self.mode!r}")
        if self.transport not in TRANSPORTS:
            raise ValueError(
                f"transport must be one of {', '.join(TRANSPORTS)}, got {self.transport!r}"
            )
        for name in (
            "delay_ms",
            "jitter_ms",
            "loss",
            "burst",
            "rate_kbps",
            "max_time_s",
            "stall_time_s",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
        if self.loss > 100:
            raise ValueError(f"loss is a percentage in [0, 100], got {self.loss}")

    def key(self) -> str:
        """A stable identity of the run (the resume key)."""
        d = asdict(self)
        d.pop("extra")
        if d["latency_turn_cap"]:  # the default: keys of runs made before it existed still match
            d.pop("latency_turn_cap")
        if not d["rate_kbps"]:  # likewise
            d.pop("rate_kbps")
        return repr(sorted(d.items()))

    def identity(self) -> dict[str, Any]:
        """The point's own keys of a result line (the first ten of ``RESULT_KEYS``)."""
        return {
            "world": self.world,
            "operator": self.operator,
            "filter": self.filter,
            "mode": self.mode,
            "transport": self.transport,
            "delay_ms": self.delay_ms,
            "jitter_ms": self.jitter_ms,
            "loss": self.loss,
            "burst": self.burst,
            "seed": self.seed,
        }

    def link_spec(self) -> str:
        """The SPEC string of ``egc-teleop link`` for this point, one direction (DESIGN 10)."""
        parts = [f"delay={self.delay_ms:g}"]
        if self.jitter_ms:
            parts += [f"jitter={self.jitter_ms:g}", f"dist={self.dist}"]
        if self.loss:
            parts.append(f"loss={self.loss:g}")
            if self.burst > 1:
                parts.append(f"burst={self.burst:g}")
        if self.rate_kbps:
            parts.append(f"rate={self.rate_kbps:g}")
        parts += [f"outage={s:g}+{d:g}" for s, d in self.outages]
        return ",".join(parts)
