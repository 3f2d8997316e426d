"""docs/cbf-sweep.md from cbf_sweep.sh's three parts (arena, delay, clutter).

python experiments/sweeps/cbf_sweep_table.py docs/cbf-sweep > docs/cbf-sweep.md
"""

from __future__ import annotations

import json
import sys
from collections.abc import Iterable
from pathlib import Path

OUTCOMES = ("reached", "collided", "stalled", "timeout")


def read(path: Path) -> list[dict]:
    if not path.exists():
        return []
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def outcome_row(label: str, runs: list[dict]) -> str:
    counts = [
        sum(r.get("outcome") == k or (k == "collided" and r.get("collided")) for r in runs)
        for k in OUTCOMES
    ]
    clear = min(
        (r["min_clearance_m"] for r in runs if "min_clearance_m" in r), default=float("nan")
    )
    return f"| {label} | {len(runs)} | " + " | ".join(map(str, counts)) + f" | {clear:.3f} |"


def header(first: str) -> list[str]:
    return [
        f"| {first} | episodes | " + " | ".join(OUTCOMES) + " | min clearance m |",
        "|---|" + "---:|" * (len(OUTCOMES) + 2),
    ]


def groups(runs: Iterable[dict], *keys: str) -> dict[tuple, list[dict]]:
    out: dict[tuple, list[dict]] = {}
    for r in runs:
        out.setdefault(tuple(r.get(k) for k in keys), []).append(r)
    return dict(sorted(out.items(), key=lambda kv: tuple(str(v) for v in kv[0])))


def page(src: Path) -> list[str]:
    arena = read(src / "arena" / "runs.jsonl")
    delay = read(src / "delay" / "runs.jsonl")
    clutter = read(src / "clutter" / "runs.jsonl")
    parts = {"arena": arena, "delay": delay, "clutter": clutter}
    lines = [
        "# cbf through 2,000+ held-out episodes (issue 28)",
        "",
        "Made by `experiments/sweeps/cbf_sweep.sh` (episodes) and "
        f"`python experiments/sweeps/cbf_sweep_table.py {src}` (this page). Every world and seed "
        "is held out: cbf's parameters were set on random seeds 0-999 and 1000-1019; this sweep "
        "uses random seeds 8000-8599 and clutter seeds 9100-9699. Jackal unless the arena's "
        "suite says otherwise (hallway and MRPB: Pioneer 3-DX).",
        "",
        "## Collisions",
        "",
        "| part | filter | episodes | collisions |",
        "|---|---|---:|---:|",
    ]
    total: dict[str, list[int]] = {}
    for part, runs in parts.items():
        for (name,), rows in groups(runs, "filter").items():
            hit = sum(bool(r.get("collided")) for r in rows)
            lines.append(f"| {part} | {name} | {len(rows)} | {hit} |")
            acc = total.setdefault(name, [0, 0])
            acc[0] += len(rows)
            acc[1] += hit
    for name, (n, hit) in sorted(total.items()):
        lines.append(f"| **all** | {name} | **{n}** | **{hit}** |")
    lines += [
        "",
        "## 1. The arena: goal and sighted operators, egc against cbf",
        "",
        f"{len(arena)} episodes; the arena's own report: [arena/report.md]"
        "(cbf-sweep/arena/report.md).",
        "",
    ]
    lines += header("suite, operator, filter")
    for (suite, op, name), rows in groups(arena, "suite", "operator", "filter").items():
        lines.append(outcome_row(f"{suite}, {op}, {name}", rows))
    lines += [
        "",
        "## 2. The sighted operator through delay (cbf, link-aware driving on)",
        "",
        f"{len(delay)} episodes, random seeds 8500-8599 at each one-way delay; the "
        "experiment's report: [delay/report.md](cbf-sweep/delay/report.md).",
        "",
    ]
    lines += header("one-way delay ms")
    for (ms,), rows in groups(delay, "delay_ms").items():
        lines.append(outcome_row(f"{ms:.0f}", rows))
    lines += [
        "",
        "## 3. Dense clutter: cbf and the goal operator",
        "",
        f"{len(clutter)} episodes on `clutter:9100-9699` (gaps 1.2-1.5x the robot's width; "
        "the straight line to the goal is always blocked). The goal operator steers "
        "straight at the goal, into the clutter: what this part shows is that cbf stops "
        "it without contact, not that it arrives.",
        "",
    ]
    lines += header("filter")
    for (name,), rows in groups(clutter, "filter").items():
        lines.append(outcome_row(name, rows))
    return lines


if __name__ == "__main__":
    print("\n".join(page(Path(sys.argv[1] if len(sys.argv) > 1 else "docs/cbf-sweep"))))
