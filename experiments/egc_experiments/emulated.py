"""``--mode emulated`` (DESIGN 10): one run of a grid point with the real processes over real
Zenoh, through ``egc-teleop link``.

The processes, each started as its own OS process:

- the robot: ``egc-teleop robot --driver sim`` with the point's world, start, profile and filter
  (and ``--no-link-aware`` when the point says so), ``--set sim.seed=SEED`` and
  ``--set pipeline.no_return_is_free=true`` (the simulated mode's pipeline), ``--summary``;
  it listens on the link endpoint (the point's ``transport``) and on a local TCP endpoint for
  the recorder;
- the recorder (``egc_experiments.watch``) next to the robot, on that local endpoint: every
  telemetry message as the robot sent it, never through the link;
- ``egc-teleop link`` with the point's SPEC (``RunPoint.link_spec()``) in both directions and
  its seed, between the operator side and the robot's link endpoint;
- the operator: ``egc_experiments.operator_model``, the operator process (``OperatorNode``)
  with the point's operator model in place of the joystick and the simulated mode's operator
  logic (``simulated.OperatorSide``), connected to the relay only.

With root and a working ``ip netns`` (``egc_experiments.netns``), the robot and its recorder run
in a robot namespace, the relay in a middle one and the operator in an operator one (two hosts
on one machine, veth pairs, no way around the relay); otherwise everything runs on loopback
with free ports. TCP cannot lose packets in the relay (a lost chunk of a byte stream is an
error): a TCP point with ``loss`` runs only in namespaces with ``nft``, where the loss is the
kernel's (``TwoHosts.set_loss``) and the relay adds the delays; elsewhere it is refused. A UDP
point uses our ``udp/`` transport (a TCP link for Zenoh's reliable traffic and a best-effort UDP
link on one port number, ``egc_common.transport``; the relay carries both, dropping only UDP
datagrams); in namespaces with ``nft`` its TCP half loses packets in the kernel at the point's
rate too. ``point.extra["udp"]`` = ``"plain"`` or ``"mixed"`` runs Zenoh's UDP link alone
(``rel=0``) or its mixed-reliability QUIC instead, for docs/transport.md.

The run ends, judged from the recorder's telemetry on the robot's clock (the same monotonic
clock for every process of the machine) as the simulated mode judges its simulator: ``reached``
(the robot's pose within the world's goal tolerance), ``collided`` (the footprint's clearance
at the reported pose below ``CONTACT_M``; the robot's own summary counts the simulator's
contacts and has the last word), ``stalled`` (no 0.1 m of progress for ``stall_time_s``) or
``timeout`` (``max_time_s``). Time 0 is the operator model's first stick (the simulated mode's
t = 0, when the operator starts and the robot is waiting); the start-up of the processes before
it is not counted.

Metrics (``RESULT_KEYS`` and more), where the simulated mode counts 20 Hz cycles the emulated
one weighs each telemetry message by the time to the next (the robot also runs a cycle when a
command arrives, so its cycles are not evenly spaced):

- ``hold_s`` / ``hold_events``: time, and stretches, in which the robot was in HOLD or IDLE
  after it first drove while the operator model wanted to move (its intent, recorded by the
  operator process with monotonic times);
- ``interventions``: time limited by a filter or the sweep (``INTERVENING_NAMES``), in 50 ms
  cycles;
- ``path_m``, ``min_clearance_m`` (the footprint's clearance at the reported poses, capped at
  1 m, 0 after a contact), ``mean_speed_mps``: from the recorded poses between t = 0 and the end;
- ``cmd_age_p50_ms`` / ``cmd_age_p99_ms`` and ``stale_rejected``: the robot's own summary (its
  accepted commands' ages on its clock; commands dropped as too old);
- ``emulated``: ``netns`` or ``loopback``; ``link``: the relay's per-direction counts.
"""

from __future__ import annotations

import bisect
import contextlib
import dataclasses
import json
import math
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any, Final

import numpy as np
from egc_common.profiles import get_profile
from egc_common.transport import free_port
from egc_robot.pipeline import INTERVENING_NAMES
from egc_sim.collision import FootprintChecker
from egc_sim.worlds import load_world

