"""The link model of ``egc-teleop link`` (DESIGN 10): delay, jitter, loss, bursts, rate, outages.

Pure and seeded: no clock is read and no socket is touched. Time is passed in as float seconds
since the link started (the origin of outages, phases and traces). ``LinkModel.transit`` decides,
for one packet (a TCP chunk or a UDP datagram) of one direction, when it arrives or that it is
dropped. The same seed and the same calls give the same decisions.

A packet sent at ``t`` goes through, in this order:

1. **Outage** (from the spec active at ``t``): on UDP it is dropped; on TCP it leaves when the
   outage ends, as a retransmission would.
2. **Loss** (UDP only): independent (Bernoulli) at ``loss_pct``, or Gilbert-Elliott bursts when
   ``burst`` > 1: a two-state chain per packet, the bad state losing everything, with mean burst
   length ``burst`` and stationary loss ``loss_pct``.
3. **Rate** (``rate_kbitps`` > 0): a serialization queue; a packet starts when the link is free
   and takes ``8 * size / rate`` seconds. UDP drops a packet that finds ``UDP_QUEUE_LIMIT``
   packets queued (netem's default limit); TCP never drops.
4. **Delay**: ``delay_ms`` plus a jitter with standard deviation ``jitter_ms`` from ``dist``,
   floored at 0 (a packet never arrives before it left). ``normal``: Gaussian; ``uniform``:
   uniform of that standard deviation (half-width ``jitter * sqrt(3)``); ``pareto``: a Pareto
   tail of shape 3 (as netem's pareto table) shifted and scaled to mean 0 and that standard
   deviation, so that most packets arrive a little early and a few very late. The floor at 0
   raises the mean when the jitter is large against the delay.
5. **Order**: a TCP link (``ordered``) and a UDP link without ``reorder`` never deliver out of
   order: a late packet holds back the ones behind it. With ``reorder`` each datagram arrives at
   its own time.
"""

from __future__ import annotations

import bisect
import csv
import hashlib
import io
import itertools
import math
import random
import tomllib
from collections import deque
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Final

DISTS: Final = ("normal", "uniform", "pareto")
SPEC_KEYS: Final = ("delay", "jitter", "dist", "loss", "burst", "rate", "outage", "reorder")
PARETO_ALPHA: Final = 3.0
_PARETO_MEAN: Final = PARETO_ALPHA / (PARETO_ALPHA - 1.0)
_PARETO_STD: Final = math.sqrt(PARETO_ALPHA / ((PARETO_ALPHA - 1.0) ** 2 * (PARETO_ALPHA - 2.0)))
UDP_QUEUE_LIMIT: Final = 1000
# Bounds no link study reaches: beyond them a value is a typo (delay=1e15) and the relay would
# hold every packet for ever (or overflow its timers) and forward nothing, silently.
MAX_DELAY_MS: Final = 600_000.0  # delay and jitter: 10 minutes
MIN_RATE_KBITPS: Final = 1.0  # a rate limit below 1 kbit/s (rate=0 is no limit)
TCP_LOSS_MESSAGE: Final = (
    "loss is not possible on a TCP link: a TCP connection retransmits what is lost; "
    "use udp/ endpoints to emulate loss, or outage= for a link that stops"
)


class SpecError(ValueError):
    """A bad SPEC, schedule, trace or scenario; the message is one line meant for the user."""


def _check_number(name: str, value: float) -> None:
    if not (isinstance(value, int | float) and math.isfinite(value) and value >= 0):
        raise SpecError(f"{name} must be a finite number >= 0, got {value!r}")


def _check_size(key: str, value: float, text: str, label: str = "") -> None:
    """SpecError unless ``value`` (of SPEC key ``key``, written ``text``; ``label``: its name
    where it is written, e.g. a trace column) is within the bounds a link study can use: delay
    and jitter at most ``MAX_DELAY_MS``, a rate of 0 (no limit) or at least ``MIN_RATE_KBITPS``."""
    if key in ("delay", "jitter") and value > MAX_DELAY_MS:
        raise SpecError(
            f"{label or key}={text.strip()} ms is more than {MAX_DELAY_MS:g} ms (10 minutes), "
            "beyond any link to study"
        )
    if key == "rate" and 0 < value < MIN_RATE_KBITPS:
        raise SpecError(
            f"rate={text.strip()} kbit/s is below {MIN_RATE_KBITPS:g} kbit/s, the slowest rate "
            "(leave rate out, or rate=0, for no limit)"
        )


