"""``--mode simulated`` (DESIGN 10): one run of a grid point in one process, on a simulated clock.

The pieces are the real ones, wired as the processes wire them, with the link model in between:

- the robot: ``egc_robot.controller.RobotController`` (``ControllerConfig(link_aware=...)``,
  the profile's pipeline with the point's filter), stepped at 20 Hz. Each cycle, as the robot
  process does it: the simulator's scan (``on_scan``) and odometry (``on_odometry``), then
  ``step``; the base command drives the simulator until the next cycle.
- the operator: the point's operator model (``egc_sim.operators.make_operator``) asked for its
  stick at 50 Hz (at a seeded phase to the robot's cycle, as two unsynchronised loops are); each stick becomes an ``OperatorCommand`` stamped with the robot's clock (a
  synchronised operator), with ``view_age_ms`` = the age of the newest telemetry that has
  arrived, encoded, sent through the **uplink** ``LinkModel`` (``ordered`` for tcp) and handed
  to ``controller.on_command`` at its arrival time. Its via point (the goal, ``map`` frame,
  issue 11) goes the same way once a second as a ``GoalMessage`` to ``controller.on_goal``;
  the filters that steer to a via point (``assist``, ``dwa``) use it, the others ignore it.
- the view: every cycle's telemetry goes through the **downlink** ``LinkModel``; what arrives
  is what the operator model sees (``sighted`` and ``route`` observe it through their reaction
  time; ``goal`` and ``forward`` steer from its pose).
- liveliness: the operator's Zenoh session (lease 2 s) ends when nothing has come through the
  uplink for ``LEASE_S``: ``on_operator_alive(op, False)``; the next arrival declares it again.

An operator does what the view tells it: while the view shows the robot IDLE, in ESTOP or
holding for a reason a centred stick cures ("waiting for a centred stick", a lost operator),
it centres the stick (deadman held) until the view shows it DRIVING again; it does not centre
for a HOLD from the link alone (the robot resumes by itself when link-aware, DESIGN 8).

The run ends ``reached`` (the robot's centre within the goal tolerance), ``collided`` (any
contact), ``stalled`` (the robot has not moved 0.1 m for ``stall_time_s``) or ``timeout``.

Metrics (``RESULT_KEYS`` and more; times in simulated seconds):

- ``hold_s`` / ``hold_events``: control cycles, and stretches of them, in which the robot was
  not driving (telemetry state HOLD, or IDLE: no operator in control, e.g. at the start while
  every command arrives too old) while the operator wanted to move (its model's stick
  deflected, before any centring);
- ``changed``, ``changed_share``, ``mean_cut``, ``filter_hold_s`` (DESIGN 13's ``hold_s``) and
  ``filter_commands``: how much the filter and the sweep changed the operator's commands,
  against what direct mode would have sent on the same cycles (``egc_robot.intervention``);
- ``interventions``: cycles in which the filter or the footprint sweep changed the command
  (the pipeline's limiter names the filter, or ``sweep``); ``latency_limited_s``: time in which the
  latency governor capped the speed (telemetry limiter ``latency``);
- ``cmd_age_p50_ms`` / ``cmd_age_p99_ms``: arrival minus stamp of the accepted commands;
  ``stale_rejected``: commands the robot dropped as too old;
- ``mean_speed_mps`` = path / time, ``max_speed_mps`` the highest speed the base reached,
  ``contact_speed_mps`` / ``contact_turn_radps`` the base's |v| and |w| entering the step that
  made contact (None without one: a contact at v = 0 is a turn in place, no speed cap can
  prevent it),
  ``loop_delay_p50_ms`` the robot's median tau (DESIGN 9) over the cycles it drove.
"""

from __future__ import annotations

import heapq
import math
import random
import time
from typing import Any, Final

import numpy as np
from egc_common.messages import (
    MAX_VIEW_AGE_MS,
    GoalMessage,
    Odometry,
    OperatorCommand,
    RejectReason,
    Telemetry,
)
from egc_common.profiles import get_profile
from egc_operator.prediction import CommandHistory, SentCommand
from egc_robot.controller import ControllerConfig, RobotController
from egc_robot.intervention import InterventionTally
from egc_robot.pipeline import INTERVENING, Limiter, PipelineConfig
from egc_sim.grid_world import Pose
from egc_sim.observation import Observation, ViewBuffer
from egc_sim.operators import Operator, Stick, make_operator
from egc_sim.simulator import Simulator
from egc_sim.worlds import load_world

from egc_experiments.link_model import LinkModel, derive_seed, parse_spec
from egc_experiments.predictive_view import ghost_observation
from egc_experiments.run_point import RESULT_KEYS, RunPoint