from egc_experiments import netns
from egc_experiments.run_point import RESULT_KEYS, RunPoint

NS_PER_S: Final = 1_000_000_000
ROBOT_ID: Final = "emu"
OPERATOR_ID: Final = "emu-operator"
DEFAULT_GOAL_TOLERANCE_M: Final = 0.3  # as the simulated mode
STALL_DISTANCE_M: Final = 0.1
CONTACT_M: Final = 0.01  # the simulator stops a contact within a bisection of the obstacle
CYCLE_S: Final = 0.05  # the simulated mode's control period
LINK_PORT: Final = 7447
WATCH_PORT: Final = 7448
START_TIMEOUT_S: Final = 30.0


class EmulationError(RuntimeError):
    """A process did not start or died; the message has the end of its log."""


# -- where the processes run ------------------------------------------------------------------


@dataclass
class Hosts:
    """Start processes on the operator, middle or robot side: in namespaces or on loopback."""

    workdir: Path
    net: netns.TwoHosts | None = None
    children: dict[str, subprocess.Popen[bytes]] = field(default_factory=dict)

    @property
    def kind(self) -> str:
        return "loopback" if self.net is None else "netns"

    def start(self, name: str, side: str, argv: Sequence[str]) -> subprocess.Popen[bytes]:
        env = dict(os.environ, PYTHONUNBUFFERED="1", PYTHONFAULTHANDLER="1")
        with (self.workdir / f"{name}.log").open("wb") as out:
            if self.net is None:
                proc = subprocess.Popen(
                    list(argv),
                    stdout=out,
                    stderr=subprocess.STDOUT,
                    stdin=subprocess.DEVNULL,
                    cwd=self.workdir,
                    env=env,
                )
            else:
                proc = self.net.popen(
                    side, argv, stdout=out, stderr=subprocess.STDOUT, cwd=self.workdir, env=env
                )
        self.children[name] = proc
        return proc

    def log(self, name: str) -> str:
        path = self.workdir / f"{name}.log"
        return path.read_text(errors="replace") if path.exists() else ""

    def wait_log(self, name: str, text: str, timeout_s: float = START_TIMEOUT_S) -> None:
        deadline = time.monotonic() + timeout_s
        while text not in self.log(name):
            if self.children[name].poll() is not None:
                raise EmulationError(f"{name} exited {self.children[name].returncode}: "
                                     f"{self.log(name)[-1500:]}")  # fmt: skip
            if time.monotonic() > deadline:
                raise EmulationError(f"{name} did not say {text!r}: {self.log(name)[-1500:]}")
            time.sleep(0.05)

    def stop(self, name: str, timeout_s: float = 10.0) -> int | None:
        proc = self.children.get(name)
        if proc is None:
            return None
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(timeout_s)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        return proc.returncode

    def kill_all(self) -> None:
        for proc in self.children.values():
            if proc.poll() is None:
                proc.kill()
        for proc in self.children.values():
            with contextlib.suppress(subprocess.TimeoutExpired):
                proc.wait(5)


def _cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "egc_app.cli", *args]


def _module(name: str, *args: str) -> list[str]:
    return [sys.executable, "-m", name, *args]


@contextlib.contextmanager
def hosts(workdir: Path, use_netns: bool | None) -> Iterator[Hosts]:
    """Namespaces when asked (or, with None, when available), else loopback; always cleaned."""
    if use_netns is None:
        use_netns = netns.unavailable_reason() is None
    if not use_netns:
        h = Hosts(workdir)
        try:
            yield h
        finally:
            h.kill_all()
        return
    with netns.TwoHosts() as net:
        h = Hosts(workdir, net)
        try:
            yield h
        finally:
            h.kill_all()


# -- following the run ------------------------------------------------------------------------