@dataclass(frozen=True, slots=True)
class LinkSpec:
    """One direction's link settings (the SPEC of DESIGN 10); the default is a perfect link.

    ``delay_ms`` mean one-way delay; ``jitter_ms`` its standard deviation, drawn from ``dist``;
    ``loss_pct`` mean loss in percent; ``burst`` mean loss burst length (0 or 1: independent
    losses); ``rate_kbitps`` bottleneck rate (0: unlimited); ``outages`` ``(start_s, duration_s)``
    in seconds since the link started; ``reorder`` lets UDP datagrams overtake each other.
    """

    delay_ms: float = 0.0
    jitter_ms: float = 0.0
    dist: str = "normal"
    loss_pct: float = 0.0
    burst: float = 0.0
    rate_kbitps: float = 0.0
    outages: tuple[tuple[float, float], ...] = ()
    reorder: bool = False

    def __post_init__(self) -> None:
        for name in ("delay_ms", "jitter_ms", "loss_pct", "burst", "rate_kbitps"):
            _check_number(name, getattr(self, name))
        for key, value in (
            ("delay", self.delay_ms),
            ("jitter", self.jitter_ms),
            ("rate", self.rate_kbitps),
        ):
            _check_size(key, value, f"{value:g}")
        if self.dist not in DISTS:
            raise SpecError(f"dist must be one of {', '.join(DISTS)}, got {self.dist!r}")
        if self.loss_pct > 100:
            raise SpecError(f"loss is a percentage in [0, 100], got {self.loss_pct:g}")
        if 0 < self.burst < 1:
            raise SpecError(f"burst is a mean burst length: 0, 1 or more, got {self.burst:g}")
        if self.burst and not self.loss_pct:
            raise SpecError("burst without loss: burst=N shapes the losses of loss=PERCENT")
        if self.burst > 1 and self.loss_pct < 100:
            loss = self.loss_pct / 100.0
            shortest = loss / (1.0 - loss)
            if self.burst < shortest:
                raise SpecError(
                    f"burst={self.burst:g} is too short for loss={self.loss_pct:g}%: "
                    f"at that loss the mean burst is at least {shortest:.3g}"
                )
        ends: list[tuple[float, float]] = []
        for outage in self.outages:
            if len(outage) != 2:
                raise SpecError(f"an outage is (start_s, duration_s), got {outage!r}")
            start, duration = outage
            _check_number("outage start", start)
            _check_number("outage duration", duration)
            if duration <= 0:
                raise SpecError(f"outage duration must be > 0 s, got {duration:g}")
            ends.append((start, start + duration))
        ends.sort()
        for (_, end), (start, _) in itertools.pairwise(ends):
            if start < end:
                raise SpecError(f"outages overlap: one starts at {start:g} s before {end:g} s")
        if not isinstance(self.reorder, bool):
            raise SpecError(f"reorder must be a bool, got {self.reorder!r}")

    @property
    def perfect(self) -> bool:
        """True when this spec changes nothing (zero delay, no loss, no limit, no outage)."""
        return self == LinkSpec(reorder=self.reorder, dist=self.dist)

    def outage_end(self, t_s: float) -> float | None:
        """The end of the outage that covers ``t_s`` (start inclusive, end exclusive), or None."""
        for start, duration in self.outages:
            if start <= t_s < start + duration:
                return start + duration
        return None

    def to_text(self) -> str:
        """This spec as a SPEC string; ``parse_spec(spec.to_text()) == spec``."""
        parts: list[str] = []
        if self.delay_ms:
            parts.append(f"delay={self.delay_ms:g}")
        if self.jitter_ms:
            parts.append(f"jitter={self.jitter_ms:g}")
        if self.dist != "normal":
            parts.append(f"dist={self.dist}")
        if self.loss_pct:
            parts.append(f"loss={self.loss_pct:g}")
        if self.burst:
            parts.append(f"burst={self.burst:g}")
        if self.rate_kbitps:
            parts.append(f"rate={self.rate_kbitps:g}")
        parts += [f"outage={s:g}+{d:g}" for s, d in self.outages]
        if self.reorder:
            parts.append("reorder=1")
        return ",".join(parts)


