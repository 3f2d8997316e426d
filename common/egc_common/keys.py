"""Zenoh key expressions of the wire contract (DESIGN 7, pinned)."""

from __future__ import annotations

import re

DEFAULT_ROBOT_ID = "sim"
_ID_RE = re.compile(r"^[A-Za-z0-9_\-]{1,64}$")


def validate_id(identifier: str, what: str = "robot id") -> str:
    """Ids become key-expression chunks: no '/', '*', '$', '?', '#' or whitespace."""
    if not isinstance(identifier, str) or not _ID_RE.match(identifier):
        raise ValueError(f"{what} {identifier!r} must be 1-64 characters of [A-Za-z0-9_-]")
    return identifier


def cmd(robot: str) -> str:
    return f"egc/{validate_id(robot)}/cmd"


def goal(robot: str) -> str:
    """Operator -> robot via points (DESIGN 7)."""
    return f"egc/{validate_id(robot)}/goal"


def telemetry(robot: str) -> str:
    return f"egc/{validate_id(robot)}/telemetry"


def state(robot: str) -> str:
    return f"egc/{validate_id(robot)}/state"


def clock(robot: str) -> str:
    return f"egc/{validate_id(robot)}/clock"


def world_map(robot: str) -> str:
    """Queryable: the robot's static occupancy map for the operator view (not pinned)."""
    return f"egc/{validate_id(robot)}/map"


def scan(robot: str) -> str:
    return f"egc/{validate_id(robot)}/scan"


def base_cmd(robot: str) -> str:
    return f"egc/{validate_id(robot)}/base/cmd"


def base_odom(robot: str) -> str:
    return f"egc/{validate_id(robot)}/base/odom"


def alive_robot(robot: str) -> str:
    return f"egc/{validate_id(robot)}/alive/robot"


def alive_operator(robot: str, operator_id: str) -> str:
    return f"egc/{validate_id(robot)}/alive/operator/{validate_id(operator_id, 'operator id')}"


def alive_operators(robot: str) -> str:
    """Wildcard matching every operator's liveliness token of one robot."""
    return f"egc/{validate_id(robot)}/alive/operator/*"


def operator_id_from_alive_key(key: str) -> str | None:
    """The operator id at the end of an ``alive/operator/<id>`` key, or None."""
    parts = str(key).split("/")
    if len(parts) == 5 and parts[0] == "egc" and parts[2:4] == ["alive", "operator"]:
        return parts[4]
    return None


def info(robot: str) -> str:
    """Robot queryable: what the robot is and does (DESIGN 15)."""
    return f"egc/{validate_id(robot)}/info"


ALL_ROBOTS_ALIVE = "egc/*/alive/robot"
ALL_ROBOTS_INFO = "egc/*/info"
ALL_ROBOTS_STATE = "egc/*/state"


def robot_id_from_key(key: str) -> str | None:
    """The robot id of any ``egc/<robot>/...`` key, or None."""
    parts = str(key).split("/")
    if len(parts) >= 3 and parts[0] == "egc":
        try:
            return validate_id(parts[1])
        except ValueError:
            return None
    return None


def camera(robot: str) -> str:
    """Robot -> operators, the camera's encoded frames (DESIGN 12, view plane)."""
    return f"egc/{validate_id(robot)}/camera"


def source(robot: str, name: str) -> str:
    """A ``zenoh`` command source -> robot (DESIGN 14)."""
    return f"egc/{validate_id(robot)}/source/{validate_id(name, 'source name')}"


def lock(robot: str, name: str) -> str:
    """A lock's feed -> robot, a msgpack bool (DESIGN 14)."""
    return f"egc/{validate_id(robot)}/lock/{validate_id(name, 'lock name')}"