class Tail:
    """New complete JSON lines of a file that another process appends to."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._file: IO[str] | None = None
        self._partial = ""

    def read(self) -> list[dict[str, Any]]:
        if self._file is None:
            if not self.path.exists():
                return []
            self._file = self.path.open(encoding="utf-8")
        text = self._partial + self._file.read()
        lines = text.split("\n")
        self._partial = lines.pop()
        return [json.loads(line) for line in lines if line.strip()]

    def close(self) -> None:
        if self._file is not None:
            self._file.close()


@dataclass
class Judge:
    """The end of a run from the robot's telemetry (module docstring), line by line."""

    goal: tuple[float, float]
    tolerance_m: float
    checker: FootprintChecker
    max_time_s: float
    stall_time_s: float
    t0_ns: int | None = None
    outcome: str | None = None
    end_ns: int | None = None
    _anchor: tuple[float, float, int] | None = None

    def start(self, t0_ns: int, start: tuple[float, float, float]) -> None:
        self.t0_ns = t0_ns
        self._anchor = (start[0], start[1], t0_ns)

    def feed(self, line: dict[str, Any]) -> None:
        if self.outcome is not None or self.t0_ns is None or line["t"] < self.t0_ns:
            return
        t = int(line["t"])
        pose = line.get("pose")
        if pose is not None:
            x, y, yaw = pose
            if self.checker.clearance(x, y, yaw, below=CONTACT_M) < CONTACT_M:
                self._end("collided", t)
                return
            if math.hypot(x - self.goal[0], y - self.goal[1]) <= self.tolerance_m:
                self._end("reached", t)
                return
        if t - self.t0_ns >= self.max_time_s * NS_PER_S:
            self._end("timeout", t)
            return
        if pose is not None and self._anchor is not None:
            ax, ay, at = self._anchor
            if math.hypot(pose[0] - ax, pose[1] - ay) >= STALL_DISTANCE_M:
                self._anchor = (pose[0], pose[1], t)
            elif t - at >= self.stall_time_s * NS_PER_S:
                self._end("stalled", t)

    def _end(self, outcome: str, t_ns: int) -> None:
        self.outcome = outcome
        self.end_ns = t_ns


def intent_at(changes: list[tuple[int, bool]], t_ns: int) -> bool:
    """The operator's wish to move at ``t_ns`` (the last change at or before it; ``changes``
    sorted by time)."""
    i = bisect.bisect_right(changes, (t_ns, True))
    return changes[i - 1][1] if i > 0 else False


def summarise(
    lines: list[dict[str, Any]],
    intents: list[tuple[int, bool]],
    t0_ns: int,
    end_ns: int,
    checker: FootprintChecker,
) -> dict[str, Any]:
    """Path, clearance, hold and intervention figures of the window [t0, end] (docstring)."""
    window = [ln for ln in lines if t0_ns <= ln["t"] <= end_ns]
    path = 0.0
    min_clearance = checker.clearance_cap_m
    previous: list[float] | None = None
    hold_s = intervening_s = latency_s = 0.0
    hold_events = 0
    driven = in_hold = False
    max_speed = 0.0
    taus: list[float] = []
    for i, ln in enumerate(window):
        nxt = window[i + 1]["t"] if i + 1 < len(window) else end_ns
        dt = max(0, nxt - ln["t"]) / NS_PER_S
        pose = ln.get("pose")
        if pose is not None:
            if previous is not None:
                path += math.hypot(pose[0] - previous[0], pose[1] - previous[1])
            previous = pose
            x, y, yaw = pose
            min_clearance = min(min_clearance, checker.clearance(x, y, yaw, below=min_clearance))
        if ln["state"] == "DRIVING":
            driven = True
            if ln.get("tau") is not None:
                taus.append(float(ln["tau"]))
        holding = intent_at(intents, ln["t"]) and driven and ln["state"] in ("HOLD", "IDLE")
        if holding:
            hold_s += dt
            hold_events += not in_hold
        in_hold = holding
        if ln.get("lim") in INTERVENING_NAMES:
            intervening_s += dt
        if ln.get("lim") == "latency":
            latency_s += dt
        max_speed = max(max_speed, abs(float(ln.get("v") or 0.0)))
    return {
        "path_m": path,
        "min_clearance_m": max(0.0, min_clearance),
        "hold_s": hold_s,
        "hold_events": hold_events,
        "interventions": round(intervening_s / CYCLE_S),
        "latency_limited_s": latency_s,
        "max_speed_mps": max_speed,
        "loop_delay_p50_ms": float(np.percentile(taus, 50)) if taus else None,
        "final_pose": previous,
        "cycles": len(window),
    }


