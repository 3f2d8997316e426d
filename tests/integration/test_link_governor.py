"""The latency governor end to end (DESIGN 9, issue 12): direct mode through ``egc-teleop link``.

The operator (a real process, stick forward in ``direct`` mode) reaches the robot through a TCP
relay adding 150 ms each way (a 300 ms round trip; one-way 300 ms would put every direct-mode
command past its 300 ms ``max_command_age``). The robot's telemetry (watched directly, not through
the relay) must show the cap of DESIGN 9 computed from the loop delay it reports, the command
scaled to it, and ``latency`` as the limiter.
"""

from __future__ import annotations

import math
import time

import pytest
from egc_common.messages import Telemetry
from egc_common.profiles import PIONEER3DX
from egc_robot.latency_governor import latency_speed_limit

from tests.integration.harness import joystick_file, operator_args
from tests.integration.test_link import finish, start_robot
from tests.integration.test_link_outage import start_relay

pytestmark = [pytest.mark.integration, pytest.mark.timeout(120)]


def test_direct_mode_through_a_300_ms_round_trip_is_capped_by_the_formula(
    port, procs, observer, tmp_path
):
    start_robot(procs, observer, port)
    relay_port, _ = start_relay(procs, port, "delay=150,jitter=10")
    rows = [(0, 0, 0, 1), (0.5, 1, 0, 1), (60, 1, 0, 1)]
    lines = ["t_s,x,y,deadman,mode"] + [f"{t},{x},{y},{d},direct" for t, x, y, d in rows]
    js = joystick_file(tmp_path / "fwd.csv", [])
    js.write_text("\n".join(lines) + "\n")
    procs.start("op", *operator_args(relay_port, "alice", js))
    observer.wait_for(
        "capped driving",
        lambda: sum(t.limiter == "latency" for t in observer.telemetry()) >= 40,
        30,
    )
    since = time.monotonic_ns()

    def capped() -> list[Telemetry]:
        return [t for t in observer.telemetry(since) if t.limiter == "latency"]

    # 30 s: a machine busy enough to hold the robot for a link gap (it resumes by itself)
    observer.wait_for("15 more capped cycles", lambda: len(capped()) >= 15, 30)
    for t in capped():
        assert t.mode == "direct" and t.state == "DRIVING"
        tau_s = t.loop_delay_ms / 1e3
        # tau: p90 command age (~150 ms + jitter) + view age (~150 ms + up to a cycle) + 0.25 s
        # = 0.55-0.65 s; a busy machine adds its scheduling delays to both ages
        assert 0.5 < tau_s < 1.2, tau_s
        expected = latency_speed_limit(tau_s, PIONEER3DX.v_max_mps, PIONEER3DX.decel_max_mps2, 0.5)
        assert t.v_lim_latency == pytest.approx(expected, rel=1e-9)
        assert t.v_cmd == pytest.approx(expected, rel=1e-9)  # scaled to the cap exactly
        assert t.v_cmd < 0.8 * PIONEER3DX.v_max_mps
        assert math.isclose(t.w_cmd, 0.0, abs_tol=1e-12)  # straight: same curvature
    finish(procs, observer)
