"""``docs/benchmarks.md`` from ``bench/results/*.json`` (issue 31): one section per benchmark in
``bench/``, each with the machine, the date and the commit it was measured at, and "not run
yet" for a benchmark without a result. ``egc-teleop bench report`` (or ``python -m
egc_experiments.bench_report``) writes the page; running a benchmark through ``egc-teleop
bench`` rewrites it too. The page is never edited by hand: a test renders it again from the
committed results and compares.

``render`` is pure (the results in, the page's text out); ``main`` is the IO around it.
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from egc_experiments.bench_results import PAGE, RESULTS_DIR, ROOT, load_results

Result = Mapping[str, Any]

# What each benchmark measures: a title and a paragraph (the details are in each script's
# docstring, bench/bench_NAME.py). Unknown names get their script's first docstring line.
ABOUT: dict[str, tuple[str, str]] = {
    "filter": (
        "the EGC filter per call",
        "EGC on scans of 360, 720 and 1,440 beams and a 30,000-point RGB-D cloud, with a "
        "command that needs all three nearest-point searches, against a plain per-point Python "
        "loop of the same algorithm in the same run (both checked to agree first); then the "
        "filter family on the same scans, as ratios to EGC's median. Targets: EGC <= 50 us at "
        "720 points and <= 2 ms at 30,000; `ek-egc` <= 2x `egc`. DWA has none: it scores every "
        "candidate velocity against every point in reach, so it grows with the points in reach.",
    ),
    "sim": (
        "the simulator per step",
        "One step on MRPB `office02` (a 360-beam lidar scan, the EGC filter, exact-arc "
        "kinematics, the footprint collision check), Pioneer 3-DX, pinned to one core, steps "
        "per second of CPU time; IR-SIM on the same map and beam count when it is installed "
        "(`pip install ir-sim`, used only here). Targets: >= 2,000 steps/s and >= 20x IR-SIM.",
    ),
    "link": (
        "operator to base over Zenoh",
        "The robot as its own process (`--driver zenoh`), operator and base in the bench "
        "process on one clock, loopback, 50 Hz commands, 720-point scans of a corridor with a "
        "box ahead (the filter modifies nearly every command). In the same run, before and "
        "after, a bare Zenoh echo (`bench/zenoh_echo.py`) over the same two hops with the same "
        "QoS and payload sizes is the baseline. Then operators killed (SIGKILL) and hung "
        "(SIGSTOP): the time to the zero command and to HOLD. Targets: p50 <= 1 ms, p99 <= 5 "
        "ms, p50 <= 1.3x the echo's; SIGKILL -> zero <= 100 ms + the stop from full speed; "
        "SIGSTOP -> HOLD <= command_timeout + 100 ms. What the latency is made of: "
        "[performance notes](performance-notes.md#the-command-path).",
    ),
    "view": (
        "the operator view keeps up",
        "20 Hz telemetry with 720-point scans decoded and logged to the Rerun view as the "
        "operator does, for `--minutes` (10 by default); the lag from arrival to logged per "
        "window. Target: the last window's median lag within 1 ms of the first's and its p99 "
        "under one period (50 ms). Sinks: an `.rrd` file (`view.json`) or the web viewer's "
        "server (`--sink web`, `view-web.json`).",
    ),
    "relay": (
        "the overhead of `egc-teleop link`",
        "64-byte round trips to an echo process on loopback, alternating in one run between "
        "direct, through the relay at delay 0, and through the relay at `delay=5` each way "
        "(lateness: the relay's release time minus the due time, from its `--stats`). Targets: "
        "the relay adds <= 0.3 ms to p50 and <= 1 ms to p99; lateness p99 < 1 ms; nothing lost.",
    ),
    "replay": (
        "`egc-teleop replay` throughput",
        "The whole replay (open the log, deserialise every message, REP 117, the robot's "
        "pipeline, the summary) on 720-beam ROS 2 logs written by the bench (MCAP and sqlite3) "
        "and on `../shared/bags/Mapping1.bag` when it is there, without and with `--record`, "
        "best of `--repeats`. Target: >= 500 scans/s for 720 beams without `--record`.",
    ),
    "ros2": (
        "the ROS 2 driver",
        "A LaserScan published by another process -> the real `Ros2Driver` under the robot's "
        "own node (a cycle on each accepted scan, EGC every cycle) -> the `/cmd_vel` it causes; "
        "beside the in-process simulator's scan -> base command. Target: p99 of the ROS 2 path "
        "under one control period (50 ms). Skipped without rclpy.",
    ),
    "camera": (
        "the camera, CPU and bytes",
        "The simulator's camera at 320x240 and 10 frames/s: render and encode CPU per frame "
        "(one core), what H.264 and JPEG give for 100-1000 kbit/s (JPEG halves its picture "
        "below 0.3 bit/pixel), the operator's decode, and the robot process with and without "
        "the camera. Targets: render <= 5 ms, render + H.264 <= 15 ms a frame, H.264 within 30% "
        "of its target up to 600 kbit/s, no H.264 frame (keyframes too) above 1.5x the target's "
        "frame, keyframes <= 1 s apart, the robot with the camera "
        "<= 25% of a core and <= 150 MB.",
    ),
    "soak": (
        "robot, operator and view for N minutes",
        "A real robot process (`--driver sim`, the simulated camera unless `--camera none`) and "
        "a real operator process (the demo script on a loop, its view served to the web viewer's "
        "buffer) on loopback for `--minutes`; each process's CPU and RSS from /proc every "
        "`--sample-s`, and the view lag from the robot's `view_timeline`, compared between the "
        "first and the last window. Targets: CPU and RSS in the last window within 5% of the "
        "first's, view lag flat (within 20 ms), the robot without a camera <= 10% of a core and "
        "<= 100 MB (with it <= 25% and <= 150 MB). `soak.json` (camera) and `soak-none.json`.",
    ),
    "fleet": (
        "a fleet on one machine",
        "One `egc-teleop router`, N simulated robots (clients of the router, no camera) and M "
        "operators without `--robot`, each starting on its own robot and switching to the next "
        "every `--period-s`, all as their own processes: the time to list the robots (and "
        "`egc-teleop robots --json --wait 1` as typed), each robot's CPU and RSS idle and while "
        "driven, the router's and the operators' CPU, every switch from the press to the first "
        "command the new robot accepted, and how late the robots' control loops ran. Targets: "
        "all N listed, switch time p50 <= 200 ms, every switch done, no control loop late by "
        "more than 50% of its period at the p99. It loads the whole machine: run it alone.",
    ),
    "ros2_teardown": (
        "starting and stopping the ROS 2 driver",
        "The real `Ros2Driver` started and stopped `--cycles` times (200 by default) while another "
        "process publishes scans at 50 Hz and odometry at 100 Hz and records every `/cmd_vel`, "
        "optionally with `--busy N` processes keeping the cores taken and a `--stall-s` stall of "
        "the executor's thread as each stop begins: crashes (a worker killed by a signal), "
        "hangs, and stops whose last `/cmd_vel` was not zero. Targets: none of the three. "
        "Skipped without rclpy.",
    ),
    "bandwidth": (
        "what the robot sends back",
        "A robot process (`--driver sim`) and a scripted operator on loopback at defaults: "
        "messages/s, bytes a message and kbit/s per stream, the robot's CPU and peak RSS; then "
        "the demo through rate-limited downlinks against loopback in the same run. Targets: "
        "view plane <= 1500 kbit/s, robot <= 10% of a core and <= 100 MB; through each rate "
        ">= 80% of the loopback distance, HOLD < 10%, no collision, view age p50 <= delay + "
        "200 ms, command age p99 <= delay + 30 ms.",
    ),
}


def _num(x: Any, digits: int = 2) -> str:
    """A number for a table: fixed digits, thousands separated, '-' for missing or NaN."""
    if x is None or isinstance(x, bool) or not isinstance(x, int | float):
        return "-" if x is None else str(x)
    if isinstance(x, float) and not math.isfinite(x):
        return "-"
    if isinstance(x, int):
        return f"{x:,}"
    return f"{x:,.{digits}f}"


def _table(
    header: Sequence[str], rows: Sequence[Sequence[Any]], text_columns: Sequence[int] = (0,)
) -> list[str]:
    """A Markdown table; numbers right-aligned, the ``text_columns`` left."""
    align = ["---" if i in text_columns else "---:" for i in range(len(header))]
    lines = ["| " + " | ".join(header) + " |", "| " + " | ".join(align) + " |"]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return lines


def targets_of(name: str, r: Result) -> dict[str, bool]:
    """The targets a result says it met or missed, by name."""
    for key in ("targets", "checks"):
        if isinstance(r.get(key), dict):
            return {str(k): bool(v) for k, v in r[key].items()}
    if name == "replay" and "met" in r:
        return {f"720 beams >= {_num(r.get('target_scans_per_s'), 0)} scans/s": bool(r["met"])}
    if name.startswith("view") and "keeps_up" in r:
        return {"keeps up (lag flat, p99 under one period)": bool(r["keeps_up"])}
    if name == "ros2" and "ros2" in r:
        p99, target = r["ros2"].get("p99_ms"), r.get("target_p99_ms")
        if isinstance(p99, int | float) and isinstance(target, int | float):
            return {f"ROS 2 p99 < {target:g} ms": p99 < target}
    if name == "ros2_teardown" and "crashes" in r:
        return {
            "no crash": not r["crashes"],
            "no hang": not r.get("hangs"),
            "every stop's last /cmd_vel zero": not r.get("unclean_stops"),
        }
    if name == "bandwidth" and isinstance(r.get("missed"), list):
        if not r["missed"]:
            return {"all targets": True}
        return {str(m): False for m in r["missed"]}
    return {}


def provenance(r: Result) -> str:
    """One line: when, at which commit, on what, under which load, with which options."""
    run, machine = r.get("run", {}), r.get("machine", {})
    commit = run.get("commit") or "no commit recorded"
    if run.get("dirty"):
        commit += " with local changes"
    load = run.get("load_average") or []
    load_s = " / ".join(f"{x:.2f}" for x in load) if load else "-"
    cores = machine.get("cores")
    usable = machine.get("cores_usable")
    cores_s = f"{cores} cores" if usable in (None, cores) else f"{cores} cores ({usable} usable)"
    options = " ".join(run.get("options") or [])
    bench = str(run.get("bench", "?"))
    # a variant's file (soak-none.json) is written by its benchmark's command (bench soak)
    bench = next((k for k, names in VARIANTS.items() if bench in names), bench)
    command = f"`egc-teleop bench {bench}{' ' + options if options else ''}`"
    return (
        f"Measured {str(run.get('date', '?')).replace('T', ' ').replace('+00:00', ' UTC')} at commit `{commit}` on {machine.get('cpu', '?')} "
        f"({cores_s}, {machine.get('arch', '?')}), Python {machine.get('python', '?')}; load "
        f"average (1 / 5 / 15 min) {load_s} when it finished; {command}."
    )


def _filter(r: Result) -> list[str]:
    rows = [
        [
            x["input"],
            _num(x["points"]),
            _num(x["median_us"], 1),
            _num(x["p95_us"], 1),
            _num(x["loop_median_us"], 1),
            f"{x['speedup']:.1f}x",
        ]
        for x in r["rows"]
    ]
    out = _table(
        ["input", "points", "median us", "p95 us", "Python loop median us", "speed-up"], rows
    )
    family = r.get("family") or []
    if family:
        out += ["", "The filter family on the same scans (ratio to EGC's median in this run):", ""]
        out += _table(
            ["filter", "points", "median us", "p95 us", "ratio to egc", "note"],
            [
                [
                    f["filter"],
                    _num(f["points"]),
                    _num(f["median_us"], 1),
                    _num(f["p95_us"], 1),
                    f"{f['ratio_to_egc']:.1f}x",
                    f.get("note", ""),
                ]
                for f in family
            ],
            text_columns=(0, 5),
        )
    return out


def _sim(r: Result) -> list[str]:
    ours, theirs = r["egc_sim"], r.get("irsim")
    rows = [
        [
            "egc_sim",
            _num(ours["steps"]),
            _num(ours["steps_per_s"], 0),
            _num(ours["us_per_step"], 1),
            _num(ours["wall_steps_per_s"], 0),
        ],
    ]
    if theirs:
        rows.append(
            [
                f"IR-SIM {theirs.get('version', '')}",
                _num(theirs["steps"]),
                _num(theirs["steps_per_s"], 1),
                _num(theirs["us_per_step"], 1),
                _num(theirs["wall_steps_per_s"], 1),
            ]
        )
    out = _table(["simulator", "steps", "steps/s (CPU)", "us/step", "steps/s (wall)"], rows)
    if theirs and r.get("ratio"):
        out += [
            "",
            f"egc_sim is {r['ratio']:.0f}x faster per step by CPU time; the two lidars' "
            f"median range difference on the same map and pose: "
            f"{_num(theirs.get('median_range_difference_m'), 3)} m.",
        ]
    else:
        out += ["", "IR-SIM was not installed for this run: no comparison."]
    return out


def _link(r: Result) -> list[str]:
    lat, echo = r["latency_ms"], r["echo_ms"]
    rows = [
        [
            "operator publish -> base receives the filtered command",
            _num(lat["p50"], 3),
            _num(lat["p90"], 3),
            _num(lat["p99"], 3),
            _num(lat["max"], 3),
        ],
        [
            "bare Zenoh echo over the same two hops",
            _num(echo["p50"], 3),
            _num(echo["p90"], 3),
            _num(echo["p99"], 3),
            _num(echo["max"], 3),
        ],
        ["product / echo", f"{lat['p50_vs_echo']:.2f}x", "", f"{lat['p99_vs_echo']:.2f}x", ""],
    ]
    out = _table(["path (ms)", "p50", "p90", "p99", "max"], rows)
    before, after = r.get("load_average_before"), r.get("load_average_after")
    kill, hold, zero = r["sigkill_to_zero_ms"], r["sigstop_to_hold_ms"], r["sigstop_to_zero_ms"]
    out += [
        "",
        f"{lat['matched']:,} of {lat['commands']:,} commands matched; publish -> the robot's "
        f"cycle start p50 {_num(lat['publish_to_cycle_start_p50'], 3)} ms. Operator SIGKILL -> "
        f"zero command {min(kill):.0f}-{max(kill):.0f} ms; SIGSTOP -> HOLD "
        f"{min(hold):.0f}-{max(hold):.0f} ms, -> zero {min(zero):.0f}-{max(zero):.0f} ms "
        f"({len(kill)} trials each).",
    ]
    if before and after:
        out[-1] += f" Load average (1 min) {before[0]:.2f} -> {after[0]:.2f} over the latency runs."
    return out


def _view(results: Mapping[str, Result]) -> Callable[[Result], list[str]]:
    def render(_: Result) -> list[str]:
        rows = []
        for name in ("view", "view-web"):
            r = results.get(name)
            if r is None:
                continue
            first, last = r["windows"][0], r["windows"][-1]
            rows.append(
                [
                    f"`{r.get('sink', name)}`",
                    f"{r['minutes']:g} min, {r['messages']:,}",
                    f"{_num(first['lag_median_ms'])} -> {_num(last['lag_median_ms'])}",
                    f"{_num(first['lag_p99_ms'], 1)} -> {_num(last['lag_p99_ms'], 1)}",
                    _num(max(w["lag_max_ms"] for w in r["windows"]), 1),
                    f"{100 * r['cpu_share_of_one_core']:.0f}%",
                    f"{_num(first['rss_mb'], 0)} -> {_num(last['rss_mb'], 0)}",
                ]
            )
        return _table(
            [
                "sink",
                "run, messages",
                "median lag ms, first -> last window",
                "p99 lag ms, first -> last",
                "max lag ms",
                "CPU of a core",
                "RSS MB",
            ],
            rows,
        )

    return render


def _relay(r: Result) -> list[str]:
    rows = []
    for proto in ("tcp", "udp"):
        p = r[proto]
        d, rel, dl = p["direct"], p["relay"], p["relay_delay"]
        rows.append(
            [
                f"{proto.upper()}, {p['round_trips']:,} per path",
                f"{_num(d['p50_ms'], 3)} / {_num(d['p99_ms'], 3)}",
                f"{_num(rel['p50_ms'], 3)} / {_num(rel['p99_ms'], 3)} "
                f"(+{_num(p['added_p50_ms'], 3)} / +{_num(p['added_p99_ms'], 3)})",
                f"{_num(dl['p50_ms'], 3)}",
                f"{_num(p['late_p50_ms'], 3)} / {_num(p['late_p99_ms'], 3)}",
            ]
        )
    return _table(
        [
            "round trips",
            "direct p50 / p99 ms",
            "relay p50 / p99 ms (added)",
            "delay 5 each way, p50 ms",
            "lateness at delay 5, p50 / p99 ms",
        ],
        rows,
    )


def _replay(r: Result) -> list[str]:
    rows = [
        [
            x["log"],
            _num(x["beams"]),
            _num(x["scans"]),
            "yes" if x["record"] else "no",
            _num(x["seconds"], 2),
            _num(x["scans_per_s"], 0),
            _num(x["changed"]),
        ]
        for x in r["rows"]
    ]
    head = f"Filter `{r.get('filter', '?')}`, profile `{r.get('profile', '?')}`."
    return [
        head,
        "",
        *_table(["log", "beams", "scans", "--record", "s", "scans/s", "changed"], rows, (0, 3)),
    ]


def _ros2(r: Result) -> list[str]:
    ros, sim = r["ros2"], r["sim"]
    rows = [
        [
            "ROS 2: LaserScan -> /cmd_vel",
            _num(ros["consumed"]),
            _num(ros["p50_ms"]),
            _num(ros["p99_ms"]),
        ],
        [
            "- scan transport (DDS, between processes)",
            "",
            _num(ros["scan_transport_p50_ms"]),
            _num(ros["scan_transport_p99_ms"]),
        ],
        [
            "- arrival -> the cycle that used it",
            "",
            _num(ros["wait_for_cycle_p50_ms"]),
            _num(ros["wait_for_cycle_p99_ms"]),
        ],
        [
            "- cycle + /cmd_vel transport",
            "",
            _num(ros["cycle_and_cmd_transport_p50_ms"]),
            _num(ros["cycle_and_cmd_transport_p99_ms"]),
        ],
        [
            "in-process simulator: scan -> base command",
            _num(sim["consumed"]),
            _num(sim["p50_ms"]),
            _num(sim["p99_ms"]),
        ],
    ]
    return _table(["path", "scans", "p50 ms", "p99 ms"], rows)


def _camera(r: Result) -> list[str]:
    out = _table(
        ["world", "render ms/frame", "core at 10 frames/s"],
        [
            [k, _num(v["ms_per_frame"]), f"{100 * v['core_share_at_10fps']:.1f}%"]
            for k, v in r["render"].items()
        ],
    )
    out += [""]
    out += _table(
        [
            "codec",
            "size",
            "target kbit/s",
            "kbit/s",
            "bytes/frame (key / other)",
            "PSNR dB",
            "encode ms/frame",
        ],
        [
            [
                c["codec"],
                c["size"],
                _num(c["target_kbps"], 0),
                _num(c["kbps"], 0),
                f"{_num(c['keyframe_bytes'], 0)} / {_num(c['other_bytes'], 0)}"
                if c["codec"] == "h264"
                else _num(c["bytes_per_frame"], 0),
                _num(c["psnr_db"], 1),
                _num(c["encode_ms_per_frame"]),
            ]
            for c in r["codecs"]
        ],
        text_columns=(0, 1),
    )
    op = r["operator"]
    out += [
        "",
        f"The operator decodes H.264 in {_num(op['decode_ms_per_frame'])} ms and "
        f"re-encodes it as JPEG for the view in {_num(op['view_jpeg_ms_per_frame'])} ms a "
        f"frame; H.264 costs {r.get('encode_cpu_ratio_h264_to_jpeg', float('nan')):.1f}x "
        "JPEG's CPU at 300 kbit/s.",
    ]
    process = r.get("process")
    if process:
        cam, none = process["camera_sim"], process["camera_none"]
        out[-1] += (
            f" The robot process (`--driver sim`): {100 * cam['core_share']:.1f}% of a core and "
            f"{cam['peak_rss_mb']:.0f} MB with `--camera sim`, {100 * none['core_share']:.1f}% "
            f"and {none['peak_rss_mb']:.0f} MB with `--camera none`."
        )
    return out


def _bandwidth(r: Result) -> list[str]:
    """``bench bandwidth``: the loopback streams with and without the camera, the demo through
    each link (the median of its repeats) and the rate-change scenario."""
    out: list[str] = []
    for camera in ("sim", "none"):
        lb = r.get(f"loopback_camera_{camera}")
        if not lb:
            continue
        out += [f"Loopback, defaults, `--camera {camera}`:", ""]
        out += _table(
            ["stream (robot -> operator)", "msgs/s", "bytes/msg", "kbit/s"],
            [
                [k, _num(s["msgs_per_s"], 1), _num(s["bytes_per_msg"], 0), _num(s["kbps"], 1)]
                for k, s in lb["streams"].items()
            ],
        )
        out += [
            "",
            f"View plane {_num(lb['view_kbps'], 1)} kbit/s; the robot process "
            f"{_num(lb['robot_cpu_pct'], 1)}% of a core, peak RSS "
            f"{_num(lb['robot_rss_mb'], 0)} MB.",
            "",
        ]
    demos = r.get("demo") or {}
    if demos:
        out += ["The demo through each link (the median of its runs):", ""]
        columns = (
            ("distance_share", 3), ("hold_share", 3), ("collisions", 0), ("operator_lost", 0),
            ("view_age_p50_ms", 0), ("cmd_age_p99_ms", 0), ("camera_fps_driving", 1),
            ("camera_age_p50_ms", 0),
        )  # fmt: skip
        rows = []
        for link, runs in demos.items():
            ok = [x for x in runs if "error" not in x]
            row = [link, str(len(ok))]
            for key, digits in columns:
                values = [x[key] for x in ok if x.get(key) is not None]
                row.append(_num(statistics.median(values), digits) if values else "-")
            rows.append(row)
        out += _table(["link", "runs", *(k for k, _ in columns)], rows)
        out += [""]
    scen = r.get("scenario")
    if scen and "back_under_s" in scen:
        rates = scen["rates_kbps"]
        changes = ", ".join(
            f"at {c:g} s to {rates[i + 1]:g} kbit/s: back under the limit after "
            + ("never" if b is None else f"{b:g} s")
            for i, (c, b) in enumerate(zip(scen["changes_s"], scen["back_under_s"], strict=True))
        )
        out += [
            f"Scenario `{scen['file']}` ({' -> '.join(f'{x:g}' for x in rates)} kbit/s): the "
            f"view age's median per second {changes}; the camera in the last phase "
            f"{_num(scen['camera_fps_last_phase'], 1)} frames/s.",
            "",
        ]
    missed = r.get("missed")
    if missed is not None:
        out += ["Targets missed: " + ("; ".join(missed) if missed else "none") + "."]
    return out


def _soak(r: Result) -> list[str]:
    rows = [
        [
            name,
            f"{_num(r[name]['first']['cpu_pct'], 1)} -> {_num(r[name]['last']['cpu_pct'], 1)}",
            f"{_num(r[name]['first']['rss_mb'], 1)} -> {_num(r[name]['last']['rss_mb'], 1)}",
        ]
        for name in ("robot", "operator")
        if name in r
    ]
    lag = r["view_lag_ms"]
    return [
        f"{r['minutes']:g} minutes, camera `{r['camera']}`, windows of {r['window_s']:.0f} s, "
        f"{r['samples']} samples.",
        "",
        *_table(
            ["process", "CPU % of a core, first -> last window", "RSS MB, first -> last"], rows
        ),
        "",
        f"View lag (median of the per-second view ages while driving): {_num(lag['first'], 0)} "
        f"-> {_num(lag['last'], 0)} ms.",
        *_soak_load(r),
    ]


def _soak_load(r: Result) -> list[str]:
    """The machine's load in each window (results from before it was recorded have none)."""
    load = r.get("load_1m")
    if not load:
        return []
    return [
        "",
        f"Load average (1 min) in the windows: {_num(load['first'], 1)} -> "
        f"{_num(load['last'], 1)}; `minutes_series` in the JSON has each minute's figures.",
    ]


