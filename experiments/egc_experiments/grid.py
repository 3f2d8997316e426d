"""Experiment grids (DESIGN 10): a TOML file of sweeps, each a full product of its axes.

A grid is a list of *sweeps*, not one product, so that "delay from 0 to 1000 ms" and "loss from
0 to 10 %" can be swept each around a fixed point of the other instead of multiplying into tens
of thousands of runs. Runs that two sweeps share (the same ``RunPoint``) run once.

Format::

    description = "what this grid is for"   # optional, copied into report.md

    # Top-level axis keys are the defaults of every sweep (a value or a list).
    profile = "pioneer3dx"
    max_time_s = 150
    seeds = 5                 # an integer N: seeds 0..N-1; or a list, e.g. [3, 7]

    [worlds.office]           # a named world: a map with its own start, goal and time limit
    map = "office02"
    start = [-7.0, -1.0, 1.5708]
    goal = [-2.0, 3.6]
    max_time_s = 120          # optional

    [[sweep]]
    name = "delay"            # optional; used in error messages and report.md
    world = ["hallway", "random", "office"]
    operator = "sighted"
    filter = ["none", "egc"]
    delay_ms = [0, 100, 200, 500]
    jitter_frac = [0, 0.3]
    link_aware = [true, false]

    [[sweep]]
    name = "loss"
    transport = "udp"
    loss = [1, 5, 10]
    ...

Axes (every one takes a value or a list; a sweep is the product of its lists):

- ``world``: a built-in name (``hallway``, ``office02``), a map.yaml / .toml / .npy path, a
  ``[worlds.NAME]`` entry, ``random:SEED`` (one fixed random world) or ``random`` (the run's
  seed picks the random world, so N seeds are N different worlds). Start and goal are the
  world's own unless a ``[worlds.NAME]`` entry gives them.
- ``operator``: ``sighted``, ``route``, ``goal``, ``forward`` (with options, e.g.
  ``"sighted:reaction_s=0.5"``, ``"route:map=building"``; ``egc_sim.operators.make_operator``)
  or a joystick file.
- ``filter``: ``none`` | ``egc`` | ``ek-egc`` | ``assist`` | ``dwa``; ``mode``: ``direct`` |
  ``shared``, by default ``direct`` for
  ``filter = "none"`` and ``shared`` otherwise.
- ``transport``: ``tcp`` (ordered, nothing lost: a TCP link retransmits, so a loss shows up as
  delay; an outage holds everything back until it ends) or ``udp`` (datagrams: lost, and
  dropped during an outage). ``loss`` on ``tcp`` is an error.
- ``delay_ms``: one-way delay, applied to each direction (the round trip is twice it);
  ``jitter_ms`` its standard deviation, or ``jitter_frac`` as a fraction of ``delay_ms`` (not
  both); ``dist``: ``normal`` | ``uniform`` | ``pareto``.
- ``loss``: percent per packet, each direction; ``burst``: mean burst length (0: independent),
  ignored (0) at ``loss = 0`` so that ``loss = [0, 5]`` and ``burst = [0, 3]`` make 3 points.
- ``rate_kbps``: a rate limit in kbit/s in each direction with a deep buffer behind it (the
  relay's ``rate=``, DESIGN 10; 0: none), e.g. ``rate_kbps = [0, 512, 192, 128]`` for the
  thin uplinks of DESIGN 12. The robot's downlink budget (DESIGN 12) runs in ``emulated`` mode
  only: the ``simulated`` mode sends the telemetry of every cycle at its modelled size, with
  no budget, so use ``--mode emulated`` for such points.
- ``outage_s``: one outage of that many seconds in both directions (0: none), starting at
  ``outage_start_s`` (default 10 s, when the robot is well under way).
- ``link_aware``: the robot's link-aware driving (DESIGN 8, 9) on or off.
- ``latency_turn_cap``: false leaves out the latency governor's cap on the turn rate (our
  addition to DESIGN 9, ``egc_robot.latency_governor``), so that a grid can compare the two.
- ``seeds``; ``profile``; ``max_time_s`` (default 150); ``stall_time_s`` (default 30: a robot
  that has not moved 0.1 m for that long ends the run as ``stalled``).

``load_grid(path)`` returns the ``RunPoint``s in order; every error is a ``GridError`` with one
line naming the file, the sweep and the key.
"""

