"""Two ways the sweep's model of the base was wrong (outside checks, issue 10: no collision,
ever, in shared mode):

- the stop after the deadman is released (HOLD, IDLE) ramped v and w each at its own limit, so
  a Jackal released from a full-speed curve stopped turning after 0.33 s while it still rolled
  for 0.67 s, left the arc the sweep had checked and hit a wall (dwa and assist, 5 of ~1,700
  episodes); it now brakes on the arc (``safety.decelerate``);
- the sweep assumed a 0.05 s control period whatever the period was: at ``--dt 0.1`` a Jackal
  under DWA hit walls in 16 of 20 random worlds, under egc and ek-egc in 1. The period is now
  the control period, and one longer than ``MAX_CONTROL_PERIOD_S`` is refused.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from egc_common.errors import UsageError
from egc_common.profiles import JACKAL, PIONEER3DX
from egc_experiments.episode import EpisodeSettings, run_settings
from egc_robot.safety import MAX_CONTROL_PERIOD_S, decelerate

MRPB = Path(__file__).resolve().parents[2].parent / "shared" / "worlds" / "mrpb"


@pytest.mark.parametrize("profile", [JACKAL, PIONEER3DX], ids=lambda p: p.name)
@pytest.mark.parametrize("v, w", [(2.0, 2.0), (-2.0, 2.0), (0.5, -3.0), (1.0, 0.0), (0.0, 1.5)])
def test_a_controlled_stop_stays_on_the_arc_and_ends_when_the_sweep_says(profile, v, w):
    v, w = max(-profile.v_max_mps, min(profile.v_max_mps, v)), w
    w = max(-profile.w_max_radps, min(profile.w_max_radps, w))
    dt = 0.05
    t_brake = max(abs(v) / profile.decel_max_mps2, abs(w) / profile.angular_accel_max_radps2)
    cmd, steps = (v, w), 0
    while cmd != (0.0, 0.0):
        nxt = decelerate(cmd, dt, profile)
        assert abs(cmd[0] - nxt[0]) <= profile.decel_max_mps2 * dt + 1e-12
        assert abs(cmd[1] - nxt[1]) <= profile.angular_accel_max_radps2 * dt + 1e-12
        if nxt[0] != 0.0 and v != 0.0:
            assert nxt[1] / nxt[0] == pytest.approx(w / v, rel=1e-12)  # the same curvature
        cmd, steps = nxt, steps + 1
    assert steps == math.ceil(t_brake / dt - 1e-9)


def _release_file(path: Path, rows: list[str]) -> str:
    path.write_text("t_s,x,y,deadman,mode\n" + "\n".join(rows) + "\n")
    return str(path)


@pytest.mark.skipif(not MRPB.is_dir(), reason=f"MRPB maps not found at {MRPB}")
@pytest.mark.parametrize(
    "world, start, rows, filter_name, seed, max_time",
    [
        (
            "narrow_graph",
            (5.125, -2.525, 1.5708),
            ["0,1,-0.6,1,shared", "2.05,0,0,0,shared"],
            "assist",
            5113,
            5.05,
        ),
        (
            "shopping_mall",
            (-2.325, 13.425, -0.7854),
            ["0,-1,0.6,1,shared", "3.26,0,0,0,shared"],
            "assist",
            5172,
            6.26,
        ),
        (
            "empty_world",
            (-1.575, -1.275, -1.5708),
            ["0,1,0.8,1,shared", "3.64,0,0,0,shared"],
            "dwa",
            5015,
            7.0,
        ),
    ],
)
def test_releasing_the_deadman_in_a_fast_curve_does_not_leave_the_arc_into_a_wall(
    tmp_path, world, start, rows, filter_name, seed, max_time
):
    stick = _release_file(tmp_path / "release.csv", rows)
    settings = EpisodeSettings(
        map=str(MRPB / world / "map.yaml"),
        start=start,
        goal=(0.0, 0.0),
        operator=stick,
        filter=filter_name,
        profile="jackal",
        max_time_s=max_time,
        seed=seed,
        via="none",
    )
    _, summary = run_settings(settings)
    assert not summary["collided"], summary


@pytest.mark.parametrize("filter_name", ["egc", "dwa"])
@pytest.mark.parametrize("seed", [5101, 5102, 5103])
def test_a_longer_control_period_is_swept_as_such(filter_name, seed):
    settings = EpisodeSettings(
        map=f"random:{seed}",
        seed=seed,
        profile="jackal",
        operator="goal",
        filter=filter_name,
        dt_s=MAX_CONTROL_PERIOD_S,
        max_time_s=20.0,
        stall_time_s=5.0,
    )
    _, summary = run_settings(settings)
    assert not summary["collided"], summary


def test_a_control_period_beyond_what_the_sweep_holds_for_is_refused():
    settings = EpisodeSettings(map="random:1", dt_s=0.2)
    with pytest.raises(UsageError, match=r"--dt must be at most 0\.1 s"):
        run_settings(settings)