def _fleet(r: Result) -> list[str]:
    rows = r["per_robot"]
    idle = [x["cpu_idle"] for x in rows.values()]
    driven = [x["cpu_driven"] for x in rows.values()]
    rss = [x["peak_rss_mb"] for x in rows.values()]
    lt, cli, sw, router = r["list"], r["list_cli"], r["switch_ms"], r["router"]
    listed_ms = None if lt.get("info_s") is None else 1000 * lt["info_s"]
    out = _table(
        ["measure", "value"],
        [
            ["robots, operators", f"{r['robots']}, {r['operators']}"],
            ["all robots' info replies after (ms)", _num(listed_ms, 0)],
            ["`egc-teleop robots --wait 1`: listed, wall s", f"{cli['listed']}, {_num(cli['wall_s'])}"],
            ["robot CPU idle -> driven, mean (% of a core)",
             f"{_num(100 * sum(idle) / len(idle), 1)} -> {_num(100 * sum(driven) / len(driven), 1)}"],
            ["robot peak RSS, mean / max (MB)", f"{_num(sum(rss) / len(rss), 0)} / {_num(max(rss), 0)}"],
            ["router CPU idle -> driven (% of a core)",
             f"{_num(100 * router['cpu_idle'], 1)} -> {_num(100 * router['cpu_driven'], 1)}"],
            ["switches done", f"{sw['n']} of {r['switches_expected']}"],
            ["switch time p50 / p90 / max (ms)", f"{_num(sw['p50'], 0)} / {_num(sw['p90'], 0)} / {_num(sw['max'], 0)}"],
            ["worst control loop lateness p99 (share of its period)",
             _num(max((x["loop_overrun_p99"] or 0.0) for x in rows.values()))],
        ],
        (0, 1),
    )  # fmt: skip
    before, after = r.get("load_average_before"), r.get("load_average_after")
    if before and after:
        out += ["", f"Load average (1 min) {before[0]:.2f} before, {after[0]:.2f} after."]
    return out