# -- one run --------------------------------------------------------------------------------------


def _relay_spec(point: RunPoint, lossless: bool) -> str:
    if lossless:
        return dataclasses.replace(point, loss=0.0, burst=0.0).link_spec()
    return point.link_spec()


# How a udp point's Zenoh link is set up (point.extra["udp"]), to compare them (docs/transport.md):
# "default": plain udp/ endpoints, i.e. what egc_common.transport makes of them (a TCP link for
# Zenoh's reliable traffic and a best-effort UDP link, rel=0, on one port number; the relay
# carries both); "plain": Zenoh's UDP link alone (rel=0); "mixed": Zenoh's mixed-reliability
# UDP (QUIC without encryption, rel=1;mixed_rel=1).
UDP_VARIANTS: Final = ("default", "plain", "mixed")
_UDP_META: Final = {"default": "", "plain": "?rel=0", "mixed": "?rel=1;mixed_rel=1"}


@dataclass(frozen=True)
class LinkPlan:
    robot_listen: str
    relay_listen: str
    relay_connect: str
    operator_connect: str


def link_plan(variant: str, robot: str, robot_port: int, relay: str, relay_port: int) -> LinkPlan:
    """The robot's listen endpoint, the relay's two and the operator's connect endpoint."""
    proto = "tcp" if variant == "tcp" else "udp"
    meta = _UDP_META.get(variant, "")
    r, m = f"{proto}/{robot}:{robot_port}", f"{proto}/{relay}:{relay_port}"
    return LinkPlan(r + meta, m, r, m + meta)