from __future__ import annotations

import itertools
import math
import tomllib
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

from egc_experiments.link_model import LinkModel, SpecError, parse_spec
from egc_experiments.run_point import MODES, TRANSPORTS, RunPoint

AXES: Final = (
    "world",
    "operator",
    "filter",
    "mode",
    "transport",
    "delay_ms",
    "jitter_ms",
    "jitter_frac",
    "dist",
    "loss",
    "burst",
    "outage_s",
    "outage_start_s",
    "rate_kbps",
    "link_aware",
    "latency_turn_cap",
    "seeds",
    "profile",
    "max_time_s",
    "stall_time_s",
)
DEFAULTS: Final[dict[str, Any]] = {
    "filter": "egc",
    "transport": "tcp",
    "delay_ms": 0.0,
    "dist": "normal",
    "loss": 0.0,
    "burst": 0.0,
    "outage_s": 0.0,
    "outage_start_s": 10.0,
    "rate_kbps": 0.0,
    "link_aware": True,
    "latency_turn_cap": True,
    "seeds": [0],
    "profile": "pioneer3dx",
    "max_time_s": 150.0,
    "stall_time_s": 30.0,
}
WORLD_KEYS: Final = ("map", "start", "goal", "max_time_s")
TOP_KEYS: Final = ("description", "name", "worlds", "sweep", *AXES)
SWEEP_KEYS: Final = ("name", *AXES)


class GridError(ValueError):
    """A bad grid file; the message is one line for the user."""


@dataclass(frozen=True, slots=True)
class WorldEntry:
    map: str
    start: tuple[float, float, float] | None = None
    goal: tuple[float, float] | None = None
    max_time_s: float | None = None


@dataclass(frozen=True, slots=True)
class Grid:
    """A parsed grid: its description, sweep names and the distinct run points in order."""

    description: str
    sweeps: tuple[str, ...]
    points: tuple[RunPoint, ...]


def _numbers(where: str, value: object, n: int) -> tuple[float, ...]:
    if (
        not isinstance(value, list)
        or len(value) != n
        or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in value)
        or not all(math.isfinite(v) for v in value)
    ):
        raise GridError(f"{where} must be a list of {n} finite numbers, got {value!r}")
    return tuple(float(v) for v in value)


def _worlds(table: object, source: str) -> dict[str, WorldEntry]:
    if not isinstance(table, dict):
        raise GridError(f"{source}: [worlds] must be a table of [worlds.NAME] tables")
    out: dict[str, WorldEntry] = {}
    for name, entry in table.items():
        where = f"{source}: [worlds.{name}]"
        if not isinstance(entry, dict):
            raise GridError(f"{where} must be a table with at least map = ...")
        unknown = sorted(set(entry) - set(WORLD_KEYS))
        if unknown:
            raise GridError(
                f"{where}: unknown key(s) {', '.join(unknown)} (known: {', '.join(WORLD_KEYS)})"
            )
        if not isinstance(entry.get("map"), str) or not entry["map"].strip():
            raise GridError(f'{where} needs map = "a built-in name or a map file"')
        start = entry.get("start")
        goal = entry.get("goal")
        limit = entry.get("max_time_s")
        if limit is not None and not (
            isinstance(limit, int | float) and not isinstance(limit, bool) and limit > 0
        ):
            raise GridError(f"{where}: max_time_s must be a positive number, got {limit!r}")
        s3 = None if start is None else _numbers(f"{where}: start", start, 3)
        g2 = None if goal is None else _numbers(f"{where}: goal", goal, 2)
        out[name] = WorldEntry(
            entry["map"].strip(),
            None if s3 is None else (s3[0], s3[1], s3[2]),
            None if g2 is None else (g2[0], g2[1]),
            None if limit is None else float(limit),
        )
    return out


def _as_list(value: object) -> list[Any]:
    return list(value) if isinstance(value, list) else [value]


