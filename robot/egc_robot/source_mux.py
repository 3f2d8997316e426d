"""Command sources and locks (DESIGN 14): which source drives this cycle, as a pure function.

A robot may take velocity commands from more than one source: its operators over Zenoh
(``operator``), an autonomy stack over Zenoh (``zenoh``, key ``egc/<robot>/source/<name>``) or a
ROS 2 topic such as a navigation stack's ``/cmd_vel_nav`` (``ros2``). Each has a ``priority`` and
a ``timeout_s``. Locks (``egc/<robot>/lock/<name>``, msgpack bool, or a ROS 2 ``std_msgs/Bool``
topic) each have a ``priority`` and a ``timeout_s`` too.

The rules, every cycle (``arbitrate``):

- a source is *fresh* while its newest command that asks to drive arrived within its
  ``timeout_s`` (the controller says what asks to drive: for the ``operator`` source, a command
  of the operator in control with the deadman held; for the others, any valid command);
- a lock is *active* while its newest value is true, or while its feed has been silent for more
  than its ``timeout_s`` (a dead heartbeat locks), or before anything was heard from it;
- an active lock blocks every source of lower priority (an equal one is not blocked);
- the highest-priority fresh source drives unless a lock blocks it. A lock that blocks it blocks
  every lower source too, so then nothing drives.

Unlike twist_mux, "nothing drives" is itself a verdict: the controller sends the base zero at
once (a base keeps its last command). ``Verdict.lock`` names the highest-priority active lock
whether or not it blocks the source that drives (the view shows it).

No clock and no IO here: times are the robot's monotonic nanoseconds, passed in.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

SOURCE_KINDS = ("operator", "zenoh", "ros2")
NS_PER_S = 1_000_000_000
MAX_TIMEOUT_S = 3600.0
NO_SOURCE = "no source fresh"


def _check_timeout(what: str, timeout_s: float) -> None:
    if (
        isinstance(timeout_s, bool)
        or not isinstance(timeout_s, (int, float))
        or not 0.0 < timeout_s <= MAX_TIMEOUT_S
    ):
        raise ValueError(f"{what}: timeout_s must be a number of seconds in (0, 3600]")


def _check_priority(what: str, priority: int) -> None:
    if isinstance(priority, bool) or not isinstance(priority, int) or abs(priority) > 2**31:
        raise ValueError(f"{what}: priority must be an integer")


@dataclass(frozen=True, slots=True)
class SourceSpec:
    """One ``[[source]]`` table. ``topic`` and ``cmd_type`` are the ``ros2`` kind's (a Twist or
    TwistStamped topic); the other kinds have none."""

    name: str
    kind: str
    priority: int
    timeout_s: float
    topic: str | None = None
    cmd_type: str = "twist"

    def __post_init__(self) -> None:
        what = f"source {self.name}"
        if self.kind not in SOURCE_KINDS:
            raise ValueError(f"{what}: kind must be one of {', '.join(SOURCE_KINDS)}")
        _check_priority(what, self.priority)
        _check_timeout(what, self.timeout_s)
        if (self.kind == "ros2") != (self.topic is not None):
            raise ValueError(f"{what}: a topic is given for kind ros2, and only for it")

    @property
    def timeout_ns(self) -> int:
        return int(self.timeout_s * NS_PER_S)


@dataclass(frozen=True, slots=True)
class LockSpec:
    """One ``[[lock]]`` table: fed by ``topic`` (a ROS 2 ``std_msgs/Bool``) when given, else by
    the Zenoh key ``egc/<robot>/lock/<name>``."""

    name: str
    priority: int
    timeout_s: float
    topic: str | None = None

    def __post_init__(self) -> None:
        what = f"lock {self.name}"
        _check_priority(what, self.priority)
        _check_timeout(what, self.timeout_s)

    @property
    def timeout_ns(self) -> int:
        return int(self.timeout_s * NS_PER_S)


@dataclass(frozen=True, slots=True)
class MuxConfig:
    """The robot's sources (kept highest priority first) and locks."""

    sources: tuple[SourceSpec, ...]
    locks: tuple[LockSpec, ...] = ()

    def __post_init__(self) -> None:
        if not self.sources:
            raise ValueError("at least one [[source]] is needed once sources are configured")
        for what, items in (("source", self.sources), ("lock", self.locks)):
            names = [item.name for item in items]
            twice = sorted({n for n in names if names.count(n) > 1})
            if twice:
                raise ValueError(f"{what} name {twice[0]} is used twice")
        by_priority: dict[int, str] = {}
        for s in self.sources:
            other = by_priority.setdefault(s.priority, s.name)
            if other != s.name:
                # Two sources of one priority would be a tie that the order of the file breaks.
                raise ValueError(
                    f"sources {other} and {s.name} have the same priority {s.priority}: "
                    "give each its own"
                )
        if sum(s.kind == "operator" for s in self.sources) > 1:
            raise ValueError("at most one source of kind operator (it stands for all operators)")
        ordered = tuple(sorted(self.sources, key=lambda s: -s.priority))
        object.__setattr__(self, "sources", ordered)

    def source(self, name: str | None) -> SourceSpec | None:
        return next((s for s in self.sources if s.name == name), None)

    @property
    def operator_source(self) -> SourceSpec | None:
        """The source that stands for the operators (None: operators can only e-stop)."""
        return next((s for s in self.sources if s.kind == "operator"), None)