PERFECT: Final = LinkSpec()


def _parse_number(key: str, text: str, suffixes: tuple[str, ...] = ()) -> float:
    raw = text.strip()
    for suffix in suffixes:
        if raw.endswith(suffix):
            raw = raw[: -len(suffix)].strip()
            break
    try:
        value = float(raw)
    except ValueError:
        raise SpecError(f"{key}={text!r} is not a number") from None
    if not math.isfinite(value):
        raise SpecError(f"{key}={text!r} is not a finite number")
    if value < 0:
        raise SpecError(f"{key}={text} must be >= 0")
    return value


def _parse_outage(text: str) -> tuple[float, float]:
    start, plus, duration = text.partition("+")
    if not plus:
        raise SpecError(f"outage={text!r} must be START_S+DURATION_S, e.g. outage=10+2")
    start_s = _parse_number("outage start", start, ("s",))
    duration_s = _parse_number("outage duration", duration, ("s",))
    if duration_s <= 0:
        raise SpecError(f"outage={text}: the duration must be > 0 s")
    return start_s, duration_s


_BOOLS: Final = {"1": True, "0": False, "true": True, "false": False, "yes": True, "no": False}


def parse_spec(text: str) -> LinkSpec:
    """Parse a SPEC (DESIGN 10): ``delay=MS,jitter=MS,dist=normal|uniform|pareto,loss=PERCENT,
    burst=N,rate=KBITPS,outage=START_S+DURATION_S,reorder=1``; every key optional, ``outage``
    repeatable. An empty string is a perfect link. Raises ``SpecError`` with one clear line."""
    if not isinstance(text, str):
        raise SpecError(f"a SPEC is a string, got {text!r}")
    if not text.strip():
        return PERFECT
    values: dict[str, Any] = {}
    outages: list[tuple[float, float]] = []
    for item in text.split(","):
        key, sep, value = item.partition("=")
        key = key.strip()
        if not item.strip():
            raise SpecError(f"empty item in SPEC {text!r} (items are separated by one comma)")
        if not sep:
            raise SpecError(f"{item.strip()!r} in SPEC is not KEY=VALUE, e.g. delay=100")
        if key not in SPEC_KEYS:
            raise SpecError(f"unknown SPEC key {key!r} (known: {', '.join(SPEC_KEYS)})")
        if key == "outage":
            outages.append(_parse_outage(value))
            continue
        if key in values:
            raise SpecError(f"{key}= given twice in SPEC {text!r}")
        if key in ("delay", "jitter"):
            values[key] = _parse_number(key, value, ("ms",))
            _check_size(key, values[key], value.strip().removesuffix("ms").strip())
        elif key == "loss":
            loss = _parse_number(key, value, ("%",))
            if loss > 100:
                raise SpecError(f"loss={value.strip()} is a percentage in [0, 100]")
            values[key] = loss
        elif key in ("burst", "rate"):
            values[key] = _parse_number(key, value)
            _check_size(key, values[key], value.strip())
        elif key == "dist":
            dist = value.strip()
            if dist not in DISTS:
                raise SpecError(f"dist={dist!r} is not one of {', '.join(DISTS)}")
            values[key] = dist
        else:  # reorder
            flag = _BOOLS.get(value.strip().lower())
            if flag is None:
                raise SpecError(f"reorder={value.strip()!r} must be 1 or 0")
            values[key] = flag
    return LinkSpec(
        delay_ms=values.get("delay", 0.0),
        jitter_ms=values.get("jitter", 0.0),
        dist=values.get("dist", "normal"),
        loss_pct=values.get("loss", 0.0),
        burst=values.get("burst", 0.0),
        rate_kbitps=values.get("rate", 0.0),
        outages=tuple(sorted(outages)),
        reorder=values.get("reorder", False),
    )


@dataclass(frozen=True, slots=True)
class Phase:
    """From ``start_s`` (seconds since the link started) on, packets sent follow ``spec``."""

    start_s: float
    spec: LinkSpec

    def __post_init__(self) -> None:
        _check_number("phase start_s", self.start_s)


