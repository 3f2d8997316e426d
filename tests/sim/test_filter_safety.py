"""Whatever the operator does, the filtered robot does not touch anything (random sticks)."""

from __future__ import annotations

import numpy as np
import pytest
from egc_experiments.episode import EpisodeSettings
from egc_experiments.episode_batch import run_batch


def random_stick_file(path, seed: int, duration_s: float = 30.0) -> str:
    """A wandering joystick: a random walk of both axes, mostly forward, deadman held."""
    rng = np.random.default_rng(seed)
    x = y = t = 0.0
    rows = ["t_s,x,y,deadman,mode"]
    while t < duration_s:
        x = float(np.clip(abs(x + rng.normal(0.0, 0.4)), -1.0, 1.0))
        y = float(np.clip(y + rng.normal(0.0, 0.5), -1.0, 1.0))
        rows.append(f"{t:.2f},{x:.3f},{y:.3f},1,shared")
        t += float(rng.uniform(0.2, 1.5))
    path.write_text("\n".join(rows) + "\n")
    return str(path)


@pytest.mark.slow
def test_random_sticks_collide_in_direct_mode_never_with_egc(tmp_path):
    settings = []
    for k in range(8):
        stick = random_stick_file(tmp_path / f"stick{k}.csv", k)
        for mode in ("none", "egc"):
            settings.append(
                EpisodeSettings(
                    f"random:{100 + k}",
                    operator=stick,
                    filter=mode,
                    profile="jackal" if k % 2 else "pioneer3dx",
                    max_time_s=30.0,
                    seed=100 + k,
                )
            )
    rows = list(run_batch(settings, jobs=2, progress=False))
    direct = [r for r in rows if r["filter"] == "none"]
    egc = [r for r in rows if r["filter"] == "egc"]
    assert sum(r["collided"] for r in direct) >= 4  # the sticks are reckless
    assert not any(r["collided"] for r in egc), [r["map"] for r in egc if r["collided"]]
    assert sum(r["path_m"] for r in egc) > 5.0  # and the filtered robots did drive