def _ros2_teardown(r: Result) -> list[str]:
    return _table(
        ["cycles", "completed", "crashes", "hangs", "unclean stops", "unheard", "close() p50 / max s", "load before -> after"],
        [[_num(r["cycles"]), _num(r["completed"]), _num(len(r["crashes"])), _num(len(r["hangs"])),
          _num(len(r["unclean_stops"])), _num(len(r["unheard"])),
          f"{_num(r['close_p50_s'])} / {_num(r['close_max_s'])}",
          f"{_num(r['load_before'])} -> {_num(r['load_after'])}"]],
    )  # fmt: skip


def _generic(r: Result) -> list[str]:
    """Any other result: its top-level numbers."""
    rows = [
        [f"`{k}`", _num(v, 3)]
        for k, v in r.items()
        if k not in ("run", "machine", "targets") and isinstance(v, int | float)
    ]
    return (
        _table(["key", "value"], rows, (0,))
        if rows
        else ["(no top-level numbers; see the JSON file)"]
    )


def _assist_plan(r: Result) -> list[str]:
    """``bench assist_plan``: assist_step with and without its local planner, call for call."""
    rows = [
        [
            name,
            _num(r[name]["median_ms"], 2),
            _num(r[name]["p95_ms"], 2),
            _num(r[name]["max_ms"], 2),
        ]
        for name in ("planned", "rules")
    ]
    return [
        f"{r['poses']} clutter poses x {r['repeats']} calls (Jackal, 360 beams), the step with "
        "the planner and with the rules alone, alternately:",
        "",
        *_table(["assist_step", "median ms", "p95 ms", "max ms"], rows),
        "",
        f"Planned over rules (medians): {_num(r['ratio_median'], 1)}x.",
    ]