@dataclass(frozen=True, slots=True)
class Schedule:
    """Timed phases, in order of ``start_s``; the phase active at a packet's send time applies.

    Before the first phase the link is perfect. A constant link is ``Schedule.constant(spec)``.
    """

    phases: tuple[Phase, ...]
    _starts: tuple[float, ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not self.phases:
            raise SpecError("a schedule needs at least one phase")
        starts = tuple(p.start_s for p in self.phases)
        for a, b in itertools.pairwise(starts):
            if b <= a:
                raise SpecError(f"phases must start in increasing order, got {a:g} s then {b:g} s")
        object.__setattr__(self, "_starts", starts)

    @classmethod
    def constant(cls, spec: LinkSpec) -> Schedule:
        """One phase from t = 0 on."""
        return cls((Phase(0.0, spec),))

    def spec_at(self, t_s: float) -> LinkSpec:
        """The spec of the phase active at ``t_s`` (zero-order hold)."""
        i = bisect.bisect_right(self._starts, t_s) - 1
        return self.phases[i].spec if i >= 0 else PERFECT

    @property
    def has_loss(self) -> bool:
        """True when any phase loses packets (impossible on a TCP link)."""
        return any(p.spec.loss_pct > 0 for p in self.phases)

    def without_loss(self) -> Schedule:
        """The same phases with no loss and no reordering: what a TCP connection beside a lossy
        UDP path sees (its segments are retransmitted, so only delay and outages remain)."""
        return Schedule(
            tuple(
                Phase(p.start_s, replace(p.spec, loss_pct=0.0, burst=0.0, reorder=False))
                for p in self.phases
            )
        )

    def describe(self) -> str:
        """A short text: the spec for one phase, else the number of phases."""
        if len(self.phases) == 1 and self.phases[0].start_s == 0:
            return self.phases[0].spec.to_text() or "perfect"
        return f"{len(self.phases)} phases"


@dataclass(frozen=True, slots=True)
class TraceRow:
    """One trace row: from ``t_s`` on, delay ``delay_ms`` and loss ``loss_pct`` (percent)."""

    t_s: float
    delay_ms: float
    loss_pct: float


@dataclass(frozen=True, slots=True)
class Trace:
    """A recorded link, CSV ``t_s,delay_ms,loss``, replayed with zero-order hold (no
    interpolation): each row holds until the next, the last one for ever.

    ``loss`` is a percentage in [0, 100] like SPEC's ``loss=PERCENT`` (so 1 means 1 %, and a
    row of 100 drops everything until the next row). An optional ``jitter_ms`` column adds jitter.
    """

    rows: tuple[TraceRow, ...]
    jitter_ms: tuple[float, ...] = ()

    def schedule(self, base: LinkSpec = PERFECT) -> Schedule:
        """The trace as a schedule; ``base`` gives the settings a trace has no column for."""
        phases = []
        for i, row in enumerate(self.rows):
            jitter = self.jitter_ms[i] if self.jitter_ms else base.jitter_ms
            burst = base.burst if row.loss_pct > 0 else 0.0
            spec = replace(
                base, delay_ms=row.delay_ms, loss_pct=row.loss_pct, burst=burst, jitter_ms=jitter
            )
            phases.append(Phase(row.t_s, spec))
        return Schedule(tuple(phases))


def parse_trace(text: str, source: str = "trace") -> Trace:
    """Parse a trace CSV (header ``t_s,delay_ms,loss`` and optionally ``jitter_ms``; lines
    starting with ``#`` are comments). Times must increase. Raises ``SpecError``."""
    lines = [(n, line) for n, line in enumerate(text.splitlines(), 1) if line.strip()]
    lines = [(n, line) for n, line in lines if not line.lstrip().startswith("#")]
    if not lines:
        raise SpecError(f"{source}: empty trace (expected a header t_s,delay_ms,loss and rows)")
    header_no, header_line = lines[0]
    header = [h.strip() for h in next(csv.reader(io.StringIO(header_line)))]
    required = ("t_s", "delay_ms", "loss")
    missing = [h for h in required if h not in header]
    unknown = [h for h in header if h not in (*required, "jitter_ms")]
    if missing or unknown:
        raise SpecError(
            f"{source}:{header_no}: the header must be t_s,delay_ms,loss[,jitter_ms], "
            f"got {header_line.strip()!r}"
        )
    rows: list[TraceRow] = []
    jitters: list[float] = []
    for n, line in lines[1:]:
        cells = [c.strip() for c in next(csv.reader(io.StringIO(line)))]
        if len(cells) != len(header):
            raise SpecError(f"{source}:{n}: expected {len(header)} columns, got {len(cells)}")
        cell = dict(zip(header, cells, strict=True))
        try:
            t_s = _parse_number("t_s", cell["t_s"])
            delay = _parse_number("delay_ms", cell["delay_ms"])
            _check_size("delay", delay, cell["delay_ms"], "delay_ms")
            loss = _parse_number("loss", cell["loss"])
            if loss > 100:
                raise SpecError(f"loss={cell['loss']} is a percentage in [0, 100]")
            if "jitter_ms" in cell:
                jitters.append(_parse_number("jitter_ms", cell["jitter_ms"]))
                _check_size("jitter", jitters[-1], cell["jitter_ms"], "jitter_ms")
        except SpecError as exc:
            raise SpecError(f"{source}:{n}: {exc}") from None
        if rows and t_s <= rows[-1].t_s:
            raise SpecError(f"{source}:{n}: t_s must increase, {t_s:g} after {rows[-1].t_s:g}")
        rows.append(TraceRow(t_s, delay, loss))
    if not rows:
        raise SpecError(f"{source}: the trace has a header but no rows")
    return Trace(tuple(rows), tuple(jitters))


def load_trace(path: str | Path) -> Trace:
    """Read and parse a trace CSV file (the thin IO wrapper of ``parse_trace``)."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise SpecError(f"trace file {p} does not exist") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SpecError(f"cannot read trace file {p}: {exc}") from None
    return parse_trace(text, str(p))


_SCENARIO_KEYS: Final = ("phase", "trace", "up_base", "down_base")
_PHASE_KEYS: Final = ("start_s", "up", "down", "both")


def _spec_field(where: str, value: object) -> LinkSpec:
    if not isinstance(value, str):
        raise SpecError(f'{where} must be a SPEC string, e.g. "delay=100", got {value!r}')
    try:
        return parse_spec(value)
    except SpecError as exc:
        raise SpecError(f"{where}: {exc}") from None


def parse_scenario(
    data: Mapping[str, Any], source: str, read_trace: Callable[[str], Trace]
) -> tuple[Schedule, Schedule]:
    """Build ``(up, down)`` schedules from a parsed scenario TOML table (see ``load_scenario``).

    ``read_trace`` maps a trace file name of the scenario to a ``Trace`` (the only IO)."""
    unknown = [k for k in data if k not in _SCENARIO_KEYS]
    if unknown:
        raise SpecError(
            f"{source}: unknown key(s) {', '.join(unknown)} (known: {', '.join(_SCENARIO_KEYS)})"
        )
    has_phase, has_trace = "phase" in data, "trace" in data
    if has_phase == has_trace:
        raise SpecError(
            f"{source}: a scenario has either [[phase]] tables or a trace, "
            + ("not both" if has_phase else "found neither")
        )
    if has_phase:
        if "up_base" in data or "down_base" in data:
            raise SpecError(f"{source}: up_base/down_base apply to a trace, not to phases")
        phases = data["phase"]
        if not isinstance(phases, list) or not phases:
            raise SpecError(f"{source}: phase must be an array of tables: [[phase]]")
        up: list[Phase] = []
        down: list[Phase] = []
        for i, phase in enumerate(phases, 1):
            where = f"{source}: phase {i}"
            if not isinstance(phase, dict):
                raise SpecError(f"{where} is not a table")
            bad = [k for k in phase if k not in _PHASE_KEYS]
            if bad:
                raise SpecError(
                    f"{where}: unknown key(s) {', '.join(bad)} (known: {', '.join(_PHASE_KEYS)})"
                )
            start = phase.get("start_s")
            if isinstance(start, bool) or not isinstance(start, int | float):
                raise SpecError(f"{where}: start_s (seconds) is required and must be a number")
            if "both" in phase and ("up" in phase or "down" in phase):
                raise SpecError(f"{where}: give both= or up=/down=, not both")
            up_spec = _spec_field(f"{where} up", phase.get("both", phase.get("up", "")))
            down_spec = _spec_field(f"{where} down", phase.get("both", phase.get("down", "")))
            try:
                up.append(Phase(float(start), up_spec))
                down.append(Phase(float(start), down_spec))
            except SpecError as exc:
                raise SpecError(f"{where}: {exc}") from None
        try:
            return Schedule(tuple(up)), Schedule(tuple(down))
        except SpecError as exc:
            raise SpecError(f"{source}: {exc}") from None
    trace = data["trace"]
    if isinstance(trace, str):
        up_file: str | None = trace
        down_file: str | None = trace
    elif isinstance(trace, dict):
        bad = [k for k in trace if k not in ("up", "down")]
        if bad or not trace:
            raise SpecError(f'{source}: [trace] takes up = "FILE" and/or down = "FILE"')
        up_file, down_file = trace.get("up"), trace.get("down")
        for name in (up_file, down_file):
            if name is not None and not isinstance(name, str):
                raise SpecError(f"{source}: trace files are strings, got {name!r}")
    else:
        raise SpecError(f"{source}: trace is a file name or a table [trace] up=... down=...")
    bases = [_spec_field(f"{source} {k}", data.get(k, "")) for k in ("up_base", "down_base")]
    schedules = []
    for name, base in zip((up_file, down_file), bases, strict=True):
        schedules.append(
            read_trace(name).schedule(base) if name is not None else Schedule.constant(base)
        )
    return schedules[0], schedules[1]


def load_scenario(path: str | Path) -> tuple[Schedule, Schedule]:
    """Read a scenario TOML file and return the ``(up, down)`` schedules.

    Either timed phases (a direction left out of a phase is a perfect link in that phase)::

        [[phase]]
        start_s = 0
        both = "delay=50,jitter=5"        # or up = "..." and/or down = "..."
        [[phase]]
        start_s = 20
        up = "delay=300,loss=2,burst=3"
        down = "delay=300"

    or a trace replayed in both directions, or per direction (relative paths are relative to
    the scenario file; a direction without a trace gets its base spec, by default a perfect
    link), with optional base specs for the settings a trace has no column for::

        trace = "link.csv"                # or: [trace] up = "up.csv" down = "down.csv"
        up_base = "dist=pareto,reorder=1"

    Raises ``SpecError`` (one line) for a missing file, bad TOML, or a bad phase or SPEC.
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise SpecError(f"scenario file {p} does not exist") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SpecError(f"cannot read scenario file {p}: {exc}") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SpecError(f"{p}: not valid TOML: {exc}") from None

    def read(name: str) -> Trace:
        trace_path = Path(name) if Path(name).is_absolute() else p.parent / name
        return load_trace(trace_path)

    return parse_scenario(data, str(p), read)


def as_schedule(link: LinkSpec | Schedule | Trace) -> Schedule:
    """A spec (constant), a schedule (as is) or a trace (over a perfect base) as a schedule."""
    if isinstance(link, Schedule):
        return link
    if isinstance(link, LinkSpec):
        return Schedule.constant(link)
    if isinstance(link, Trace):
        return link.schedule()
    raise TypeError(f"expected LinkSpec, Schedule or Trace, got {type(link).__name__}")


def derive_seed(seed: int, label: str) -> int:
    """A seed for one part of a run (e.g. ``"up"``, ``"down"``), stable across Python versions."""
    digest = hashlib.sha256(f"{seed}/{label}".encode()).digest()
    return int.from_bytes(digest[:8], "big")


class LinkModel:
    """One direction of a link: ``transit`` gives each packet's arrival time or None (dropped).

    ``ordered`` is a TCP link: nothing may be dropped (a schedule with loss raises
    ``SpecError``), a packet sent in an outage leaves when it ends, and arrivals never decrease.
    Counters: ``sent``, ``forwarded``, and ``dropped`` by reason (``loss``, ``outage``, ``queue``).
    """

    def __init__(
        self, spec_or_schedule: LinkSpec | Schedule | Trace, seed: int, ordered: bool
    ) -> None:
        self.schedule = as_schedule(spec_or_schedule)
        self.ordered = ordered
        if ordered and self.schedule.has_loss:
            raise SpecError(TCP_LOSS_MESSAGE)
        self._delay_rng = random.Random(derive_seed(seed, "delay"))
        self._loss_rng = random.Random(derive_seed(seed, "loss"))
        self._bad: bool | None = None  # Gilbert-Elliott state, drawn at the first packet
        self._link_free_s = -math.inf
        self._queued: deque[float] = deque()  # departure times of packets in the rate queue
        self._last_arrival_s = -math.inf
        self.sent = 0
        self.forwarded = 0
        self.dropped: dict[str, int] = {"loss": 0, "outage": 0, "queue": 0}

    def backlog_s(self, t_s: float) -> float:
        """Seconds of serialization still queued at ``t_s`` behind the rate limit (0 if none)."""
        return max(0.0, self._link_free_s - t_s)

    @property
    def dropped_total(self) -> int:
        """All drops, whatever the reason."""
        return sum(self.dropped.values())

    def _lost(self, spec: LinkSpec) -> bool:
        loss = spec.loss_pct / 100.0
        rng = self._loss_rng
        if loss <= 0:
            self._bad = False
            return False
        if loss >= 1:
            self._bad = True
            return True
        if spec.burst <= 1 or self._bad is None:
            self._bad = rng.random() < loss
            return self._bad
        leave_bad = 1.0 / spec.burst
        enter_bad = loss * leave_bad / (1.0 - loss)
        self._bad = rng.random() >= leave_bad if self._bad else rng.random() < enter_bad
        return self._bad

    def _delay_s(self, spec: LinkSpec) -> float:
        if not spec.jitter_ms:
            return spec.delay_ms / 1000.0
        rng = self._delay_rng
        if spec.dist == "normal":
            z = rng.gauss(0.0, 1.0)
        elif spec.dist == "uniform":
            z = (2.0 * rng.random() - 1.0) * math.sqrt(3.0)
        else:
            x = (1.0 - rng.random()) ** (-1.0 / PARETO_ALPHA)
            z = (x - _PARETO_MEAN) / _PARETO_STD
        return max(0.0, spec.delay_ms + spec.jitter_ms * z) / 1000.0

    def transit(self, t_send_s: float, size_bytes: int) -> float | None:
        """The arrival time (s) of a packet of ``size_bytes`` sent at ``t_send_s``, or None."""
        self.sent += 1
        t = t_send_s
        spec = self.schedule.spec_at(t)
        end = spec.outage_end(t)
        if end is not None:
            if not self.ordered:
                self.dropped["outage"] += 1
                return None
            while end is not None:  # TCP: retransmitted once the link is back
                t = end
                spec = self.schedule.spec_at(t)
                end = spec.outage_end(t)
        if not self.ordered and self._lost(spec):
            self.dropped["loss"] += 1
            return None
        if spec.rate_kbitps > 0:
            queued = self._queued
            while queued and queued[0] <= t:
                queued.popleft()
            if not self.ordered and len(queued) >= UDP_QUEUE_LIMIT:
                self.dropped["queue"] += 1
                return None
            start = max(t, self._link_free_s)
            self._link_free_s = start + size_bytes * 8.0 / (spec.rate_kbitps * 1000.0)
            queued.append(self._link_free_s)
            t = self._link_free_s
        arrival = t + self._delay_s(spec)
        if self.ordered or not spec.reorder:
            arrival = max(arrival, self._last_arrival_s)
        self._last_arrival_s = max(arrival, self._last_arrival_s)
        self.forwarded += 1
        return arrival


def percentile(sorted_values: list[float], q: float) -> float:
    """The ``q``-th percentile (0-100) of sorted values, linear between ranks (numpy's default)."""
    if not sorted_values:
        raise ValueError("percentile of no values")
    pos = (len(sorted_values) - 1) * q / 100.0
    lo = math.floor(pos)
    hi = min(lo + 1, len(sorted_values) - 1)
    return sorted_values[lo] + (sorted_values[hi] - sorted_values[lo]) * (pos - lo)


@dataclass(frozen=True, slots=True)
class DirectionStats:
    """Counts and delay percentiles of one direction, from the delays actually observed (ms).

    Percentiles are None when nothing was forwarded. ``late_*`` is the relay's scheduling
    lateness (release time minus planned arrival), when measured. ``send_errors``: the sends of
    this direction the system reported as failed (``ECONNREFUSED`` after an ICMP port
    unreachable from the far end, no route to host, a full buffer); a datagram whose send failed
    at once is in neither ``forwarded`` nor ``dropped`` (the link model's losses).
    ``in_flight``: packets the link model let through that were still held (delayed, or queued
    behind a rate limit) when the relay stopped or their connection closed, so never delivered.
    So every packet a direction read is forwarded, dropped, in flight or a send refused at once
    (a TCP direction counts chunks as read; a refusal reported later by ICMP is a send error of
    a packet already forwarded).
    """

    forwarded: int
    dropped: int
    p50_ms: float | None = None
    p90_ms: float | None = None
    p99_ms: float | None = None
    max_ms: float | None = None
    late_p50_ms: float | None = None
    late_p99_ms: float | None = None
    late_max_ms: float | None = None
    send_errors: int = 0
    in_flight: int = 0
    bytes: int = 0  # payload bytes forwarded

    @classmethod
    def from_samples(
        cls,
        forwarded: int,
        dropped: int,
        delays_ms: Iterable[float],
        lateness_ms: Iterable[float] = (),
        send_errors: int = 0,
        in_flight: int = 0,
        nbytes: int = 0,
    ) -> DirectionStats:
        """Summarise the observed delays (and scheduling lateness) of one direction."""
        delays = sorted(delays_ms)
        late = sorted(lateness_ms)

        def pct(values: list[float], q: float) -> float | None:
            return percentile(values, q) if values else None

        return cls(
            forwarded,
            dropped,
            p50_ms=pct(delays, 50),
            p90_ms=pct(delays, 90),
            p99_ms=pct(delays, 99),
            max_ms=delays[-1] if delays else None,
            late_p50_ms=pct(late, 50),
            late_p99_ms=pct(late, 99),
            late_max_ms=late[-1] if late else None,
            send_errors=send_errors,
            in_flight=in_flight,
            bytes=nbytes,
        )

    @property
    def loss_pct(self) -> float:
        """Dropped share of what was sent, in percent (0 when nothing was sent)."""
        total = self.forwarded + self.dropped
        return 100.0 * self.dropped / total if total else 0.0

    def to_dict(self) -> dict[str, float | int | None]:
        """The fields as a JSON-ready dict, plus ``loss_pct``."""
        return {
            "forwarded": self.forwarded,
            "dropped": self.dropped,
            "loss_pct": self.loss_pct,
            "p50_ms": self.p50_ms,
            "p90_ms": self.p90_ms,
            "p99_ms": self.p99_ms,
            "max_ms": self.max_ms,
            "late_p50_ms": self.late_p50_ms,
            "late_p99_ms": self.late_p99_ms,
            "late_max_ms": self.late_max_ms,
            "send_errors": self.send_errors,
            "in_flight": self.in_flight,
            "bytes": self.bytes,
        }

    def line(self, name: str, duration_s: float | None = None) -> str:
        """One human line, e.g. ``up: forwarded 100, dropped 2 (2.0%), delay p50 50.1 ... ms;
        carried 51200 bytes (40.9 kbit/s); ...``; the mean rate when ``duration_s`` is given."""

        def ms(v: float | None) -> str:
            return "-" if v is None else f"{v:.1f}"

        rate = ""
        if duration_s is not None and duration_s > 0:
            rate = f" ({self.bytes * 8 / 1000 / duration_s:.1f} kbit/s)"
        text = (
            f"{name}: forwarded {self.forwarded}, dropped {self.dropped} ({self.loss_pct:.1f}%), "
            f"delay p50 {ms(self.p50_ms)} p90 {ms(self.p90_ms)} p99 {ms(self.p99_ms)} "
            f"max {ms(self.max_ms)} ms; carried {self.bytes} bytes{rate}"
        )
        if self.late_p99_ms is not None:
            text += f"; late p99 {self.late_p99_ms:.3f} max {ms(self.late_max_ms)} ms"
        text += f"; in flight at stop {self.in_flight}"
        return text + f"; send errors {self.send_errors}"