def _check_values(where: str, key: str, values: list[Any]) -> list[Any]:
    if not values:
        raise GridError(f"{where}: {key} is an empty list")

    def number(v: object, lo: float = 0.0, hi: float = math.inf) -> float:
        if not isinstance(v, int | float) or isinstance(v, bool) or not math.isfinite(v):
            raise GridError(f"{where}: {key} values must be numbers, got {v!r}")
        if not lo <= v <= hi:
            raise GridError(f"{where}: {key} = {v!r} is outside [{lo:g}, {hi:g}]")
        return float(v)

    if key in ("world", "operator", "filter", "mode", "transport", "dist", "profile"):
        for v in values:
            if not isinstance(v, str) or not v.strip():
                raise GridError(f"{where}: {key} values must be non-empty strings, got {v!r}")
        if key == "mode" and (bad := [v for v in values if v not in MODES]):
            raise GridError(f"{where}: mode {bad[0]!r} is not one of {', '.join(MODES)}")
        if key == "transport" and (bad := [v for v in values if v not in TRANSPORTS]):
            raise GridError(f"{where}: transport {bad[0]!r} is not one of {', '.join(TRANSPORTS)}")
        return [v.strip() for v in values]
    if key in ("link_aware", "latency_turn_cap"):
        if not all(isinstance(v, bool) for v in values):
            raise GridError(f"{where}: {key} values must be true or false")
        return values
    if key == "loss":
        return [number(v, 0.0, 100.0) for v in values]
    if key == "jitter_frac":
        return [number(v, 0.0, 10.0) for v in values]
    if key in ("max_time_s", "stall_time_s"):
        out = [number(v) for v in values]
        if any(v <= 0 for v in out):
            raise GridError(f"{where}: {key} must be > 0")
        return out
    return [number(v) for v in values]


def _seeds(where: str, value: object) -> list[int]:
    if isinstance(value, int) and not isinstance(value, bool):
        if not 1 <= value <= 100_000:
            raise GridError(f"{where}: seeds = N needs 1 <= N <= 100000, got {value}")
        return list(range(value))
    if isinstance(value, list) and value:
        if not all(isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in value):
            raise GridError(f"{where}: seeds must be integers >= 0, got {value!r}")
        return list(value)
    raise GridError(f"{where}: seeds must be an integer N (0..N-1) or a list of integers")


def _sweep_points(
    where: str, axes: dict[str, Any], worlds: dict[str, WorldEntry]
) -> Iterator[tuple[str, RunPoint]]:
    """The sweep's run points, each with the ``world`` name it came from (a [worlds.NAME]
    entry or a map)."""
    for key in ("world", "operator"):
        if key not in axes:
            raise GridError(f"{where}: no {key} (give it in the sweep or at the top level)")
    if "jitter_ms" in axes and "jitter_frac" in axes:
        raise GridError(f"{where}: give jitter_ms or jitter_frac, not both")
    lists: dict[str, list[Any]] = {}
    for key in AXES:
        if key == "seeds":
            lists[key] = _seeds(where, axes.get(key, DEFAULTS["seeds"]))
        elif key in axes:
            lists[key] = _check_values(where, key, _as_list(axes[key]))
        elif key == "jitter_ms" and "jitter_frac" not in axes:
            lists[key] = [0.0]
        elif key in DEFAULTS:
            lists[key] = [DEFAULTS[key]]
    if any(b > 0 for b in lists["burst"]) and not any(v > 0 for v in lists["loss"]):
        raise GridError(f"{where}: burst without loss: burst shapes the losses of loss > 0")
    names = list(lists)
    for combo in itertools.product(*(lists[k] for k in names)):
        v = dict(zip(names, combo, strict=True))
        entry = worlds.get(v["world"], WorldEntry(v["world"]))
        mode = v.get("mode") or ("direct" if v["filter"] == "none" else "shared")
        jitter = v["delay_ms"] * v["jitter_frac"] if "jitter_frac" in v else v["jitter_ms"]
        outages = ((v["outage_start_s"], v["outage_s"]),) if v["outage_s"] > 0 else ()
        try:
            point = RunPoint(
                world=entry.map,
                operator=v["operator"],
                filter=v["filter"],
                mode=mode,
                transport=v["transport"],
                delay_ms=float(v["delay_ms"]),
                jitter_ms=round(float(jitter), 6),
                dist=v["dist"],
                loss=float(v["loss"]),
                burst=float(v["burst"]) if v["loss"] > 0 else 0.0,
                outages=outages,
                rate_kbps=float(v["rate_kbps"]),
                seed=int(v["seeds"]),
                link_aware=bool(v["link_aware"]),
                latency_turn_cap=bool(v["latency_turn_cap"]),
                profile=v["profile"],
                start=entry.start,
                goal=entry.goal,
                max_time_s=entry.max_time_s or float(v["max_time_s"]),
                stall_time_s=float(v["stall_time_s"]),
            )
        except ValueError as exc:
            raise GridError(f"{where}: {exc}") from None
        yield v["world"], point