RENDERERS: dict[str, Callable[[Result], list[str]]] = {
    "assist_plan": _assist_plan,
    "filter": _filter,
    "sim": _sim,
    "link": _link,
    "relay": _relay,
    "replay": _replay,
    "ros2": _ros2,
    "camera": _camera,
    "bandwidth": _bandwidth,
    "soak": _soak,
    "fleet": _fleet,
    "ros2_teardown": _ros2_teardown,
}


def heading(name: str, first_line: str) -> str:
    """A section's heading text: the benchmark's name and what it measures."""
    return f"{name}: {ABOUT.get(name, (first_line or name, ''))[0]}"


def anchor(text: str) -> str:
    """GitHub's anchor for a heading: lowercase, punctuation but hyphens and underscores
    dropped, spaces to hyphens."""
    kept = "".join(c for c in text.strip().lower() if c.isalnum() or c in " -_")
    return kept.replace(" ", "-")


# Benchmarks that write one file per variant (``--sink web``, ``--camera none``).
VARIANTS: dict[str, tuple[str, ...]] = {"view": ("view", "view-web"), "soak": ("soak", "soak-none")}


def _rendered(renderer: Callable[[Result], list[str]], r: Result) -> list[str]:
    try:
        return [*renderer(r), ""]
    except (KeyError, TypeError, ValueError, IndexError, AttributeError) as exc:
        return [
            f"The result file does not have the shape this page expects ({exc!r}); its "
            "top-level numbers:",
            "",
            *_generic(r),
            "",
        ]