NS_PER_S: Final = 1_000_000_000
ROBOT_PERIOD_NS: Final = 50_000_000  # 20 Hz
OPERATOR_PERIOD_NS: Final = 20_000_000  # 50 Hz
LEASE_S: Final = 2.0  # the Zenoh session lease (a silent link this long loses liveliness)
OPERATOR_ID: Final = "sim-operator"
# The robot's clock at the start of a run: not 0, which a command stamp reserves for "not
# synchronised" (DESIGN 7). Event times count from 0 (the link's outages are timed from there).
CLOCK0_NS: Final = NS_PER_S
DEFAULT_GOAL_TOLERANCE_M: Final = 0.3
STALL_DISTANCE_M: Final = 0.1
MOVE_TOLERANCE: Final = 0.05  # a stick deflected more than this "wants to move"
# HOLD reasons the robot leaves by itself (DESIGN 8); any other needs a centred stick.
_SELF_CLEARING: Final = ("command timeout", "stale commands", "sensor stale")
_TELEMETRY_BASE_BYTES: Final = 600

# Event kinds, in the order they are handled at the same instant.
_DOWN, _OPERATOR, _UP, _GOAL, _ROBOT = 0, 1, 2, 3, 4


class OperatorSide:
    """The operator process around an operator model: the view, centring, commands.

    A model that drives by the predictive display (``sighted:predictive=1``) is fed the ghost
    frames (``predictive_view``) instead of the telemetry: ``on_ghost``; in this mode
    ``command`` records the commands sent and shows the model the ghost after each one, as
    the operator process's view redraws it after each send.
    """

    def __init__(self, model: Operator, mode: str, start: Pose) -> None:
        self.model = model
        self.mode = mode
        self.observing = hasattr(model, "observe")
        params = getattr(model, "params", None)
        self.predictive = self.observing and bool(getattr(params, "predictive", False))
        self.view = ViewBuffer(float(getattr(params, "reaction_s", 0.0)))
        self.newest: Observation | None = None  # newest arrived telemetry (view_age_ms)
        self.newest_telemetry: Telemetry | None = None
        self.history = CommandHistory()  # the commands sent (the predictive display's)
        self.start = start
        self.seq = 0
        self.wants_move = False

    def on_telemetry(
        self, t_s: float, obs: Observation, telemetry: Telemetry | None = None
    ) -> None:
        if self.newest is None or obs.stamp_s >= self.newest.stamp_s:
            self.newest = obs
            self.newest_telemetry = telemetry
        self.view.observe(t_s, obs)
        if self.observing and not self.predictive:
            self.model.observe(t_s, obs)  # type: ignore[attr-defined]

    def on_ghost(self, t_s: float, obs: Observation) -> None:
        """The predictive display's frame at ``t_s`` (the model sees it after its reaction)."""
        if self.predictive:
            self.model.observe(t_s, obs)  # type: ignore[attr-defined]

    def stick(self, t_s: float) -> Stick:
        seen = self.view.seen(t_s)
        pose = seen.pose if seen is not None and seen.pose is not None else self.start
        intent = self.model.command(t_s, pose)
        self.wants_move = intent.deadman and (
            abs(intent.x_o) > MOVE_TOLERANCE or abs(intent.y_o) > MOVE_TOLERANCE
        )
        if seen is None or _needs_centring(seen):
            return Stick(0.0, 0.0, True, intent.mode)
        return intent

    def command(self, t_ns: int) -> OperatorCommand:
        t_s = t_ns / NS_PER_S
        s = self.stick(t_s)
        self.seq += 1
        view_age = None
        if self.newest is not None:
            view_age = min(max(round((t_s - self.newest.stamp_s) * 1000), 0), MAX_VIEW_AGE_MS)
        command = OperatorCommand(
            seq=self.seq,
            stamp_ns=CLOCK0_NS + t_ns,
            x=s.x_o,
            y=s.y_o,
            mode=s.mode,
            deadman=s.deadman,
            estop=s.estop,
            reset=False,
            op=OPERATOR_ID,
            view_age_ms=view_age,
        )
        if self.predictive:
            self.history.add(
                SentCommand(command.stamp_ns, s.x_o, s.y_o, s.mode, s.deadman, s.estop)
            )
            if self.newest is not None and self.newest_telemetry is not None:
                ghost = ghost_observation(
                    self.newest, self.newest_telemetry, self.history, command.stamp_ns
                )
                self.on_ghost(t_s, ghost)
        return command


def _needs_centring(obs: Observation) -> bool:
    if obs.state in ("IDLE", "ESTOP"):
        return True
    return obs.state == "HOLD" and obs.reason not in _SELF_CLEARING


def _percentile(values: list[float], q: float) -> float | None:
    return None if not values else round(float(np.percentile(values, q)), 3)


