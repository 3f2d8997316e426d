"""report.md and the plots of an experiment directory (DESIGN 10), from its runs.jsonl lines.

Every table aggregates runs that share the columns left of the metrics: ``n`` runs, the share
``reached`` / ``collided`` / ``stalled`` / ``timeout`` (percent), the mean ``time`` of the runs
that reached the goal, the mean ``hold`` time and ``hold events`` (the robot not driving while
the operator wanted to move), the mean ``stale`` commands dropped, the mean time the latency
governor ``capped`` the speed, the mean ``speed`` (path / time) and the 10th percentile of the
minimum clearance (``clear p10``).

Sections: overview; against delay (no loss, no outage); against loss (UDP); against outages;
TCP against UDP; per world. A section whose runs are not in the grid is left out. Plots
(``*.png``, matplotlib's Agg backend): outcome, time and hold time against delay, one panel per
operator, one line per mode (filter) and link-aware setting; and, when the grid has them,
outcome against loss (independent and bursty loss, each its own line labelled with its bursts)
and hold time against outage length (one panel per operator and transport). ``write_plots``
removes the plots of ``PLOT_FILES`` it did not write this time (left by an earlier grid in the
same directory), and no other file.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

Row = dict[str, Any]
Key = Callable[[Row], Any]


def _mean(values: Iterable[float | None]) -> float | None:
    xs = [float(v) for v in values if v is not None]
    return sum(xs) / len(xs) if xs else None


def _p10(values: Iterable[float]) -> float | None:
    xs = sorted(float(v) for v in values)
    if not xs:
        return None
    pos = 0.1 * (len(xs) - 1)
    lo = math.floor(pos)
    hi = min(lo + 1, len(xs) - 1)
    return float(xs[lo] + (xs[hi] - xs[lo]) * (pos - lo))


def _pct(rows: Sequence[Row], outcome: str) -> float:
    hits = sum(1 for r in rows if r["outcome"] == outcome)
    return 100.0 * hits / len(rows)


def summarise(rows: Sequence[Row]) -> dict[str, float | int | None]:
    """The metric columns of one group of runs (module docstring)."""
    return {
        "n": len(rows),
        "reached": _pct(rows, "reached"),
        "collided": _pct(rows, "collided"),
        "stalled": _pct(rows, "stalled"),
        "timeout": _pct(rows, "timeout"),
        "time": _mean(r["time_s"] for r in rows if r["outcome"] == "reached"),
        "hold": _mean(r["hold_s"] for r in rows),
        "hold_events": _mean(r["hold_events"] for r in rows),
        "stale": _mean(r["stale_rejected"] for r in rows),
        "capped": _mean(r.get("latency_limited_s", 0.0) for r in rows),
        "speed": _mean(r["mean_speed_mps"] for r in rows),
        "clear_p10": _p10(r["min_clearance_m"] for r in rows),
    }


METRIC_HEADERS = (
    ("n", "n", "{:d}"),
    ("reached", "reached %", "{:.0f}"),
    ("collided", "collided %", "{:.0f}"),
    ("stalled", "stalled %", "{:.0f}"),
    ("timeout", "timeout %", "{:.0f}"),
    ("time", "time s", "{:.1f}"),
    ("hold", "hold s", "{:.1f}"),
    ("hold_events", "hold events", "{:.1f}"),
    ("stale", "stale", "{:.0f}"),
    ("capped", "capped s", "{:.1f}"),
    ("speed", "speed m/s", "{:.3f}"),
    ("clear_p10", "clear p10 m", "{:.2f}"),
)


def setting(row: Row) -> str:
    """``direct`` or ``shared (egc)``: the mode with the filter that runs in it."""
    return row["mode"] if row["mode"] == "direct" else f"{row['mode']} ({row['filter']})"


def link_aware(row: Row) -> str:
    """``on``, ``off``, or ``speed cap`` (on, without the governor's turn-rate cap)."""
    if not row.get("link_aware", True):
        return "off"
    return "on" if row.get("latency_turn_cap", True) else "speed cap"


def outage_s(row: Row) -> float:
    return float(sum(d for _, d in row.get("outages") or []))


def jitter_pct(row: Row) -> float | None:
    """The jitter as a percentage of the delay; None (shown ``-``) at delay 0, where it has no
    meaning. The tables show the jitter in ms (``COLUMNS["jitter"]``)."""
    return round(100.0 * row["jitter_ms"] / row["delay_ms"]) if row["delay_ms"] else None


def burst_label(row: Row) -> str:
    """``bursts of N`` (Gilbert-Elliott loss, mean burst length N) or ``independent``."""
    return f"bursts of {row['burst']:g}" if row["burst"] > 1 else "independent"


def loss_label(row: Row) -> str:
    if not row["loss"]:
        return "0"
    return f"{row['loss']:g}" + (f" ({burst_label(row)})" if row["burst"] > 1 else "")


COLUMNS: dict[str, tuple[str, Key]] = {
    "operator": ("operator", lambda r: r["operator"]),
    "setting": ("mode", setting),
    "link_aware": ("link-aware", link_aware),
    "delay": ("delay ms", lambda r: r["delay_ms"]),
    # In ms, not as a share of the delay: a percentage is meaningless at delay 0 (it showed 0
    # there, for any jitter, and grouped jittered runs at delay 0 with unjittered ones).
    "jitter": ("jitter ms", lambda r: r["jitter_ms"]),
    "loss": ("loss %", loss_label),
    "outage": ("outage s", outage_s),
    "transport": ("transport", lambda r: r["transport"]),
    "world": ("world", lambda r: r["world"]),
}


def _fmt(value: Any, spec: str = "{}") -> str:
    if value is None:
        return "-"
    if isinstance(value, float) and spec == "{}":
        return f"{value:g}"
    return spec.format(value)


def _sort_key(value: Any) -> tuple[int, Any]:
    if isinstance(value, int | float):
        return (0, value)
    return (1, str(value))


def table(rows: Sequence[Row], columns: Sequence[str]) -> str:
    """A markdown table: one line per distinct value of ``columns``, metrics after them."""
    groups: dict[tuple[Any, ...], list[Row]] = defaultdict(list)
    for r in rows:
        groups[tuple(COLUMNS[c][1](r) for c in columns)].append(r)
    heads = [COLUMNS[c][0] for c in columns] + [h for _, h, _ in METRIC_HEADERS]
    lines = ["| " + " | ".join(heads) + " |", "|" + "|".join("---" for _ in heads) + "|"]
    for key in sorted(groups, key=lambda k: tuple(_sort_key(v) for v in k)):
        stats = summarise(groups[key])
        cells = [_fmt(v) for v in key] + [_fmt(stats[m], f) for m, _, f in METRIC_HEADERS]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _plain_link(r: Row) -> bool:
    return not r["loss"] and not r.get("outages")


def subsets(rows: Sequence[Row]) -> dict[str, list[Row]]:
    """The runs each section of the report looks at."""
    return {
        "delay": [r for r in rows if _plain_link(r)],
        "loss": [r for r in rows if r["transport"] == "udp" and not r.get("outages")],
        "outage": outage_comparison(rows),
    }


def transport_pairs(rows: Sequence[Row]) -> list[Row]:
    """Runs without loss whose point the grid ran on both TCP and UDP."""

    def point(r: Row) -> tuple[Any, ...]:
        return tuple(
            repr(r.get(k))
            for k in (
                "world", "operator", "filter", "mode", "delay_ms", "jitter_ms", "dist",
                "outages", "seed", "link_aware", "profile", "start", "goal",
            )
        )  # fmt: skip

    transports: dict[tuple[Any, ...], set[str]] = defaultdict(set)
    for r in rows:
        if not r["loss"]:
            transports[point(r)].add(r["transport"])
    return [r for r in rows if not r["loss"] and transports[point(r)] >= {"tcp", "udp"}]


def outage_comparison(rows: Sequence[Row]) -> list[Row]:
    """Runs without loss at the (delay, jitter) points that the grid also ran with outages."""
    with_outage = {(r["delay_ms"], r["jitter_ms"]) for r in rows if r.get("outages")}
    return [r for r in rows if not r["loss"] and (r["delay_ms"], r["jitter_ms"]) in with_outage]


def _varies(rows: Sequence[Row], key: Key) -> bool:
    return len({key(r) for r in rows}) > 1


def key_numbers(rows: Sequence[Row]) -> str:
    """reached / collided / hold for link-aware on and off at 200 and 500 ms, per mode."""
    plain = [r for r in rows if _plain_link(r) and not r["jitter_ms"]]
    lines = [
        "| operator | delay ms | mode | link-aware | n | reached % | collided % | hold s |",
        "|---|---|---|---|---|---|---|---|",
    ]
    found = False
    for op in sorted({r["operator"] for r in plain}):
        for delay in (200.0, 500.0):
            for mode in sorted({setting(r) for r in plain}):
                for aware in ("on", "speed cap", "off"):
                    group = [
                        r
                        for r in plain
                        if r["operator"] == op
                        and r["delay_ms"] == delay
                        and setting(r) == mode
                        and link_aware(r) == aware
                    ]
                    if not group:
                        continue
                    found = True
                    s = summarise(group)
                    lines.append(
                        f"| {op} | {delay:g} | {mode} | {aware} | {s['n']} | "
                        f"{_fmt(s['reached'], '{:.0f}')} | {_fmt(s['collided'], '{:.0f}')} | "
                        f"{_fmt(s['hold'], '{:.1f}')} |"
                    )
    return "\n".join(lines) if found else ""


def write_report(
    rows: Sequence[Row],
    path: Path,
    title: str,
    description: str = "",
    command: str = "",
    plots: Sequence[str] = (),
) -> None:
    """report.md (module docstring); written to a temporary file first, then renamed."""
    rows = list(rows)
    parts = [f"# {title}", ""]
    if description:
        parts += [description.strip(), ""]
    if command:
        parts += ["Made with:", "", "```", command, "```", ""]
    parts += [
        f"{len(rows)} runs. Delay, jitter and loss apply to each direction (the round trip is "
        "twice the delay). Columns: see `egc_experiments.report`; `time s` is the mean over "
        "the runs that reached the goal, `hold s` the time the robot did not drive while the "
        "operator wanted to, `capped s` the time the latency governor limited the speed.",
        "",
    ]
    if not rows:
        path.write_text("\n".join([*parts, "No runs yet."]) + "\n", encoding="utf-8")
        return
    by_op = ["operator"] if _varies(rows, COLUMNS["operator"][1]) else []
    sections: list[tuple[str, str]] = [("Overview", table(rows, [*by_op, "setting", "link_aware"]))]
    numbers = key_numbers(rows)
    if numbers:
        sections.append(("Key numbers (no loss, no outage, no jitter)", numbers))
    sub = subsets(rows)
    if _varies(sub["delay"], COLUMNS["delay"][1]):
        cols = [*by_op, "delay"]
        if _varies(sub["delay"], COLUMNS["jitter"][1]):
            cols.append("jitter")
        if _varies(sub["delay"], COLUMNS["transport"][1]):
            cols.append("transport")
        sections.append(
            (
                "Against delay (no loss, no outage)",
                table(sub["delay"], [*cols, "setting", "link_aware"]),
            )
        )
    if _varies(sub["loss"], COLUMNS["loss"][1]):
        cols = [*by_op, "loss"]
        if _varies(sub["loss"], COLUMNS["delay"][1]):
            cols.append("delay")
        sections.append(
            ("Against loss (UDP, no outage)", table(sub["loss"], [*cols, "setting", "link_aware"]))
        )
    if sub["outage"]:
        sections.append(
            (
                "Against outages (one outage, both directions; no loss)",
                table(sub["outage"], [*by_op, "outage", "transport", "setting", "link_aware"]),
            )
        )
    paired = transport_pairs(rows)
    if paired:
        sections.append(
            (
                "TCP against UDP (the same points on both; no loss)",
                table(paired, [*by_op, "transport", "delay", "outage", "setting", "link_aware"]),
            )
        )
    if _varies(rows, COLUMNS["world"][1]):
        sections.append(("Per world", table(rows, ["world", *by_op, "setting", "link_aware"])))
    for heading, body in sections:
        parts += [f"## {heading}", "", body, ""]
    if plots:
        parts += ["## Plots", ""]
        parts += [f"![{name}]({name})" for name in plots]
        parts.append("")
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text("\n".join(parts), encoding="utf-8")
    tmp.replace(path)


def _series(
    rows: Sequence[Row],
    x: Key,
    y: Callable[[Sequence[Row]], float | None],
    variants: Callable[[Row], Sequence[str]] = lambda r: ("",),
) -> dict[tuple[str, str, str], list[tuple[float, float]]]:
    """One line per mode, link-aware setting and variant; a row can be on the lines of several
    variants (the loss-free runs start the line of each kind of loss)."""
    groups: dict[tuple[str, str, str, float], list[Row]] = defaultdict(list)
    for r in rows:
        for variant in variants(r):
            groups[(setting(r), link_aware(r), variant, float(x(r)))].append(r)
    out: dict[tuple[str, str, str], list[tuple[float, float]]] = defaultdict(list)
    for (mode, aware, variant, xv), group in sorted(groups.items()):
        value = y(group)
        if value is not None:
            out[(mode, aware, variant)].append((xv, value))
    return out


def _figure(
    rows: Sequence[Row],
    x: Key,
    xlabel: str,
    panels: Sequence[tuple[str, Callable[[Sequence[Row]], float | None]]],
    path: Path,
    title: str,
    facet: Key = lambda r: r["operator"],
    variants: Callable[[Row], Sequence[str]] = lambda r: ("",),
) -> bool:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    operators = sorted({facet(r) for r in rows})
    if not rows or len({x(r) for r in rows}) < 2:
        return False
    fig, axes = plt.subplots(
        len(panels),
        len(operators),
        figsize=(max(7.0, 4.8 * len(operators)), 3.2 * len(panels) + 0.6),
        squeeze=False,
        sharex=True,
    )
    styles = {"on": "-", "off": "--"}
    palette = ["tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple"]
    modes = sorted({setting(r) for r in rows})
    colours = {m: palette[i % len(palette)] for i, m in enumerate(modes)}
    kinds = sorted({v for r in rows for v in variants(r)})
    markers = {v: "osD^vP"[i % 6] for i, v in enumerate(kinds)}
    for col, op in enumerate(operators):
        op_rows = [r for r in rows if facet(r) == op]
        for row_i, (ylabel, fn) in enumerate(panels):
            ax = axes[row_i][col]
            for (mode, aware, kind), points in sorted(_series(op_rows, x, fn, variants).items()):
                colour = colours[mode]
                xs, ys = zip(*points, strict=True)
                ax.plot(
                    xs,
                    ys,
                    styles.get(aware, ":"),
                    color=colour,
                    marker=markers[kind],
                    markersize=3,
                    label=f"{mode}, link-aware {aware}" + (f", {kind}" if kind else ""),
                )
            ax.set_ylabel(ylabel)
            if ylabel.endswith("%"):
                ax.set_ylim(-3, 103)
            ax.grid(True, alpha=0.3)
            if row_i == 0:
                ax.set_title(op)
            if row_i == len(panels) - 1:
                ax.set_xlabel(xlabel)
    legend: dict[str, Any] = {}
    for ax in axes.flat:
        for handle, label in zip(*ax.get_legend_handles_labels(), strict=True):
            legend.setdefault(label, handle)
    labels = sorted(legend)
    handles = [legend[label] for label in labels]
    if handles:
        fig.legend(handles, labels, loc="lower center", ncol=2, fontsize=8)
    fig.suptitle(title)
    # Room under the axes for the legend's rows (about 0.2 in each at 8 pt), so that it does not
    # cover the x axis's label.
    legend_rows = math.ceil(len(handles) / 2)
    bottom = min(0.5, (0.15 + 0.2 * legend_rows) / fig.get_figheight()) if handles else 0.02
    fig.tight_layout(rect=(0, bottom, 1, 0.97))
    tmp = path.with_name(path.stem + ".tmp.png")
    fig.savefig(tmp, dpi=100)
    plt.close(fig)
    tmp.replace(path)
    return True


def _rate(outcome: str) -> Callable[[Sequence[Row]], float]:
    return lambda g: _pct(g, outcome)


# Every file write_plots may write (and the temporary it writes each through).
PLOT_FILES = (
    "outcome_vs_delay.png",
    "time_vs_delay.png",
    "hold_vs_delay.png",
    "outcome_vs_loss.png",
    "hold_vs_outage.png",
)


def least_jitter_per_delay(rows: Sequence[Row]) -> tuple[list[Row], str]:
    """The runs at each delay with the least jitter there, and how to say which these are.

    A grid without jitter-free runs (every delay point jittered) still gets its plots against
    delay; an outside check's grid with jitter 20 ms throughout got none.
    """
    delay: Key = COLUMNS["delay"][1]
    least: dict[Any, float] = {}
    for r in rows:
        d = delay(r)
        least[d] = min(least.get(d, math.inf), r["jitter_ms"] or 0.0)
    kept = [r for r in rows if (r["jitter_ms"] or 0.0) == least[delay(r)]]
    jitters = sorted(set(least.values()))
    if jitters in ([], [0.0]):
        return kept, "no jitter"
    if len(jitters) == 1:
        return kept, f"jitter {jitters[0]:g} ms"
    return kept, "the least jitter at each delay"


def loss_kinds(rows: Sequence[Row]) -> Callable[[Row], Sequence[str]]:
    """The loss plot's lines of a row: its kind of loss (``burst_label``), and every kind in
    ``rows`` for a loss-free row (loss 0 is where each line starts). Empty labels when all the
    loss is independent (then the axis says so)."""
    kinds = sorted({burst_label(r) for r in rows if r["loss"]})
    if kinds in ([], ["independent"]):
        return lambda r: ("",)
    return lambda r: (burst_label(r),) if r["loss"] else tuple(kinds)


def remove_stale_plots(out_dir: Path, written: Sequence[str]) -> list[str]:
    """Remove the plots of ``PLOT_FILES`` (and their temporaries) that this report did not
    write: an earlier grid's, run into the same directory. No other file is touched. Returns
    the names removed."""
    removed = []
    for name in PLOT_FILES:
        for stale in (name, Path(name).stem + ".tmp.png"):
            path = out_dir / stale
            if stale in written or not (path.is_file() or path.is_symlink()):
                continue
            path.unlink(missing_ok=True)
            removed.append(stale)
    return removed


def write_plots(rows: Sequence[Row], out_dir: Path) -> list[str]:
    """The plots of the module docstring; returns the file names written. The other plots of
    ``PLOT_FILES`` are removed (``remove_stale_plots``)."""
    written: list[str] = []
    plain, jitter_note = least_jitter_per_delay([r for r in rows if _plain_link(r)])
    delay: Key = COLUMNS["delay"][1]
    lossy = [r for r in rows if r["transport"] == "udp" and not r.get("outages")]
    kinds = loss_kinds(lossy)
    bursty = any(r["loss"] and r["burst"] > 1 for r in lossy)
    figures: list[tuple[str, Sequence[Row], Key, str, list[Any], str]] = [
        (
            "outcome_vs_delay.png",
            plain,
            delay,
            "one-way delay (ms)",
            [("reached %", _rate("reached")), ("collided %", _rate("collided"))],
            f"Outcome against delay (no loss, {jitter_note})",
        ),
        (
            "time_vs_delay.png",
            plain,
            delay,
            "one-way delay (ms)",
            [
                (
                    "time to goal (s)",
                    lambda g: _mean(r["time_s"] for r in g if r["outcome"] == "reached"),
                )
            ],
            f"Time to the goal against delay (runs that reached it; {jitter_note})",
        ),
        (
            "hold_vs_delay.png",
            plain,
            delay,
            "one-way delay (ms)",
            [("hold time (s)", lambda g: _mean(r["hold_s"] for r in g))],
            f"Time held while the operator wanted to drive, against delay ({jitter_note})",
        ),
        (
            "outcome_vs_loss.png",
            lossy,
            lambda r: r["loss"],
            "loss (%), each direction" if bursty else "loss (%), independent, each direction",
            [
                ("reached %", _rate("reached")),
                ("hold time (s)", lambda g: _mean(r["hold_s"] for r in g)),
            ],
            "Outcome and hold time against loss (UDP)",
        ),
        (
            "hold_vs_outage.png",
            outage_comparison(rows),
            outage_s,
            "outage (s)",
            [
                ("hold time (s)", lambda g: _mean(r["hold_s"] for r in g)),
                ("reached %", _rate("reached")),
            ],
            "Hold time and outcome against the length of one outage",
        ),
    ]
    facets: dict[str, Key] = {
        "hold_vs_outage.png": lambda r: f"{r['operator']}, {r['transport'].upper()}",
    }
    lines: dict[str, Callable[[Row], Sequence[str]]] = {"outcome_vs_loss.png": kinds}
    for name, subset, x, xlabel, panels, title in figures:
        if name == "hold_vs_outage.png" and not any(r.get("outages") for r in subset):
            continue
        if name == "outcome_vs_loss.png" and not any(r["loss"] for r in subset):
            continue
        assert name in PLOT_FILES, name
        facet = facets.get(name, COLUMNS["operator"][1])
        variants = lines.get(name, lambda r: ("",))
        if _figure(subset, x, xlabel, panels, out_dir / name, title, facet, variants):
            written.append(name)
    remove_stale_plots(out_dir, written)
    return written
