"""An operator process driven by an experiment's operator model (emulated mode, DESIGN 10).

::

    python -m egc_experiments.operator_model --robot ID --zenoh-connect ENDPOINT \\
        --operator forward|goal|sighted[:K=V,...]|route[:K=V,...]|FILE --world WORLD \\
        [--start X,Y,YAW] [--goal X,Y] [--mode shared|direct] [--seed N] [--profile NAME] \\
        [--operator-id ID] [--intent FILE.jsonl]

``egc-teleop operator`` replays a joystick file blind; the operator models of the experiments
react to what the operator view shows, so this process is the operator process with the model
in place of the joystick, and nothing else changed:

- the Zenoh side is the operator's own ``egc_operator.operator_node.OperatorNode``: 50 Hz
  commands with command QoS, clock sync, ``view_age_ms``, the liveliness token;
- the model sees only the telemetry that has *arrived* through the link (the node hands it to
  this process's view, which turns each message into an ``egc_sim.observation.Observation``:
  pose, scan points, state, reason), never the simulator's truth;
- the stick is decided by ``egc_experiments.simulated.OperatorSide``, the very operator logic
  of the simulated mode (the model's stick through its reaction time; centred, deadman held,
  while the view shows the robot IDLE, in ESTOP or waiting for a centred stick), so both modes
  run the same operator;
- the goal goes to the robot as the operator's via point (``map`` frame), as in the simulated
  mode: ``assist`` and ``dwa`` steer to it (without it the two modes disagreed on them).

The model's clock starts (t = 0) at the first stick the node asks for. ``--intent`` records,
as JSON lines, ``{"t0": NS}`` first and then ``{"t": NS, "move": BOOL}`` whenever the model's
wish to move changes (monotonic ns), which the emulated runner needs for ``hold_s`` (DESIGN 10:
time the robot did not drive while the operator wanted it to).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import logging
import sys
import threading
import time
from pathlib import Path
from typing import IO, Any

import numpy as np
from egc_common import keys
from egc_common.cli_args import PROFILE_HELP, numbers_are_values
from egc_common.clock_id import monotonic_clock_id
from egc_common.errors import UsageError
from egc_common.joystick_file import JoystickSample
from egc_common.messages import Telemetry
from egc_common.profiles import get_profile
from egc_common.stop_flag import stop_on_signals
from egc_common.transport import ZenohOptions, open_session
from egc_operator.operator_node import OperatorNode
from egc_operator.prediction import CommandHistory
from egc_operator.via_route import Route
from egc_sim.bridge import parse_pose
from egc_sim.observation import Observation
from egc_sim.operators import make_operator
from egc_sim.worlds import load_world

from egc_experiments.predictive_view import ghost_observation
from egc_experiments.simulated import OperatorSide

log = logging.getLogger("egc.operator_model")
NS_PER_S = 1_000_000_000


class ModelDriver:
    """The model's view (what arrives) and stick (what the node publishes), thread-safe.

    Zenoh calls ``on_telemetry`` from its threads, the node calls ``sample`` from its loop;
    observations are queued with their arrival times and fed to the model in order, at the
    next stick, on the model's clock.
    """

    def __init__(self, side: OperatorSide, intent: IO[str] | None = None) -> None:
        self.side = side
        self._intent = intent
        self._lock = threading.Lock()
        self._pending: list[tuple[int, Observation, bool]] = []  # (arrival, frame, ghost?)
        self._newest: tuple[Observation, Telemetry] | None = None
        self._rtt_ms: float | None = None
        self._t0_ns: int | None = None
        self._last_obs_s = 0.0
        self._wants: bool | None = None
        self.finished = False

    # -- the view (egc_operator.operator_node.View) ------------------------------------------------

    def on_telemetry(self, t: Telemetry, received_ns: int | None = None) -> None:
        obs = Observation(
            t.stamp_ns / NS_PER_S,
            t.pose,
            np.asarray(t.scan_xy, dtype=np.float64),
            t.state,
            t.reason or "",
        )
        with self._lock:
            self._pending.append((time.monotonic_ns(), obs, False))
            if self._newest is None or t.stamp_ns >= self._newest[1].stamp_ns:
                self._newest = (obs, t)

    def on_commands(self, history: CommandHistory, robot_now_ns: int) -> None:
        """The node sent a command: the predictive display's ghost, for a model that uses it."""
        if not self.side.predictive:
            return
        with self._lock:
            newest, rtt_ms = self._newest, self._rtt_ms
        if newest is None:
            return
        ghost = ghost_observation(newest[0], newest[1], history, robot_now_ns, rtt_ms)
        with self._lock:
            self._pending.append((time.monotonic_ns(), ghost, True))

    def on_link(self, rtt_ms: float, offset_ns: int) -> None:
        with self._lock:
            self._rtt_ms = rtt_ms

    def on_state(self, *args: Any, **kwargs: Any) -> None:
        pass

    def on_text(self, *args: Any, **kwargs: Any) -> None:
        pass

    def set_world(self, *args: Any, **kwargs: Any) -> None:
        pass

    def on_route(self, *args: Any, **kwargs: Any) -> None:
        pass  # the model knows its goal; the via points it sends need no drawing

    def close(self) -> None:
        pass

    # -- the command source (egc_operator.command_source.CommandSource) ---------------------------

    def sample(self, t_s: float) -> JoystickSample:
        now = time.monotonic_ns()
        with self._lock:
            if self._t0_ns is None:
                self._t0_ns = now
                self._write({"t0": now})
            t0 = self._t0_ns
            for arrived_ns, obs, ghost in self._pending:
                # Observations that came before t = 0 are seen at t = 0; arrivals never go back.
                self._last_obs_s = max(self._last_obs_s, (arrived_ns - t0) / NS_PER_S)
                if ghost:
                    self.side.on_ghost(self._last_obs_s, obs)
                else:
                    self.side.on_telemetry(self._last_obs_s, obs)
            self._pending.clear()
            model_t = (now - t0) / NS_PER_S
            stick = self.side.stick(model_t)
            wants = self.side.wants_move
            if wants != self._wants:
                self._wants = wants
                self._write({"t": now, "move": wants})
        return JoystickSample(
            model_t, stick.x_o, stick.y_o, stick.deadman, stick.mode, stick.estop, False
        )

    def _write(self, line: dict[str, Any]) -> None:
        if self._intent is not None:
            self._intent.write(json.dumps(line) + "\n")
            self._intent.flush()


