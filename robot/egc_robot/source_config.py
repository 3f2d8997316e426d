"""The robot TOML's ``[[source]]``, ``[[lock]]`` and ``[[operator]]`` tables (DESIGN 14), checked.

    [[source]]                 # one per source of velocity commands
    name = "nav"               # [A-Za-z0-9_-], 1-64 characters (a Zenoh key chunk)
    kind = "ros2"              # operator | zenoh | ros2
    priority = 10              # integer; higher wins; each source its own
    timeout_s = 0.5            # fresh while its newest command is younger (default 0.5 s)
    topic = "/cmd_vel_nav"     # ros2 only: a Twist or TwistStamped topic
    cmd_type = "twist"         # ros2 only: twist | twist-stamped (default twist)

    [[lock]]
    name = "pause"
    priority = 200             # blocks every source of lower priority while active
    timeout_s = 1.0            # silent longer than this: active (default 0.5 s)
    kind = "ros2"              # zenoh (default: key egc/<robot>/lock/<name>) | ros2
    topic = "/pause"           # ros2 only: a std_msgs/Bool topic

    [[operator]]               # operators among themselves (none listed: priority 0)
    id = "supervisor"
    priority = 100             # a higher one takes control at once; equal ones: first come

Every mistake is a ``ValueError`` of one line naming the table, its entry and the key.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from egc_common.keys import validate_id

from egc_robot.ros2_core import CMD_TYPES, is_topic_name
from egc_robot.source_mux import MAX_TIMEOUT_S, SOURCE_KINDS, LockSpec, MuxConfig, SourceSpec

DEFAULT_TIMEOUT_S = 0.5
SOURCE_KEYS = ("name", "kind", "priority", "timeout_s", "topic", "cmd_type")
LOCK_KEYS = ("name", "priority", "timeout_s", "kind", "topic")
OPERATOR_KEYS = ("id", "priority")
LOCK_KINDS = ("zenoh", "ros2")


def _tables(raw: object, table: str, allowed: tuple[str, ...]) -> list[dict[str, Any]]:
    if raw is None:
        return []
    if not isinstance(raw, list) or not all(isinstance(t, dict) for t in raw):
        raise ValueError(f"{table} must be an array of tables ([[{table}]])")
    for i, entry in enumerate(raw, 1):
        unknown = sorted(set(entry) - set(allowed))
        if unknown:
            raise ValueError(
                f"[[{table}]] {_label(entry, i)}: unknown key {unknown[0]} "
                f"(known: {', '.join(allowed)})"
            )
    return raw


def _label(entry: Mapping[str, Any], index: int) -> str:
    name = entry.get("name", entry.get("id"))
    return f"#{index} ({name})" if isinstance(name, str) else f"#{index}"


def _required(entry: Mapping[str, Any], key: str, where: str) -> Any:
    if key not in entry:
        raise ValueError(f"{where}: key {key} is missing")
    return entry[key]


def _int(entry: Mapping[str, Any], key: str, where: str) -> int:
    value = _required(entry, key, where)
    if isinstance(value, bool) or not isinstance(value, int) or abs(value) > 2**31:
        raise ValueError(f"{where}: key {key} must be an integer, got {value!r}")
    return value


def _seconds(entry: Mapping[str, Any], where: str) -> float:
    value = entry.get("timeout_s", DEFAULT_TIMEOUT_S)
    if (
        isinstance(value, bool)
        or not isinstance(value, (int, float))
        or not 0.0 < value <= MAX_TIMEOUT_S
    ):
        raise ValueError(
            f"{where}: key timeout_s must be a number of seconds in (0, 3600], got {value!r}"
        )
    return float(value)


def _choice(entry: Mapping[str, Any], key: str, choices: tuple[str, ...], where: str) -> str:
    value = entry[key]
    if value not in choices:
        raise ValueError(f"{where}: key {key} must be one of {', '.join(choices)}, got {value!r}")
    return str(value)


def _name(entry: Mapping[str, Any], key: str, where: str) -> str:
    value = _required(entry, key, where)
    if not isinstance(value, str):
        raise ValueError(f"{where}: key {key} must be a string, got {value!r}")
    try:
        return validate_id(value, f"key {key}")
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None


def _topic(entry: Mapping[str, Any], kind: str, where: str) -> str | None:
    if kind != "ros2":
        if "topic" in entry:
            raise ValueError(f"{where}: key topic is for kind ros2 only")
        return None
    topic = _required(entry, "topic", where)
    if not isinstance(topic, str) or not is_topic_name(topic):
        raise ValueError(f"{where}: key topic {topic!r} is not a valid ROS 2 topic name")
    return topic


def _source(entry: Mapping[str, Any], index: int) -> SourceSpec:
    where = f"[[source]] {_label(entry, index)}"
    name = _name(entry, "name", where)
    _required(entry, "kind", where)
    kind = _choice(entry, "kind", SOURCE_KINDS, where)
    priority = _int(entry, "priority", where)
    topic = _topic(entry, kind, where)
    cmd_type = "twist"
    if "cmd_type" in entry:
        if kind != "ros2":
            raise ValueError(f"{where}: key cmd_type is for kind ros2 only")
        cmd_type = _choice(entry, "cmd_type", CMD_TYPES, where)
    return SourceSpec(name, kind, priority, _seconds(entry, where), topic, cmd_type)


def _lock(entry: Mapping[str, Any], index: int) -> LockSpec:
    where = f"[[lock]] {_label(entry, index)}"
    name = _name(entry, "name", where)
    priority = _int(entry, "priority", where)
    kind = _choice(entry, "kind", LOCK_KINDS, where) if "kind" in entry else "zenoh"
    topic = _topic(entry, kind, where)
    return LockSpec(name, priority, _seconds(entry, where), topic)


def mux_config(sources: object, locks: object) -> MuxConfig | None:
    """The ``[[source]]`` and ``[[lock]]`` tables as a ``MuxConfig``; None when there is no
    ``[[source]]`` table (the robot behaves as without sources: one operator source). Locks
    without sources are refused: they would lock nothing anyone expects."""
    source_tables = _tables(sources, "source", SOURCE_KEYS)
    lock_tables = _tables(locks, "lock", LOCK_KEYS)
    if not source_tables:
        if lock_tables:
            raise ValueError("[[lock]] tables need [[source]] tables (a lock blocks sources)")
        return None
    specs = tuple(_source(entry, i) for i, entry in enumerate(source_tables, 1))
    lock_specs = tuple(_lock(entry, i) for i, entry in enumerate(lock_tables, 1))
    return MuxConfig(specs, lock_specs)


def operator_priorities(operators: object) -> tuple[tuple[str, int], ...]:
    """The ``[[operator]]`` tables as (id, priority) pairs; each id at most once."""
    out: dict[str, int] = {}
    for i, entry in enumerate(_tables(operators, "operator", OPERATOR_KEYS), 1):
        where = f"[[operator]] {_label(entry, i)}"
        op = _name(entry, "id", where)
        if op in out:
            raise ValueError(f"{where}: operator {op} is listed twice")
        out[op] = _int(entry, "priority", where)
    return tuple(out.items())
