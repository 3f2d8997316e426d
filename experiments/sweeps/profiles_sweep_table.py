"""The table of docs/profiles-sweep.md from profiles_sweep.sh's JSON lines.

python experiments/sweeps/profiles_sweep_table.py docs/profiles-sweep
"""

from __future__ import annotations

import json
import statistics
import sys
from pathlib import Path

SHAPES = (
    ("turtlebot4", "TurtleBot 4 (disc, 0.342 m across)"),
    ("husky", "Husky (0.99 x 0.67 m)"),
    ("pentagon", "pentagon (docs/profiles/pentagon.toml)"),
)
FILTERS = ("egc", "ek-egc", "assist", "cbf", "dwa")
OUTCOMES = ("reached", "stalled", "timeout")


def table(src: Path) -> list[str]:
    lines = [
        "| shape | filter | episodes | collisions | reached | stalled | timeout "
        "| path m (median, max) | min clearance m |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    totals: dict[str, list[int]] = {}
    for tag, label in SHAPES:
        for name in FILTERS:
            path = src / f"{tag}-{name}.jsonl"
            if not path.exists():
                continue
            rows = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
            errors = [r for r in rows if "error" in r]
            runs = [r for r in rows if "error" not in r]
            if not runs:
                continue
            outcome = [sum(r["outcome"] == k for r in runs) for k in OUTCOMES]
            collided = sum(bool(r["collided"]) for r in runs)
            paths = [r["path_m"] for r in runs]
            total = totals.setdefault(tag, [0, 0, 0])
            total[0] += len(runs)
            total[1] += collided
            total[2] += len(errors)
            count = f"{len(runs)}" + (f" (+{len(errors)} errors)" if errors else "")
            lines.append(
                f"| {label} | {name} | {count} | {collided} | "
                + " | ".join(str(n) for n in outcome)
                + f" | {statistics.median(paths):.2f}, {max(paths):.2f} | "
                f"{min(r['min_clearance_m'] for r in runs):.3f} |"
            )
    lines.append("")
    for tag, label in SHAPES:
        if tag in totals:
            n, collided, errors = totals[tag]
            extra = f", {errors} errors" if errors else ""
            lines.append(f"- {label}: {n} episodes, {collided} collisions{extra}")
    return lines


if __name__ == "__main__":
    print("\n".join(table(Path(sys.argv[1]))))