def _targets_line(targets: Mapping[str, bool]) -> list[str]:
    if not targets:
        return []
    said = "; ".join(f"{k}: {'met' if ok else '**missed**'}" for k, ok in targets.items())
    return [f"Targets: {said}.", ""]


def all_targets(name: str, results: Mapping[str, Result]) -> dict[str, bool]:
    """Every variant's targets, prefixed with the file's name when there are several."""
    files = [n for n in VARIANTS.get(name, (name,)) if n in results]
    found: dict[str, bool] = {}
    for n in files:
        prefix = f"{n}: " if len(files) > 1 else ""
        found |= {prefix + k: v for k, v in targets_of(name, results[n]).items()}
    return found


def _section(name: str, results: Mapping[str, Result], first_line: str) -> list[str]:
    about = ABOUT.get(name, ("", ""))[1]
    out = [f"## {heading(name, first_line)}", ""]
    if about:
        out += [about, ""]
    variants = VARIANTS.get(name, (name,))
    files = [n for n in variants if n in results]
    if not files:
        written = " or ".join(f"`bench/results/{n}.json`" for n in variants)
        return [*out, f"Not run yet: `egc-teleop bench {name}` writes {written}.", ""]
    several = len(files) > 1
    if name == "view":  # one table for both sinks
        for n in files:
            out += [(f"`{n}.json`: " if several else "") + provenance(results[n]), ""]
        out += _rendered(_view(results), results[files[0]])
        return out + _targets_line(all_targets(name, results))
    for n in files:
        r = results[n]
        if several:
            out += [f"`{n}.json`:", ""]
        out += [provenance(r), ""]
        out += _rendered(RENDERERS.get(name, _generic), r)
        out += _targets_line(targets_of(name, r))
    return out


