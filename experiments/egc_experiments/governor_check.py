"""Does the latency governor make an operator collide less? A table from an experiment's runs.

Reads ``runs.jsonl`` of an experiment with ``link_aware`` on and off (e.g.
``experiments/grids/governor-jackal.toml``) and prints, per operator and one-way delay, the
collisions with link-aware driving (and so the governor, DESIGN 9) on and off, and how many of
them happened while the robot was moving (``contact_speed_mps`` above ``MOVING_MPS``; a contact
at v = 0 is a turn in place, which no speed cap can prevent). The totals over the delayed runs
(delay > 0) come with a one-sided Fisher exact test (scipy) of "fewer collisions with the
governor", so that a difference of a few runs is not read as an effect. Runs with
``latency_turn_cap`` false (the governor's speed cap alone) are a third arm, compared with both::

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

from egc_experiments.report import link_aware

MOVING_MPS: Final = 0.05


def _count(runs: Iterable[dict[str, Any]]) -> dict[tuple[str, float, str], list[int]]:
    """(operator, delay, arm) -> [runs, collided, collided while moving]; the arm is
    ``report.link_aware``: on, ``speed cap`` (on without the turn-rate cap) or off."""
    table: dict[tuple[str, float, str], list[int]] = defaultdict(lambda: [0, 0, 0])
    for run in runs:
        cell = table[(run["operator"], float(run["delay_ms"]), link_aware(run))]
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


def _compare(table: dict[tuple[str, float, str], list[int]], arm: str, other: str) -> str:
    """Per operator and delay, ``arm`` against ``other``; totals over delay > 0 with Fisher."""
    operators = sorted({key[0] for key in table})
    delays = sorted({key[1] for key in table})
    lines = [
        f"| operator | one-way delay ms | runs | collided, {arm} / {other} "
        f"| of them moving, {arm} / {other} |",
        "|---|---:|---:|---:|---:|",
    ]
    totals: dict[str, tuple[list[int], list[int]]] = {}
    for op in operators:
        a_total, b_total = [0, 0, 0], [0, 0, 0]
        for delay in delays:
            a, b = table.get((op, delay, arm)), table.get((op, delay, other))
            if a is None or b is None:
                continue
            lines.append(f"| `{op}` | {delay:g} | {a[0]} | {a[1]} / {b[1]} | {a[2]} / {b[2]} |")
            if delay > 0:
                a_total = [x + y for x, y in zip(a_total, a, strict=True)]
                b_total = [x + y for x, y in zip(b_total, b, strict=True)]
        totals[op] = (a_total, b_total)
    lines += [
        "",
        "Delayed runs (delay > 0) in total, with the one-sided Fisher exact p of 'fewer with "
        f"{arm} than {other}':",
        "",
        f"| operator | runs per setting | collided, {arm} / {other} | p "
        f"| moving contacts, {arm} / {other} | p |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for op, (a, b) in totals.items():
        if a[0] == 0 or b[0] == 0:
            continue
        lines.append(
            f"| `{op}` | {a[0]} | {a[1]} / {b[1]} | {_fisher_less(a, b, 1):.3f} "
            f"| {a[2]} / {b[2]} | {_fisher_less(a, b, 2):.3f} |"
        )
    return "\n".join(lines) + "\n"


def report(runs: list[dict[str, Any]]) -> str:
    """The markdown tables (module docstring): the governor on against off and, when the runs
    have them, the speed cap alone against off and the full governor against the speed cap."""
    table = _count(runs)
    arms = {key[2] for key in table}
    parts = [_compare(table, "on", "off")]
    if "speed cap" in arms:
        parts.append(_compare(table, "speed cap", "off"))
        parts.append(_compare(table, "on", "speed cap"))
    return "\n".join(parts)


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
