"""Draw plans on the arena (matplotlib, the `plot` extra): the grid's inflated cells and turn
costs, obstacles, each leg, and the footprint along the way.

    python -m ramp.autonomy.planning.plot -o docs/img/planning.png

draws SPEC 6.1's example world: from the left start box to the first digging spot, back to
the collector (approach, then the straight reverse), and out to the next spot. `draw_plan`
is for any caller that wants the same picture of its own plans.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Sequence
from typing import Any

import numpy as np

from ramp.autonomy.planning.dig_spots import DigSites
from ramp.autonomy.planning.docking import plan_to_dock
from ramp.autonomy.planning.geometry import ArenaMap, Pose
from ramp.autonomy.planning.path import Path, end_yaw, swept_poses
from ramp.autonomy.planning.planner import Planner
from ramp.common.outputs import figure_file, save_figure

# SPEC 6.1's world-file example.
EXAMPLE_ROCKS = ({"x": 2.10, "y": 0.90, "d": 0.25}, {"x": 3.30, "y": 2.60, "d": 0.12},
                 {"x": 2.80, "y": 1.70, "d": 0.30})
EXAMPLE_CRATERS = ({"x": 3.90, "y": 1.10, "d": 0.30}, {"x": 2.40, "y": 3.20, "d": 0.20})


def draw_plan(ax: Any, planner: Planner, runs: Sequence[tuple[Pose, Sequence[Path], str]],
              *, every_m: float = 0.35) -> None:
    """Draw the arena and, for each (start pose, legs, label), the legs and footprints."""
    from matplotlib.patches import Circle, Polygon, Rectangle

    arena, grid = planner.arena, planner.loosest_grid
    extent = (0.0, arena.length, 0.0, arena.width)
    cost = np.where(grid.blocked, np.nan, grid.cost)
    ax.imshow(grid.blocked.T, origin="lower", extent=extent, cmap="Greys", vmin=0, vmax=3,
              interpolation="nearest")
    ax.imshow(cost.T, origin="lower", extent=extent, cmap="Oranges", alpha=0.35,
              interpolation="nearest")
    for d in arena.obstacles:
        ax.add_patch(Circle((d.x, d.y), d.radius, color="black"))
    ax.axvline(1.5, color="grey", lw=0.6, ls=":")
    ax.axvline(4.44, color="grey", lw=0.6, ls=":")
    ax.add_patch(Rectangle((-0.08, 1.94 - 0.825), 0.08, 1.65, color="tab:green", clip_on=False))
    colours = ("tab:blue", "tab:red", "tab:purple", "tab:brown")
    hl, hw = planner.config.robot.half_length_m, planner.config.robot.half_width_m
    for n, (start, legs, label) in enumerate(runs):
        colour = colours[n % len(colours)]
        yaw = start.yaw
        for k, leg in enumerate(legs):
            pts = leg.points
            ax.plot(pts[:, 0], pts[:, 1], color=colour, lw=1.6, ls="--" if leg.reverse else "-",
                    label=label if k == 0 else None)
            poses = swept_poses(leg, yaw)
            yaw = end_yaw(leg, yaw)
            travelled = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(poses[:, :2],
                                                                            axis=0).T))])
            marks = np.searchsorted(travelled, np.arange(0.0, travelled[-1] + 1e-9, every_m))
            for x, y, a in poses[np.unique(np.append(marks, len(poses) - 1))]:
                c, s = math.cos(a), math.sin(a)
                corners = [(x + c * u - s * v, y + s * u + c * v)
                           for u, v in ((hl, hw), (hl, -hw), (-hl, -hw), (-hl, hw))]
                ax.add_patch(Polygon(corners, fill=False, lw=0.4, color=colour, alpha=0.6))
    ax.set_xlim(-0.1, arena.length)
    ax.set_ylim(0.0, arena.width)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m), +y left")


def example(out: str) -> int:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    planner = Planner(ArenaMap.from_world(EXAMPLE_ROCKS, EXAMPLE_CRATERS))
    sites = DigSites(planner)
    start = Pose(0.75, 2.91, math.radians(90))
    dock_ref = (1.6, 1.94)
    spot, go = sites.next_spot(start, reference=dock_ref)
    if spot is None:
        sys.stderr.write(f"no digging spot: {go.reason}\n")
        return 1
    sites.mark_dug(spot)
    dug = Pose(spot.pose.x + sites.config.creep_m, spot.pose.y, 0.0)
    back, dock = plan_to_dock(planner, dug)
    if dock is None:
        sys.stderr.write(f"no way to the collector: {back.reason}\n")
        return 1
    spot2, again = sites.next_spot(dock.docked, reference=dock_ref)
    runs = [(start, go.legs, "start -> first spot"), (dug, back.legs, "back to the collector")]
    if spot2 is not None:
        runs.append((dock.docked, again.legs, "out to the next spot"))
    fig, ax = plt.subplots(figsize=(11, 6.2))
    draw_plan(ax, planner, runs)
    for trench in sites.dug:
        ax.add_patch(plt.Rectangle((trench.x0, trench.y0), trench.x1 - trench.x0,
                                   trench.y1 - trench.y0, color="tab:olive", alpha=0.6))
    ax.legend(loc="upper right", fontsize=8)
    ax.set_title("SPEC 6.1's example world. Grey: blocked to the robot's centre at the "
                 f"smallest margin ({planner.config.min_margin_m:g} m); orange: no room to spin; "
                 "dashed: reversing; olive: trench", fontsize=9)
    fig.tight_layout()
    save_figure(fig, out, dpi=110)
    sys.stdout.write(out + "\n")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m ramp.autonomy.planning.plot",
                                     description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("-o", "--out", type=figure_file, default="planning.png",
                        help="PNG file to write")
    args = parser.parse_args(argv)
    return example(args.out)


if __name__ == "__main__":
    sys.exit(main())
