"""``egc-teleop demo``: the simulated robot, a scripted operator and the operator view, as
separate processes talking Zenoh on loopback (DESIGN 1; issue 4, the README's main job).

- ``egc-teleop robot --driver sim --map WORLD`` listens on a free loopback port and writes its
  run statistics at exit (``--summary``);
- ``egc-teleop operator --script demo`` connects to it and opens the operator view: the Rerun
  viewer when there is a display, otherwise (or with ``--save``) a ``.rrd`` recording, and it
  says where on stderr.

- with ``--up SPEC`` / ``--down SPEC`` (DESIGN 10 link specs, e.g. ``delay=200,jitter=50``), an
  ``egc-teleop link`` process sits between them and the operator connects through it, so the
  demo shows how the product drives on a cellular, Wi-Fi or satellite link; ``--transport udp``
  runs the Zenoh link over UDP instead of TCP.
- with ``--ros2``, a real ROS 2 graph sits between the robot process and the simulator:
  ``egc-teleop sim --ros2`` is the ROS 2 robot (``/scan``, ``/odom``, ``/cmd_vel``) and the robot
  process runs ``--driver ros2`` (DESIGN 11). Discovery stays on this machine
  (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` unless set), so the demo's ``/cmd_vel`` never
  reaches a real robot on the network; ``ROS_DOMAIN_ID`` is yours.

The demo ends when the script ends (or after ``--duration``), or on SIGINT/SIGTERM, which it
forwards. The children are asked to stop (SIGTERM), killed if they do not, and die with the demo
if it is killed itself (PR_SET_PDEATHSIG), so nothing is left behind. Then it prints a summary:
distance, interventions, collisions, command latency percentiles.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from egc_common.child_process import die_with_parent
from egc_common.cli_args import PROFILE_HELP, check_writable
from egc_common.errors import UsageError
from egc_common.profiles import get_profile
from egc_common.stop_flag import stop_on_signals
from egc_common.transport import free_port
from egc_experiments.link_cli import link_schedules
from egc_experiments.link_model import SpecError
from egc_experiments.relay import EndpointError, Relay, parse_endpoint
from egc_operator.command_source import load_script, script_names
from egc_sim.bridge import open_simulator

STOP_TIMEOUT_S = 10.0


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--duration", type=float, default=None, metavar="S", help="(default: the script's length)"
    )
    parser.add_argument("--save", metavar="FILE.rrd", help="save the operator view to a file")
    parser.add_argument("--no-view", action="store_true", help="run without the operator view")
    parser.add_argument(
        "--world", default="hallway", help="built-in world or map file (default: hallway)"
    )
    parser.add_argument(
        "--profile",
        default="pioneer3dx",
        metavar="NAME|FILE",
        help=f"{PROFILE_HELP} (default: pioneer3dx)",
    )
    parser.add_argument(
        "--script",
        default="demo",
        help="built-in operator script (default: demo; `operator --script list` lists them)",
    )
    link = parser.add_argument_group("emulated link (egc-teleop link between the two)")
    link.add_argument("--up", metavar="SPEC", help="operator -> robot, e.g. delay=200,jitter=50")
    link.add_argument("--down", metavar="SPEC", help="robot -> operator, same form")
    link.add_argument("--scenario", metavar="FILE", help="a link scenario file (TOML)")
    link.add_argument("--link-seed", type=int, default=0, metavar="N", help="(default: 0)")
    link.add_argument(
        "--transport", choices=("tcp", "udp"), default="tcp", help="Zenoh link (default: tcp)"
    )
    parser.add_argument(
        "--no-link-aware",
        action="store_true",
        help="run the robot without link-aware driving, to compare",
    )
    parser.add_argument("--json", metavar="FILE", help="also write the summary as JSON")
    parser.add_argument(
        "--camera",
        choices=("sim", "none"),
        default=None,
        help="the robot's camera (DESIGN 12): sim, the simulator's forward camera in the view, "
        "or none (default: sim; none with --ros2, whose simulator publishes no images)",
    )
    parser.add_argument(
        "--ros2",
        action="store_true",
        help="ROS 2 in the loop: 'egc-teleop sim --ros2' as the robot's base and lidar, the "
        "robot process on --driver ros2 (needs the ros2 extra)",
    )


def _start(args: list[str], env: dict[str, str] | None = None) -> subprocess.Popen[bytes]:
    return subprocess.Popen(
        [sys.executable, "-m", "egc_app.cli", *args],
        stdin=subprocess.DEVNULL,
        preexec_fn=die_with_parent,
        env=env,
    )


def _stop(proc: subprocess.Popen[bytes]) -> int:
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    return proc.returncode


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}" if n == 1 else f"{n} {noun}es" if noun.endswith("ch") else f"{n} {noun}s"


def format_summary(summary: dict[str, Any]) -> str:
    lat = summary.get("command_latency", {})

    def ms(key: str) -> str:
        value = lat.get(key)
        return "n/a" if value is None else f"{value:.2f} ms"

    lines = [
        "demo summary",
        f"  distance        {summary['distance_m']:.2f} m",
        f"  interventions   {summary['interventions']} cycles in which EGC or the footprint "
        f"sweep changed the command (in {_count(summary.get('intervention_onsets', 0), 'stretch')})",
        f"  collisions      {summary['collisions']}",
        f"  command latency p50 {ms('p50_ms')}, p90 {ms('p90_ms')}, p99 {ms('p99_ms')}, "
        f"max {ms('max_ms')} (operator publish -> robot, {lat.get('n', 0)} commands)",
        f"  robot cycles    {summary['cycles']} {summary.get('cycles_by_state', {})}",
        f"  time by state   {_seconds(summary.get('seconds_by_state', {}))}; HOLD entered "
        f"{summary.get('hold_events', 0)} times; speed capped by latency "
        f"{summary.get('latency_limited_s', 0.0):.1f} s",
        f"  rejected        {summary.get('rejected') or 'none'}",
    ]
    camera = summary.get("camera")
    if camera:
        lines.append(
            f"  camera          {camera['codec']} {camera['width']}x{camera['height']}, "
            f"{camera['frames_sent']} frames sent, {camera['fps']:g} frames/s, "
            f"{camera['kbps']:g} kbit/s"
        )
    downlink = summary.get("downlink_kbps") or {}
    if downlink.get("p50") is not None:  # DESIGN 12: what the view plane cost
        view = (summary.get("view_age_ms") or {}).get("p50_ms")
        lines.append(
            f"  view plane      {downlink['p50']:.0f} kbit/s p50, {downlink['max']:.0f} max; "
            f"telemetry {summary.get('telemetry_sent', 0)} messages of "
            f"{summary.get('telemetry_bytes_mean') or 0:.0f} bytes; view age p50 "
            f"{'n/a' if view is None else f'{view:.0f} ms'}; operator lost "
            f"{summary.get('operator_lost', 0)} times while driving"
        )
    return "\n".join(lines)


def _seconds(by_state: dict[str, float]) -> str:
    total = sum(by_state.values())
    if not total:
        return "n/a"
    return ", ".join(f"{k} {v:.1f} s ({100 * v / total:.0f}%)" for k, v in sorted(by_state.items()))


def _link_cmd(args: argparse.Namespace, listen: str, connect: str) -> list[str]:
    cmd = ["link", "--listen", listen, "--connect", connect, "--seed", str(args.link_seed)]
    for flag, value in (("--up", args.up), ("--down", args.down), ("--scenario", args.scenario)):
        if value is not None:
            cmd += [flag, value]
    return cmd


def _wait_ready(proc: subprocess.Popen[bytes], host: str, port: int) -> None:
    """Wait until ``proc`` accepts TCP connections on ``port``."""
    deadline = time.monotonic() + 3 * STOP_TIMEOUT_S
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise UsageError(f"{proc.args[3]} exited with code {proc.returncode}")
        try:
            with socket.create_connection((host, port), timeout=0.2):
                return
        except OSError:
            time.sleep(0.05)
    raise UsageError(f"{proc.args[3]} did not start listening on port {port}")


def check_arguments(args: argparse.Namespace) -> None:
    """Every argument the children would refuse, checked here before any of them starts, with
    the message the child would give: one line and exit 2 from the demo itself, not a child's
    error, a robot's stop summary and "robot exited 2" after it (DESIGN 2)."""
    if args.duration is not None and not args.duration > 0:
        raise UsageError("--duration must be positive")
    if args.save is not None and args.no_view:
        raise UsageError("--save and --no-view exclude each other")
    if args.save is not None:
        if not args.save.endswith(".rrd"):
            raise UsageError(f"--save needs a .rrd file name, got {args.save!r}")
        # Before the robot starts: the operator would refuse it only once the robot is up.
        check_writable(args.save, "--save")
    if args.json is not None:  # now, not as a traceback once the whole demo has run
        check_writable(args.json, "--json")
    if args.camera == "sim" and args.ros2:
        raise UsageError(
            "--camera sim needs the simulator in the robot process; with --ros2 the robot runs "
            "--driver ros2 and the ROS 2 simulator publishes no images (use --camera none)"
        )
    try:
        profile = get_profile(args.profile)
        load_script(args.script)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    open_simulator(args.world, profile, None, 0)  # the robot's (and sim's) own check and message
    if args.up is not None or args.down is not None or args.scenario is not None:
        # egc-teleop link's own checks: the SPECs or the scenario, and what a TCP link refuses.
        up, down = link_schedules(args.up or "", args.down or "", args.scenario)
        somewhere = parse_endpoint(f"{args.transport}/127.0.0.1:1")
        try:
            Relay(somewhere, somewhere, up, down, seed=args.link_seed)
        except (SpecError, EndpointError) as exc:
            hint = " (in the demo: --transport udp)" if args.transport == "tcp" else ""
            raise UsageError(f"{exc}{hint}") from None


