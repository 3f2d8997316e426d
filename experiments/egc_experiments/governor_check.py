"""Does the latency governor make an operator collide less? A table from an experiment's runs.

Reads ``runs.jsonl`` of an experiment with ``link_aware`` on and off (e.g.
``experiments/grids/governor-jackal.toml``) and prints, per operator and one-way delay, the
collisions with link-aware driving (and so the governor, DESIGN 9) on and off, and how many of
them happened while the robot was moving (``contact_speed_mps`` above ``MOVING_MPS``; a contact
at v = 0 is a turn in place, which no speed cap can prevent). The totals over the delayed runs
(delay > 0) come with a one-sided Fisher exact test (scipy) of "fewer collisions with the
governor", so that a difference of a few runs is not read as an effect::

    python -m egc_experiments.governor_check DIR/runs.jsonl
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import defaultdict
from collections.abc import Iterable
from pathlib import Path
from typing import Any, Final

from scipy.stats import fisher_exact

MOVING_MPS: Final = 0.05


def _count(runs: Iterable[dict[str, Any]]) -> dict[tuple[str, float, bool], list[int]]:
    """(operator, delay, link_aware) -> [runs, collided, collided while moving]."""
    table: dict[tuple[str, float, bool], list[int]] = defaultdict(lambda: [0, 0, 0])
    for run in runs:
        cell = table[(run["operator"], float(run["delay_ms"]), bool(run["link_aware"]))]
        cell[0] += 1
        if run["collided"]:
            cell[1] += 1
            speed = run.get("contact_speed_mps")
            cell[2] += speed is not None and speed > MOVING_MPS
    return table


def _fisher_less(on: list[int], off: list[int], column: int) -> float:
    """One-sided p of 'the governor (on) has a smaller rate than off' for one count column."""
    _, p = fisher_exact(
        [[on[column], on[0] - on[column]], [off[column], off[0] - off[column]]],
        alternative="less",
    )
    return float(p)


def report(runs: list[dict[str, Any]]) -> str:
    """The markdown tables (module docstring)."""
    table = _count(runs)
    operators = sorted({key[0] for key in table})
    delays = sorted({key[1] for key in table})
    lines = [
        "| operator | one-way delay ms | runs | collided, governor on / off "
        "| of them moving, on / off |",
        "|---|---:|---:|---:|---:|",
    ]
    totals: dict[str, tuple[list[int], list[int]]] = {}
    for op in operators:
        on_total, off_total = [0, 0, 0], [0, 0, 0]
        for delay in delays:
            on, off = table.get((op, delay, True)), table.get((op, delay, False))
            if on is None or off is None:
                continue
            lines.append(
                f"| `{op}` | {delay:g} | {on[0]} | {on[1]} / {off[1]} | {on[2]} / {off[2]} |"
            )
            if delay > 0:
                on_total = [a + b for a, b in zip(on_total, on, strict=True)]
                off_total = [a + b for a, b in zip(off_total, off, strict=True)]
        totals[op] = (on_total, off_total)
    lines += [
        "",
        "Delayed runs (delay > 0) in total, with the one-sided Fisher exact p of 'fewer with the "
        "governor':",
        "",
        "| operator | runs per setting | collided, on / off | p | moving contacts, on / off | p |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for op, (on, off) in totals.items():
        if on[0] == 0 or off[0] == 0:
            continue
        lines.append(
            f"| `{op}` | {on[0]} | {on[1]} / {off[1]} | {_fisher_less(on, off, 1):.3f} "
            f"| {on[2]} / {off[2]} | {_fisher_less(on, off, 2):.3f} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m egc_experiments.governor_check", description=__doc__.split("\n")[0]
    )
    parser.add_argument("runs", type=Path, help="runs.jsonl of an experiment")
    args = parser.parse_args(argv)
    try:
        text = args.runs.read_text(encoding="utf-8")
        runs = [json.loads(line) for line in text.splitlines() if line.strip()]
        need = {"operator", "delay_ms", "link_aware", "collided"}
        if not runs or any(not need <= run.keys() for run in runs):
            raise ValueError(f"needs lines with {', '.join(sorted(need))}")
    except (OSError, ValueError) as exc:
        print(f"governor_check: {args.runs}: {exc}", file=sys.stderr)
        return 2
    sys.stdout.write(report(runs))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