def render(
    results: Mapping[str, Result], benches: Sequence[str], first_lines: Mapping[str, str]
) -> str:
    """The page. ``benches``: the benchmark names in bench/ (each gets a section, run or not);
    ``first_lines``: each script's first docstring line, for names without a description."""
    lines = [
        "# Benchmarks",
        "",
        "<!-- Generated by `egc-teleop bench report` from bench/results/*.json: do not edit. -->",
        "",
        "Generated by `egc-teleop bench report` from the result files in `bench/results/`; a "
        "benchmark run through `egc-teleop bench NAME` rewrites its file and this page. Each "
        "section says what was measured, where, when and at which commit; a benchmark without "
        "a result says so. Timing targets live here, never in the tests: the benchmarks "
        "measure against a baseline in the same run where there is one, and the machine's load "
        "is given because on a shared machine it moves the absolute numbers. What the numbers "
        "mean, and what was tried to improve them: [performance notes](performance-notes.md). "
        "How to run them: [the CLI reference](cli.md#egc-teleop-bench).",
        "",
    ]
    summary = []
    for name in benches:
        found = [results[n] for n in VARIANTS.get(name, (name,)) if n in results]
        r = max(found, key=lambda x: str(x.get("run", {}).get("date", ""))) if found else None
        link = f"[{name}](#{anchor(heading(name, first_lines.get(name, '')))})"
        if r is None:
            summary.append([link, "not run yet", "", ""])
            continue
        t = all_targets(name, results)
        met = f"{sum(t.values())} of {len(t)} met" if t else "-"
        run = r.get("run", {})
        summary.append([link, str(run.get("date", "?"))[:10], f"`{run.get('commit') or '?'}`", met])
    lines += _table(["benchmark", "last run", "commit", "targets"], summary, (0, 1, 2, 3))
    lines += [""]
    for name in benches:
        lines += _section(name, results, first_lines.get(name, ""))
    return "\n".join(lines).rstrip() + "\n"