def check_link(point: RunPoint) -> None:
    """The point's link as the link model takes it; ``GridError`` if it cannot be built."""
    try:
        LinkModel(parse_spec(point.link_spec()), 0, ordered=point.transport == "tcp")
    except SpecError as exc:
        raise GridError(f"{point.transport} link {point.link_spec()!r}: {exc}") from None


def parse_grid(
    data: dict[str, Any],
    source: str = "grid",
    check_point: Callable[[RunPoint], None] | None = None,
) -> Grid:
    """A grid from parsed TOML (module docstring). ``check_point`` vets each distinct point
    (world, operator, filter, profile exist) and raises ``GridError``; links are always checked.
    """
    unknown = sorted(set(data) - set(TOP_KEYS))
    if unknown:
        raise GridError(
            f"{source}: unknown key(s) {', '.join(unknown)} (known: {', '.join(TOP_KEYS)})"
        )
    description = data.get("description", "")
    if not isinstance(description, str):
        raise GridError(f"{source}: description must be a string")
    worlds = _worlds(data.get("worlds", {}), source)
    sweeps = data.get("sweep")
    if not isinstance(sweeps, list) or not sweeps or not all(isinstance(s, dict) for s in sweeps):
        raise GridError(f"{source}: a grid needs at least one [[sweep]] table")
    defaults = {k: v for k, v in data.items() if k in AXES}
    points: dict[str, RunPoint] = {}
    names: list[str] = []
    world_of: dict[str, str] = {}  # point key -> the world name (maybe an entry) it came from
    for i, sweep in enumerate(sweeps, start=1):
        name = sweep.get("name", f"sweep {i}")
        if not isinstance(name, str):
            raise GridError(f"{source}: sweep {i}: name must be a string")
        where = f"{source}: sweep {name!r}"
        bad = sorted(set(sweep) - set(SWEEP_KEYS))
        if bad:
            raise GridError(f"{where}: unknown key(s) {', '.join(bad)} (axes: {', '.join(AXES)})")
        names.append(name)
        axes = {**defaults, **{k: v for k, v in sweep.items() if k != "name"}}
        if "jitter_frac" in sweep and "jitter_ms" in defaults and "jitter_ms" not in sweep:
            del axes["jitter_ms"]
        if "jitter_ms" in sweep and "jitter_frac" in defaults and "jitter_frac" not in sweep:
            del axes["jitter_frac"]
        for world_name, point in _sweep_points(where, axes, worlds):
            key = point.key()
            if key in points:
                continue
            world_of[key] = world_name
            try:
                check_link(point)
            except GridError as exc:
                raise GridError(f"{where}: {exc}") from None
            points[key] = point
    if check_point is not None:
        checked: set[tuple[Any, ...]] = set()
        for point in points.values():
            ident: tuple[Any, ...] = (
                point.world,
                point.operator,
                point.filter,
                point.profile,
                point.start,
                point.goal,
            )
            if point.operator.startswith("route"):
                ident += (point.mode,)
            if ident in checked:
                continue
            checked.add(ident)
            try:
                check_point(point)
            except GridError as exc:
                name = world_of[point.key()]
                if name not in worlds:  # a map named in the sweep: the message names it
                    raise
                raise GridError(f"{source}: [worlds.{name}]: {exc}") from None
    return Grid(description, tuple(names), tuple(points.values()))


def load_grid(path: str | Path, check_point: Callable[[RunPoint], None] | None = None) -> Grid:
    """Read and parse a grid file; every problem is one ``GridError`` line."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise GridError(f"grid file {p} does not exist") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise GridError(f"cannot read grid file {p}: {exc}") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise GridError(f"{p}: not valid TOML: {exc}") from None
    return parse_grid(data, str(p), check_point)