def _goal(text: str | None) -> tuple[float, float] | None:
    if text is None:
        return None
    try:
        x, y = (float(v) for v in text.split(","))
    except ValueError:
        raise UsageError(f"--goal must be X,Y in metres, got {text!r}") from None
    return x, y


def build_parser() -> argparse.ArgumentParser:
    parser = numbers_are_values(
        argparse.ArgumentParser(
            prog="python -m egc_experiments.operator_model", description=__doc__.splitlines()[0]
        )
    )
    parser.add_argument("--robot", default=keys.DEFAULT_ROBOT_ID, metavar="ID")
    parser.add_argument("--operator-id", default="model-operator", metavar="ID")
    parser.add_argument("--zenoh-connect", required=True, action="append", metavar="ENDPOINT")
    parser.add_argument("--operator", required=True, metavar="SPEC")
    parser.add_argument("--world", required=True, metavar="WORLD")
    parser.add_argument("--start", metavar="X,Y,YAW")
    parser.add_argument("--goal", metavar="X,Y")
    parser.add_argument("--mode", choices=("shared", "direct"), default="shared")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--profile", default="pioneer3dx", help=PROFILE_HELP)
    parser.add_argument("--rate-hz", type=float, default=50.0)
    parser.add_argument("--intent", metavar="FILE.jsonl")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="operator-model: %(message)s", stream=sys.stderr)
    try:
        profile = get_profile(args.profile)
        world = load_world(
            args.world,
            seed=args.seed,
            reach_m=profile.footprint.reach_m,
            footprint=profile.footprint,
        )
        start = parse_pose(args.start) or world.start_pose
        goal = _goal(args.goal) or world.goal
        if start is None:
            raise UsageError(f"world {args.world!r} has no start: give --start")
        model = make_operator(
            args.operator,
            goal,
            args.mode,
            seed=args.seed,
            world=world,
            start=start,
            half_width_m=profile.half_size_m[1],
            profile=profile,
        )
    except (UsageError, ValueError, OSError) as exc:
        print(f"operator-model: error: {exc}", file=sys.stderr)
        return 2
    session = open_session(ZenohOptions(connect=tuple(args.zenoh_connect)))
    stop = stop_on_signals()  # not threading.Event: its set() can deadlock in a handler
    with contextlib.ExitStack() as stack:
        intent = (
            stack.enter_context(Path(args.intent).open("w", encoding="utf-8"))
            if args.intent
            else None
        )
        driver = ModelDriver(OperatorSide(model, args.mode, start), intent)
        # One host (network namespaces share the kernel's clock): the robot's clock is ours, so
        # clock sync needs no estimate, and command ages are the link's alone (as for a real
        # operator on the robot's machine; Cristian's estimate was off by up to 22 ms here).
        node = OperatorNode(
            session,
            args.robot,
            args.operator_id,
            driver,
            args.rate_hz,
            view=driver,
            clock_id=monotonic_clock_id(),
            # The goal as the operator's via point in the map frame, as the simulated mode sends
            # it: the filters that steer to a via point (assist, dwa) need it in both modes.
            route=Route("map", (goal,)) if goal is not None else None,
        )
        log.info("operator %s (%s) driving robot %s", args.operator_id, args.operator, args.robot)
        try:
            node.run(stop)
        finally:
            node.close()
            session.close()
            log.info("stopped after %d commands", node.published)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