def run(args: argparse.Namespace) -> int:
    if args.script == "list":  # as `egc-teleop operator --script list`
        print("\n".join(script_names()))
        return 0
    check_arguments(args)
    linked = args.up is not None or args.down is not None or args.scenario is not None
    proto = args.transport
    endpoint = f"{proto}/127.0.0.1:{free_port(proto)}"
    operator_endpoint = endpoint
    link_port = free_port(proto)
    if linked:
        operator_endpoint = f"{proto}/127.0.0.1:{link_port}"
    workdir = Path(tempfile.mkdtemp(prefix="egc-demo-"))
    summary_path = workdir / "robot-summary.json"
    driver = "ros2" if args.ros2 else "sim"
    robot_cmd = ["robot", "--driver", driver, "--map", args.world, "--profile", args.profile]
    robot_cmd += ["--listen", endpoint, "--summary", str(summary_path)]
    if args.no_link_aware:
        robot_cmd.append("--no-link-aware")
    robot_cmd += ["--camera", args.camera or ("none" if args.ros2 else "sim")]
    operator_cmd = ["operator", "--script", args.script, "--operator-id", "demo-operator"]
    operator_cmd += ["--zenoh-connect", operator_endpoint]
    if args.duration is not None:
        operator_cmd += ["--loop", "--duration", str(args.duration)]
    if args.no_view:
        operator_cmd.append("--no-view")
    elif args.save is not None:
        operator_cmd += ["--save", str(Path(args.save).resolve())]

    stop = stop_on_signals()  # not threading.Event: its set() can deadlock in a handler
    ros_env: dict[str, str] | None = None
    base: subprocess.Popen[bytes] | None = None
    if args.ros2:
        from egc_sim.ros2_base import require_rclpy

        require_rclpy()
        ros_env = dict(os.environ)
        ros_env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        base = _start(["sim", "--ros2", "--map", args.world, "--profile", args.profile], ros_env)
    robot = _start(robot_cmd, ros_env)
    relay: subprocess.Popen[bytes] | None = None
    link_started_s: float | None = None
    operator: subprocess.Popen[bytes] | None = None
    try:
        if linked:
            # The relay checks that the robot side is reachable (a udp/ endpoint of ours also
            # listens on TCP, for Zenoh's reliable control link, on the same port).
            _wait_ready(robot, "127.0.0.1", int(endpoint.rsplit(":", 1)[1]))
            relay = _start(_link_cmd(args, operator_endpoint, endpoint))
            _wait_ready(relay, "127.0.0.1", link_port)
            # A scenario's time 0 (on the robot's clock too): the relay takes it just before it
            # listens, so within one poll (50 ms) before this; the relay's first line says it
            # exactly. Not when it was started: Python takes seconds to start on a busy machine.
            link_started_s = time.monotonic()
        operator = _start(operator_cmd)
        while not stop.wait(0.1):
            if operator.poll() is not None or robot.poll() is not None:
                break
            if relay is not None and relay.poll() is not None:
                break
            if base is not None and base.poll() is not None:
                break
    finally:
        operator_rc = None if operator is None else _stop(operator)
        robot_rc = _stop(robot)
        relay_rc = None if relay is None else _stop(relay)
        base_rc = None if base is None else _stop(base)
    if robot_rc != 0 or operator_rc not in (0, -signal.SIGTERM):
        print(f"demo: robot exited {robot_rc}, operator {operator_rc}", file=sys.stderr)
        return 1
    if base_rc not in (None, 0):
        print(f"demo: the ROS 2 simulator exited {base_rc}", file=sys.stderr)
        return 1
    if relay_rc not in (None, 0):
        print(f"demo: the link relay exited {relay_rc}", file=sys.stderr)
        return 1
    try:
        summary = json.loads(summary_path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        print(f"demo: no robot summary ({exc})", file=sys.stderr)
        return 1
    if link_started_s is not None:
        # the view_timeline's t_s is on the same monotonic clock (DESIGN 12: how the budget
        # followed a scenario's phases)
        summary["link_started_s"] = round(link_started_s, 3)
    print(format_summary(summary), flush=True)
    if args.json is not None:
        try:  # checked before the start; the folder may have gone since
            Path(args.json).write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
        except OSError as exc:
            print(f"demo: cannot write --json {args.json}: {exc.strerror or exc}", file=sys.stderr)
            return 1
    return 0
