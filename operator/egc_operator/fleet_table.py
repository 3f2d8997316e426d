"""The fleet as the status line and the view show it (DESIGN 15): pure, times passed in.

One ``FleetRow`` per robot seen: its state (the newest state message, else the info reply's
snapshot), why, the operator in control, what it is (profile, camera), its link figures (the
age of its newest state message, which comes at least once a second, and the round trip of its
clock query) and, when its driver localises, its map pose and map frame id. The driven robot's
own figures come from its telemetry (the status line's and view's main panels); the fleet rows
are for the others, at the cost of their state messages and one clock query a second each.

- ``others_text``: the status line's fleet part, ``r1 HOLD, r3 IDLE (op-2)``.
- ``fleet_markdown``: the view's fleet panel, a table.
- ``on_shared_map``: the robots to draw on the driven robot's map: those whose info gives the
  same map frame id and whose state gives a map pose.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from egc_common.messages import StateMessage
from egc_common.robot_info import RobotInfo

NS_PER_S = 1_000_000_000
# A robot sends its state at least once a second (DESIGN 7); older than this it is not current.
STATE_STALE_S = 2.5


@dataclass(frozen=True, slots=True)
class FleetRow:
    robot: str
    driven: bool
    state: str | None = None
    reason: str | None = None
    operator: str | None = None
    state_age_s: float | None = None  # None: no state message yet
    rtt_ms: float | None = None
    profile: str | None = None
    camera: str | None = None
    map_id: str | None = None
    map_pose: tuple[float, float, float] | None = None
    snapshot_age_s: float | None = None  # its camera's latest snapshot (fleet_thumbnails)

    @property
    def stale(self) -> bool:
        return self.state_age_s is not None and self.state_age_s > STATE_STALE_S


def fleet_rows(
    robots: Sequence[str],
    infos: Mapping[str, RobotInfo | None],
    states: Mapping[str, tuple[StateMessage, int]],
    rtts_ms: Mapping[str, float],
    driven: str | None,
    now_ns: int,
    snapshots_ns: Mapping[str, int] | None = None,
) -> list[FleetRow]:
    """The rows, in ``robots``' order; ``states`` maps a robot to its newest state message and
    its arrival time (``now_ns``'s clock), ``snapshots_ns`` to when its camera's latest
    snapshot was taken (same clock)."""
    snapshots_ns = snapshots_ns or {}
    rows = []
    for robot in robots:
        info = infos.get(robot)
        seen = states.get(robot)
        state, rx_ns = (None, None) if seen is None else seen
        rows.append(
            FleetRow(
                robot=robot,
                driven=robot == driven,
                state=state.state if state is not None else (info.state if info else None),
                reason=None if state is None else state.reason,
                operator=state.operator if state is not None else (info.operator if info else None),
                state_age_s=None if rx_ns is None else max(0.0, (now_ns - rx_ns) / NS_PER_S),
                rtt_ms=rtts_ms.get(robot),
                profile=None if info is None else info.profile,
                camera=None if info is None else info.camera,
                map_id=None if info is None else info.map,
                map_pose=None if state is None else state.map_pose,
                snapshot_age_s=None
                if robot not in snapshots_ns
                else max(0.0, (now_ns - snapshots_ns[robot]) / NS_PER_S),
            )
        )
    return rows


def _state_word(row: FleetRow) -> str:
    if row.state is None:
        return "?"
    if row.stale:
        return f"{row.state}? (silent {row.state_age_s:.0f} s)"
    return row.state


def others_text(rows: Sequence[FleetRow], me: str) -> str:
    """The other robots for the status line: ``r1 HOLD, r3 IDLE (op-2)``; the operator in
    control is named when it is not this one."""
    parts = []
    for row in rows:
        if row.driven:
            continue
        who = f" ({row.operator})" if row.operator and row.operator != me else ""
        parts.append(f"{row.robot} {_state_word(row)}{who}")
    return ", ".join(parts) if parts else "no other robot"


def _figure(value: float | None, fmt: str) -> str:
    return "-" if value is None else format(value, fmt)


def fleet_markdown(rows: Sequence[FleetRow], me: str, note: str = "") -> str:
    """The view's fleet panel: one table row per robot, the driven one in bold."""
    lines = [
        "| robot | state | why | in control | state age | clock rtt | profile | camera |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        name = f"**{row.robot} (driven)**" if row.driven else row.robot
        who = (
            "-"
            if row.operator is None
            else ("this operator" if row.operator == me else row.operator)
        )
        age = "-" if row.state_age_s is None else f"{row.state_age_s:.1f} s"
        camera = row.camera or "?"
        if row.snapshot_age_s is not None:
            camera += f" (snapshot {row.snapshot_age_s:.0f} s ago)"
        lines.append(
            f"| {name} | {_state_word(row)} | {row.reason or '-'} | {who} | {age} | "
            f"{_figure(row.rtt_ms, '.1f')} ms | {row.profile or '?'} | {camera} |"
        )
    if not rows:
        lines.append("| (no robot seen) | | | | | | | |")
    text = "\n".join(lines)
    return f"{text}\n\n{note}" if note else text


def on_shared_map(rows: Sequence[FleetRow]) -> list[FleetRow]:
    """The robots drawn on the driven robot's map: it and every robot in the same map frame
    (the same id from their info) whose state gives a map pose. None without a driven robot
    with a map id: robots in unknown frames are never drawn as if they shared one."""
    driven = next((row for row in rows if row.driven), None)
    if driven is None or driven.map_id is None:
        return []
    return [
        row
        for row in rows
        if row.map_id == driven.map_id and row.map_pose is not None and not row.stale
    ]