def run_emulated(point: RunPoint, workdir: Path, use_netns: bool | None = None) -> dict[str, Any]:
    """Run one grid point with real processes (module docstring); its result line.

    ``use_netns``: True (namespaces, NetnsError if not possible), False (loopback) or None
    (namespaces when available). Raises ``ValueError`` for a point this machine cannot emulate
    (TCP with loss outside namespaces with nft) and ``EmulationError`` when a process fails.
    """
    wall0 = time.perf_counter()
    workdir.mkdir(parents=True, exist_ok=True)
    profile = get_profile(point.profile)
    world = load_world(
        point.world, seed=point.seed, reach_m=profile.footprint.reach_m, footprint=profile.footprint
    )
    start = point.start or world.start_pose
    goal = point.goal or world.goal
    if start is None or goal is None:
        raise ValueError(f"world {point.world!r} has no start or goal: give them in the grid")
    tolerance = world.goal_tolerance_m or DEFAULT_GOAL_TOLERANCE_M
    checker = FootprintChecker(world, profile.footprint)
    if use_netns is None:
        use_netns = netns.unavailable_reason() is None
    kernel_loss = point.transport == "tcp" and point.loss > 0
    has_nft = use_netns and netns.nft_unavailable_reason() is None
    if kernel_loss and (not use_netns or netns.nft_unavailable_reason() is not None):
        why = netns.nft_unavailable_reason() if use_netns else "not in namespaces"
        raise ValueError(
            "a TCP point with loss needs kernel loss (network namespaces and nft): the relay "
            f"cannot drop bytes of a TCP stream ({why})"
        )
    proto = point.transport
    variant = str(point.extra.get("udp", "default")) if proto == "udp" else "tcp"
    if variant not in (*UDP_VARIANTS, "tcp"):
        raise ValueError(f"extra udp must be one of {', '.join(UDP_VARIANTS)}, got {variant!r}")
    files = {
        name: workdir / name for name in ("robot.json", "watch.jsonl", "intent.jsonl", "link.json")
    }
    for path in files.values():
        path.unlink(missing_ok=True)
    with hosts(workdir, use_netns) as h:
        if h.net is not None:
            robot_addr, relay_addr = netns.ROBOT_ADDR, netns.MIDDLE_OP_ADDR
            robot_port = relay_port = LINK_PORT
            watch_ep = f"tcp/127.0.0.1:{WATCH_PORT}"
            if kernel_loss or (variant == "default" and point.loss > 0 and has_nft):
                # TCP: the kernel drops, the relay delays. The TCP half of a udp/ link: the
                # relay cannot drop its bytes, the kernel drops its packets at the same rate.
                only = None if kernel_loss else "tcp"
                h.net.set_loss("up", point.loss, only)
                h.net.set_loss("down", point.loss, only)
        else:
            robot_addr = relay_addr = "127.0.0.1"
            robot_port, relay_port = free_port(proto), free_port(proto)
            watch_ep = f"tcp/127.0.0.1:{free_port()}"
        plan = link_plan(variant, robot_addr, robot_port, relay_addr, relay_port)
        robot = ["robot", "--robot", ROBOT_ID, "--driver", "sim", "--map", point.world]
        robot += [f"--start={start[0]:g},{start[1]:g},{start[2]:g}", "--profile", point.profile]
        robot += ["--filter", point.filter, "--summary", str(files["robot.json"])]
        robot += ["--listen", plan.robot_listen, "--listen", watch_ep, "--log-level", "WARNING"]
        robot += ["--set", f"sim.seed={point.seed}", "--set", "pipeline.no_return_is_free=true"]
        if not point.link_aware:
            robot.append("--no-link-aware")
        if not point.latency_turn_cap:
            robot += ["--set", "link.latency_turn_cap=false"]
        h.start("robot", "rb", _cli(*robot))
        watch = ["--robot", ROBOT_ID, "--connect", watch_ep, "--out", str(files["watch.jsonl"])]
        h.start("watch", "rb", _module("egc_experiments.watch", *watch))
        h.wait_log("watch", "watch: ready")
        spec = _relay_spec(point, kernel_loss)
        link = ["link", "--listen", plan.relay_listen, "--connect", plan.relay_connect]
        link += ["--up", spec, "--down", spec, "--seed", str(point.seed)]
        link += ["--stats", str(files["link.json"])]
        h.start("link", "mid", _cli(*link))
        h.wait_log("link", "listening on")
        operator = ["--robot", ROBOT_ID, "--operator-id", OPERATOR_ID]
        operator += ["--zenoh-connect", plan.operator_connect, "--operator", point.operator]
        operator += ["--world", point.world, f"--start={start[0]:g},{start[1]:g},{start[2]:g}"]
        operator += [f"--goal={goal[0]:g},{goal[1]:g}", "--mode", point.mode]
        operator += ["--seed", str(point.seed), "--profile", point.profile]
        operator += ["--intent", str(files["intent.jsonl"])]
        h.start("operator", "op", _module("egc_experiments.operator_model", *operator))
        judge = Judge(goal, tolerance, checker, point.max_time_s, point.stall_time_s)
        lines, intents = _follow(h, judge, files, start)
        assert judge.t0_ns is not None and judge.end_ns is not None and judge.outcome
        robot_rc = h.stop("robot")
        h.stop("operator")
        link_rc = h.stop("link")
        h.stop("watch")
    if robot_rc != 0:
        raise EmulationError(f"the robot exited {robot_rc}: {h.log('robot')[-1500:]}")
    if link_rc != 0:
        raise EmulationError(f"the relay exited {link_rc}: {h.log('link')[-1500:]}")
    summary: dict[str, Any] = json.loads(files["robot.json"].read_text(encoding="utf-8"))
    link_stats: dict[str, Any] = json.loads(files["link.json"].read_text(encoding="utf-8"))
    outcome = judge.outcome
    if summary.get("collisions", 0) > 0 and outcome != "collided":
        outcome = "collided"  # the simulator's contact, which the poses may not show
    figures = summarise(lines, intents, judge.t0_ns, judge.end_ns, checker)
    elapsed = (judge.end_ns - judge.t0_ns) / NS_PER_S
    latency = summary.get("command_latency", {})
    final = figures["final_pose"] or list(start)
    result: dict[str, Any] = {
        **point.identity(),
        "outcome": outcome,
        "reached": outcome == "reached",
        "collided": outcome == "collided",
        "time_s": round(elapsed, 3),
        "path_m": round(figures["path_m"], 4),
        "min_clearance_m": round(0.0 if outcome == "collided" else figures["min_clearance_m"], 4),
        "mean_speed_mps": round(figures["path_m"] / elapsed, 4) if elapsed > 0 else 0.0,
        "hold_s": round(figures["hold_s"], 3),
        "hold_events": figures["hold_events"],
        "interventions": figures["interventions"],
        "cmd_age_p50_ms": _round(latency.get("p50_ms")),
        "cmd_age_p99_ms": _round(latency.get("p99_ms")),
        "stale_rejected": int(summary.get("rejected", {}).get("stale", 0)),
        "link_aware": point.link_aware,
        "latency_turn_cap": point.latency_turn_cap,
        "outages": [list(o) for o in point.outages],
        "rate_kbps": point.rate_kbps,
        "dist": point.dist,
        "max_speed_mps": round(figures["max_speed_mps"], 4),
        "latency_limited_s": round(figures["latency_limited_s"], 3),
        "loop_delay_p50_ms": _round(figures["loop_delay_p50_ms"]),
        "profile": point.profile,
        "start": list(start),
        "goal": list(goal),
        "max_time_s": point.max_time_s,
        "goal_distance_m": round(math.hypot(final[0] - goal[0], final[1] - goal[1]), 4),
        "cycles": figures["cycles"],
        "emulated": h.kind,
        "t0_ns": judge.t0_ns,  # monotonic: the window of the recorder's lines (watch.jsonl)
        "end_ns": judge.end_ns,
        "kernel_loss": kernel_loss,
        "link": {k: link_stats.get(k) for k in ("up", "down")},
        "link_tcp": link_stats.get("tcp"),  # the TCP half of a udp/ link (the relay's companion)
        "udp": variant if proto == "udp" else None,
        "robot_distance_m": summary.get("distance_m"),
        "robot_hold_s": summary.get("hold_s"),
        "robot_collisions": summary.get("collisions"),
        "wall_s": round(time.perf_counter() - wall0, 3),
    }
    missing = [k for k in RESULT_KEYS if k not in result]
    assert not missing, missing
    return result


