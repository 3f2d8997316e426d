"""How much the safety layer changed the operator's commands (DESIGN 13, pinned metrics).

A safety layer that rewrites a careful operator's commands gets switched off, so the product
measures it. Per control cycle, the command sent is compared with what direct mode would have
sent on the same cycle (``PipelineResult.plain``: the operator's command within the profile's
velocity and acceleration limits): the difference is the filter's and the footprint sweep's
doing alone, not the base's ramp, which direct mode has too.

- ``changed``: cycles whose v or w differs by more than 0.01 (m/s, rad/s) from direct mode's
  (DESIGN 11's threshold, as in the replay summary); ``changed_share`` = changed / commands;
- ``mean_cut``: the mean over the cycles of |dv| / v_max + |dw| / w_max;
- ``hold_s``: time during which the layer stopped a command direct mode would have moved with
  (translation kept above 0.01 m/s by direct mode cut to 0.01 or less, or a turn in place so
  stopped; the replay's ``held``).

``commands`` counts the cycles that went through the pipeline (the deadman held); a HOLD of the
state machine or a released deadman is not the filter's. Pure and clock-free: the caller says
how long each cycle lasted.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from egc_robot.pipeline import PipelineResult

CHANGED = 0.01  # m/s or rad/s: DESIGN 11's "differs by more than 0.01"
MOVING = 0.01  # |v| (m/s) or |w| (rad/s) above this is a moving command


@dataclass(slots=True)
class InterventionTally:
    """Running sums over an episode's cycles; ``as_dict`` gives the pinned keys."""

    v_max_mps: float
    w_max_radps: float
    commands: int = 0
    changed: int = 0
    cut_sum: float = 0.0
    hold_s: float = 0.0

    def add(self, result: PipelineResult, dt_s: float) -> None:
        """One cycle's pipeline result, which lasted ``dt_s`` seconds."""
        if result.plain is None:
            return
        v0, w0 = result.plain
        v, w = result.v_cmd_mps, result.w_cmd_radps
        dv, dw = abs(v - v0), abs(w - w0)
        self.commands += 1
        self.changed += dv > CHANGED or dw > CHANGED
        self.cut_sum += dv / self.v_max_mps + dw / self.w_max_radps
        if abs(v0) > MOVING:
            held = abs(v) <= MOVING
        else:
            held = abs(w0) > MOVING and abs(w) <= MOVING
        self.hold_s += dt_s if held else 0.0

    def as_dict(self) -> dict[str, Any]:
        n = self.commands
        return {
            "commands": n,
            "changed": self.changed,
            "changed_share": round(self.changed / n, 6) if n else 0.0,
            "mean_cut": round(self.cut_sum / n, 6) if n else 0.0,
            "hold_s": round(self.hold_s, 3),
        }