def available(bench_dir: Path = ROOT / "bench") -> list[str]:
    return sorted(p.stem.removeprefix("bench_") for p in bench_dir.glob("bench_*.py"))


def first_docstring_lines(bench_dir: Path = ROOT / "bench") -> dict[str, str]:
    """Each script's first docstring line without its "Issue N benchmark: " prefix."""
    found = {}
    for path in bench_dir.glob("bench_*.py"):
        text = path.read_text(encoding="utf-8").lstrip()
        line = text.split("\n", 1)[0].strip('"').strip() if text.startswith('"""') else ""
        found[path.stem.removeprefix("bench_")] = line.split("benchmark: ", 1)[-1]
    return found


def page_text(results_dir: Path = RESULTS_DIR, bench_dir: Path = ROOT / "bench") -> str:
    return render(load_results(results_dir), available(bench_dir), first_docstring_lines(bench_dir))


def write_page(out: Path = PAGE, results_dir: Path = RESULTS_DIR) -> Path:
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(page_text(results_dir), encoding="utf-8")
    return out


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m egc_experiments.bench_report", description=__doc__.splitlines()[0]
    )
    parser.add_argument(
        "--results", type=Path, default=RESULTS_DIR, help="result files (default bench/results)"
    )
    parser.add_argument(
        "--out", type=Path, default=PAGE, help="the page (default docs/benchmarks.md)"
    )
    args = parser.parse_args(argv)
    print(f"wrote {write_page(args.out, args.results)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