def _round(value: float | None) -> float | None:
    return None if value is None else round(float(value), 3)


def _follow(
    h: Hosts, judge: Judge, files: dict[str, Path], start: tuple[float, float, float]
) -> tuple[list[dict[str, Any]], list[tuple[int, bool]]]:
    """Follow the run until the judge ends it; the telemetry lines and the operator's intents."""
    watch, intent = Tail(files["watch.jsonl"]), Tail(files["intent.jsonl"])
    lines: list[dict[str, Any]] = []
    intents: list[tuple[int, bool]] = []
    begun = time.monotonic()
    try:
        while judge.outcome is None:
            for name in ("robot", "watch", "link", "operator"):
                if h.children[name].poll() is not None:
                    raise EmulationError(
                        f"{name} exited {h.children[name].returncode} during the run: "
                        f"{h.log(name)[-1500:]}"
                    )
            for item in intent.read():
                if "t0" in item:
                    judge.start(int(item["t0"]), start)
                else:
                    intents.append((int(item["t"]), bool(item["move"])))
            if judge.t0_ns is None and time.monotonic() - begun > START_TIMEOUT_S:
                raise EmulationError(f"the operator never started: {h.log('operator')[-1500:]}")
            new = watch.read()
            lines += new
            for line in new:
                judge.feed(line)
            if judge.t0_ns is not None and judge.outcome is None:
                # a robot that stopped publishing cannot end the run by itself
                limit = judge.t0_ns + int((judge.max_time_s + 10.0) * NS_PER_S)
                if time.monotonic_ns() > limit:
                    raise EmulationError("the robot's telemetry stopped during the run")
            time.sleep(0.05)
    finally:
        watch.close()
        intent.close()
    return lines, intents
