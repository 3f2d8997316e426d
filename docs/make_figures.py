"""Regenerate the figures of the paper's hallway experiment (Park & Kim 2014, sec. 4.2).

Runs the built-in ``hallway`` world with the stick held forward and the EGC filter on, through
the robot's own command pipeline (``egc_experiments.episode``), and draws

- ``docs/fig9_hallway_trajectory.png`` (after Fig. 9): the map, the areas A-D and the robot's
  footprint every 2 s along its path;
- ``docs/fig11_commands.png`` (after Fig. 11): the reference commands of the operator (blue) and
  the commands the filter sent to the base (red), linear and angular, over time.

    python docs/make_figures.py [--out-dir docs]
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
from egc_common.profiles import get_profile
from egc_experiments.episode import EpisodeSettings, run_settings
from egc_sim.episodes import EpisodeResult
from egc_sim.worlds import World, load_world
from matplotlib.patches import Polygon, Rectangle

FOOTPRINT_EVERY_S = 2.0


def footprint(
    x: float, y: float, yaw: float, length: float, width: float
) -> list[tuple[float, float]]:
    c, s = math.cos(yaw), math.sin(yaw)
    corners = (
        (0.5 * length, 0.5 * width),
        (-0.5 * length, 0.5 * width),
        (-0.5 * length, -0.5 * width),
        (0.5 * length, -0.5 * width),
    )
    return [(x + c * u - s * v, y + s * u + c * v) for u, v in corners]


def trajectory_figure(world: World, result: EpisodeResult, profile_name: str, path: Path) -> None:
    profile = get_profile(profile_name)
    fig, ax = plt.subplots(figsize=(12, 3.2))
    extent = (
        world.origin_x_m,
        world.origin_x_m + world.width_m,
        world.origin_y_m,
        world.origin_y_m + world.height_m,
    )
    ax.imshow(world.occupancy, origin="lower", extent=extent, cmap="Greys", vmin=0, vmax=1.6)
    for area in world.areas:
        ax.add_patch(
            Rectangle(
                (area.x_min_m, area.y_min_m),
                area.x_max_m - area.x_min_m,
                area.y_max_m - area.y_min_m,
                fill=False,
                ls="--",
                ec="tab:orange",
            )
        )
        ax.text(
            0.5 * (area.x_min_m + area.x_max_m),
            area.y_max_m + 0.05,
            area.name,
            ha="center",
            va="bottom",
            color="tab:orange",
            fontsize=12,
            weight="bold",
        )
    every = max(1, round(FOOTPRINT_EVERY_S / (result.trace[1].t_s - result.trace[0].t_s)))
    for row in result.trace[::every]:
        ax.add_patch(
            Polygon(
                footprint(row.x_m, row.y_m, row.yaw_rad, profile.length_m, profile.width_m),
                closed=True,
                fill=False,
                ec="tab:blue",
                lw=0.8,
            )
        )
    ax.plot([r.x_m for r in result.trace], [r.y_m for r in result.trace], color="tab:blue", lw=0.6)
    if world.start_pose is not None:
        ax.plot(*world.start_pose[:2], "go", label="start")
    if world.goal is not None:
        ax.plot(*world.goal, "r*", ms=12, label="goal")
    ax.set_xlim(extent[0], extent[1])
    ax.set_ylim(extent[2], extent[3] + 0.4)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(
        f"Hallway, constant forward command, EGC on: {result.outcome}, "
        f"{result.path_m:.1f} m in {result.time_s:.0f} s, "
        f"min clearance {result.min_clearance_m:.2f} m"
    )
    ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def commands_figure(world: World, result: EpisodeResult, path: Path) -> None:
    t = [r.t_s for r in result.trace]
    fig, (ax_v, ax_w) = plt.subplots(2, 1, figsize=(10, 5), sharex=True)
    ax_v.plot(
        t, [r.v_ref_mps for r in result.trace], color="tab:blue", label="reference (operator)"
    )
    ax_v.plot(
        t, [r.v_cmd_mps for r in result.trace], color="tab:red", lw=0.8, label="modified (EGC)"
    )
    ax_w.plot(t, [r.w_ref_radps for r in result.trace], color="tab:blue")
    ax_w.plot(t, [r.w_cmd_radps for r in result.trace], color="tab:red", lw=0.8)
    # Shade the time spent in each area.
    for area in world.areas:
        inside = [r.t_s for r in result.trace if area.contains(r.x_m, r.y_m)]
        if inside:
            for ax in (ax_v, ax_w):
                ax.axvspan(min(inside), max(inside), color="tab:orange", alpha=0.12)
            ax_v.text(
                0.5 * (min(inside) + max(inside)),
                0.165,
                area.name,
                ha="center",
                color="tab:orange",
                weight="bold",
            )
    ax_v.set_ylabel("v [m/s]")
    ax_v.set_ylim(-0.02, 0.18)
    ax_w.set_ylabel("w [rad/s]")
    ax_w.set_xlabel("t [s]")
    ax_v.legend(loc="lower right", fontsize=8)
    ax_v.set_title("Reference vs modified commands (after the paper's Fig. 11)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out-dir", default=str(Path(__file__).resolve().parent))
    args = ap.parse_args(argv)
    out = Path(args.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    settings = EpisodeSettings("hallway", operator="forward", filter="egc")
    result, _ = run_settings(settings, record_trace=True)
    world = load_world("hallway")
    trajectory_figure(world, result, settings.profile, out / "fig9_hallway_trajectory.png")
    commands_figure(world, result, out / "fig11_commands.png")
    print(f"wrote {out / 'fig9_hallway_trajectory.png'} and {out / 'fig11_commands.png'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