def run_simulated(point: RunPoint) -> dict[str, Any]:
    """Run one grid point (module docstring); returns its result line (``RESULT_KEYS`` +)."""
    wall0 = time.perf_counter()
    profile = get_profile(point.profile)
    world = load_world(
        point.world, seed=point.seed, reach_m=profile.footprint.reach_m, footprint=profile.footprint
    )
    start = point.start or world.start_pose
    goal = point.goal or world.goal
    if start is None or goal is None:
        raise ValueError(f"world {point.world!r} has no start or goal: give them in the grid")
    tolerance = world.goal_tolerance_m or DEFAULT_GOAL_TOLERANCE_M
    sim = Simulator(world, profile, start, seed=point.seed)
    pipeline = PipelineConfig(profile, filter=point.filter, no_return_is_free=True)
    controller = RobotController(
        ControllerConfig(
            pipeline, link_aware=point.link_aware, latency_turn_cap=point.latency_turn_cap
        ),
        CLOCK0_NS,
    )
    model = make_operator(
        point.operator,
        goal,
        point.mode,
        seed=point.seed,
        world=world,
        start=start,
        half_width_m=profile.half_size_m[1],
        profile=profile,
    )
    operator = OperatorSide(model, point.mode, start)
    spec = parse_spec(point.link_spec())
    ordered = point.transport == "tcp"
    up = LinkModel(spec, derive_seed(point.seed, "up"), ordered)
    down = LinkModel(spec, derive_seed(point.seed, "down"), ordered)

    events: list[tuple[int, int, int, Any]] = []
    order = 0

    def push(t_ns: int, kind: int, data: Any) -> None:
        nonlocal order
        order += 1
        heapq.heappush(events, (t_ns, kind, order, data))

    max_ns = round(point.max_time_s * NS_PER_S)
    # The operator's 50 Hz is not phase-locked to the robot's 20 Hz: a seeded phase, so that
    # commands do not arrive exactly at the robot's cycle (which would make a delay equal to
    # max_command_age pass on every other cycle, an artefact no real link has).
    phase_ns = random.Random(derive_seed(point.seed, "phase")).randrange(1, OPERATOR_PERIOD_NS)
    push(phase_ns, _OPERATOR, None)
    push(0, _ROBOT, None)
    controller.on_operator_alive(OPERATOR_ID, True)
    alive = True
    last_up_ns = 0
    base = (0.0, 0.0)
    last_robot_ns = 0
    ages_ms: list[float] = []
    loop_delays: list[float] = []
    hold_cycles = hold_events = interventions = latency_cycles = cycles = 0
    profile = controller.config.pipeline.profile
    tally = InterventionTally(profile.v_max_mps, profile.w_max_radps)  # DESIGN 13
    in_hold = False
    max_speed = 0.0
    before = contact = (0.0, 0.0)  # the base's twist entering the step that made contact
    anchor = (start[0], start[1], 0)  # (x, y, t_ns) of the last 0.1 m of progress
    outcome = "timeout"
    dt_s = ROBOT_PERIOD_NS / NS_PER_S
    sent = 0
    goal_seq = 0
    next_goal_ns = 0

    while events:
        t_ns, kind, _, data = heapq.heappop(events)
        t_s = t_ns / NS_PER_S
        if kind == _DOWN:
            operator.on_telemetry(t_s, *data)
        elif kind == _OPERATOR:
            cmd = operator.command(t_ns)
            payload = cmd.encode()
            sent += 1
            arrival = up.transit(t_s, len(payload))
            if arrival is not None:
                push(max(round(arrival * NS_PER_S), t_ns), _UP, payload)
            if t_ns >= next_goal_ns:  # the operator's via point, repeated at 1 Hz as it does
                goal_seq += 1
                goal_msg = GoalMessage(goal_seq, 0, OPERATOR_ID, "map", (goal,)).encode()
                goal_arrival = up.transit(t_s, len(goal_msg))
                if goal_arrival is not None:
                    push(max(round(goal_arrival * NS_PER_S), t_ns), _GOAL, goal_msg)
                next_goal_ns = t_ns + NS_PER_S
            push(t_ns + OPERATOR_PERIOD_NS, _OPERATOR, None)
        elif kind == _GOAL:
            controller.on_goal(data, CLOCK0_NS + t_ns)
        elif kind == _UP:
            if not alive:
                controller.on_operator_alive(OPERATOR_ID, True)
                alive = True
            last_up_ns = t_ns
            verdict = controller.on_command(data, CLOCK0_NS + t_ns)
            if verdict.accepted and verdict.latency_ns is not None:
                ages_ms.append(verdict.latency_ns / 1e6)
        else:  # the robot's control cycle
            if t_ns > 0:
                before = sim.twist
                sim.step(base[0], base[1], (t_ns - last_robot_ns) / NS_PER_S)
            last_robot_ns = t_ns
            x, y, _ = sim.pose
            max_speed = max(max_speed, abs(sim.twist[0]))
            if sim.collided:
                outcome = "collided"
                contact = before
                break
            if math.hypot(x - goal[0], y - goal[1]) <= tolerance:
                outcome = "reached"
                break
            if t_ns >= max_ns:
                break
            if math.hypot(x - anchor[0], y - anchor[1]) >= STALL_DISTANCE_M:
                anchor = (x, y, t_ns)
            elif t_ns - anchor[2] >= point.stall_time_s * NS_PER_S:
                outcome = "stalled"
                break
            if alive and t_ns - last_up_ns > LEASE_S * NS_PER_S:
                controller.on_operator_alive(OPERATOR_ID, False)
                alive = False
            now_ns = CLOCK0_NS + t_ns
            controller.on_scan(sim.scan(stamp_ns=now_ns), now_ns)
            ox, oy, oth = sim.odometry
            v, w = sim.twist
            controller.on_odometry(
                Odometry(now_ns, ox, oy, oth, v, w, sim.collided, map_pose=sim.pose)
            )
            out = controller.step(now_ns)
            base = (out.base.linear_mps, out.base.angular_radps)
            tel = out.telemetry
            cycles += 1
            if tel.state == "DRIVING" and tel.loop_delay_ms is not None:
                loop_delays.append(tel.loop_delay_ms)
            holding = operator.wants_move and tel.state in ("HOLD", "IDLE")
            hold_cycles += holding
            hold_events += holding and not in_hold
            in_hold = holding
            if out.result is not None:
                interventions += out.result.limiter in INTERVENING
                tally.add(out.result, dt_s)
            latency_cycles += tel.limiter == Limiter.LATENCY.value
            size = _TELEMETRY_BASE_BYTES + 8 * len(tel.scan_xy)
            arrival = down.transit(t_s, size)
            if arrival is not None:
                obs = Observation(
                    t_s,
                    tel.pose,
                    np.asarray(tel.scan_xy, dtype=np.float64),
                    tel.state,
                    tel.reason or "",
                )
                push(max(round(arrival * NS_PER_S), t_ns), _DOWN, (obs, tel))
            push(t_ns + ROBOT_PERIOD_NS, _ROBOT, None)

    elapsed = last_robot_ns / NS_PER_S
    path = sim.path_m
    counters = controller.counters
    result: dict[str, Any] = {
        **point.identity(),
        "outcome": outcome,
        "reached": outcome == "reached",
        "collided": outcome == "collided",
        "time_s": round(elapsed, 3),
        "path_m": round(path, 4),
        "min_clearance_m": round(sim.min_clearance_m, 4),
        "mean_speed_mps": round(path / elapsed, 4) if elapsed > 0 else 0.0,
        "hold_s": round(hold_cycles * dt_s, 3),
        "hold_events": hold_events,
        "interventions": interventions,
        # DESIGN 13 (egc_robot.intervention); its hold_s is filter_hold_s here, since DESIGN 10
        # pins hold_s for the robot's holds (HOLD / IDLE while the operator wants to move).
        **{
            ("filter_" + k if k in ("hold_s", "commands") else k): v
            for k, v in tally.as_dict().items()
        },
        "cmd_age_p50_ms": _percentile(ages_ms, 50),
        "cmd_age_p99_ms": _percentile(ages_ms, 99),
        "stale_rejected": counters.rejected.get(RejectReason.STALE.value, 0),
        "link_aware": point.link_aware,
        "latency_turn_cap": point.latency_turn_cap,
        "outages": [list(o) for o in point.outages],
        "rate_kbps": point.rate_kbps,
        "dist": point.dist,
        "max_speed_mps": round(max_speed, 4),
        "contact_speed_mps": round(abs(contact[0]), 4) if outcome == "collided" else None,
        "contact_turn_radps": round(abs(contact[1]), 4) if outcome == "collided" else None,
        "latency_limited_s": round(latency_cycles * dt_s, 3),
        "loop_delay_p50_ms": _percentile(loop_delays, 50),
        "profile": point.profile,
        "start": list(start),
        "goal": list(goal),
        "max_time_s": point.max_time_s,
        "goal_distance_m": round(math.hypot(sim.pose[0] - goal[0], sim.pose[1] - goal[1]), 4),
        "cycles": cycles,
        "commands_sent": sent,
        "commands_lost": up.dropped_total,
        "telemetry_lost": down.dropped_total,
        "rejected": counters.rejected_total,
        "wall_s": round(time.perf_counter() - wall0, 3),
    }
    missing = [k for k in RESULT_KEYS if k not in result]
    assert not missing, missing
    return result