@dataclass(frozen=True, slots=True)
class LockFeed:
    """A lock's newest value and its arrival time (robot's monotonic clock)."""

    value: bool
    rx_ns: int


@dataclass(frozen=True, slots=True)
class Verdict:
    """One cycle's arbitration.

    ``source``: the source that drives (None: none may). ``lock``: the highest-priority active
    lock (None: none is active). ``blocked``: the fresh source that lock keeps from driving
    (None: no fresh source is blocked). ``reason``: in words, for the state machine and the
    view: ``source nav``, ``lock bumper: true``, ``lock hb: silent for 0.62 s``,
    ``no source fresh``.
    """

    source: str | None
    lock: str | None
    reason: str
    blocked: str | None = None


def lock_state(spec: LockSpec, feed: LockFeed | None, now_ns: int) -> str | None:
    """Why the lock is active at ``now_ns`` (``true``, ``silent for 0.62 s``, ``never heard``),
    or None when it is not."""
    if feed is None:
        return "never heard"
    silent_ns = now_ns - feed.rx_ns
    if silent_ns > spec.timeout_ns:
        return f"silent for {silent_ns / NS_PER_S:.2f} s"
    return "true" if feed.value else None


def is_fresh(spec: SourceSpec, claim_rx_ns: int | None, now_ns: int) -> bool:
    """The source's newest command that asks to drive arrived within its timeout."""
    return claim_rx_ns is not None and now_ns - claim_rx_ns <= spec.timeout_ns


def arbitrate(
    config: MuxConfig,
    claims: Mapping[str, int],
    locks: Mapping[str, LockFeed],
    now_ns: int,
) -> Verdict:
    """The source that drives at ``now_ns`` (see the module docstring).

    ``claims``: per source name, the arrival time of its newest command that asks to drive
    (absent: none yet); ``locks``: per lock name, its newest value (absent: never heard).
    """
    lock: LockSpec | None = None
    lock_why = ""
    for spec in config.locks:
        why = lock_state(spec, locks.get(spec.name), now_ns)
        if why is not None and (lock is None or spec.priority > lock.priority):
            lock, lock_why = spec, why
    lock_name = None if lock is None else lock.name
    floor = -math.inf if lock is None else lock.priority
    for source in config.sources:  # highest priority first
        if not is_fresh(source, claims.get(source.name), now_ns):
            continue
        if source.priority < floor:
            return Verdict(None, lock_name, f"lock {lock_name}: {lock_why}", source.name)
        return Verdict(source.name, lock_name, f"source {source.name}")
    if lock is not None:
        return Verdict(None, lock_name, f"lock {lock_name}: {lock_why}")
    return Verdict(None, None, NO_SOURCE)
