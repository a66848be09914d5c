"""Draw what `ramp sim perceive` found: the localization (as thesis figure 5.39) and the
obstacle map (as figure 5.40), side by side.

Left: the level scan laid into the arena from every candidate pose the localizer kept (the
symmetric arena allows two to four), the chosen one bold, the others faint, beside the true
pose; a scan that fits its pose draws the walls. Right: the arena map with the 3D sweep's
returns as the detector saw them (coloured by height above the ground it fitted: rocks warm,
craters cool; walls and the robot's own frame left out), the true obstacles as dashed
outlines and the detected ones filled, each with its diameter. matplotlib is an optional
extra (`plot`); it is imported only here.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from firmware_like.arena import collector_span, footprint_corners
from ramp.common.outputs import save_figure

if TYPE_CHECKING:
    from matplotlib.axes import Axes

    from firmware_like.marte import MarteWorld
    from ramp.autonomy.perception.pipeline import PoseEstimate
    from ramp.simulation.perceive import PerceiveResult

CANDIDATE_COLOURS = ("#1f5fbf", "#d62728", "#2ca02c", "#9467bd")
KIND_COLOURS = {"rock": "#d62728", "crater": "#7b3fa0"}


def draw_perception(world: MarteWorld, result: PerceiveResult, path: str | Path,
                    title: str = "") -> None:
    """Write the two-panel PNG for `result` (taken in `world`) to `path`."""
    import matplotlib

    matplotlib.use("Agg")  # files only: no display needed
    import matplotlib.pyplot as plt

    fig, (ax_loc, ax_map) = plt.subplots(1, 2, figsize=(16, 5.6), layout="constrained")
    for ax in (ax_loc, ax_map):
        _arena(ax, world)
    _localization(ax_loc, world, result)
    _obstacles(ax_map, world, result)
    if title:
        fig.suptitle(title, fontsize=11)
    save_figure(fig, path, dpi=100)
    plt.close(fig)


def _arena(ax: Axes, world: MarteWorld) -> None:
    from matplotlib.patches import Rectangle

    mp, ap = world.params, world.arena
    length, width = mp.arena_length, mp.arena_width
    for x0, x1, colour in ((0.0, mp.start_region_end, "#2ca02c"),
                           (mp.start_region_end, mp.dig_region_start, "#ff7f0e"),
                           (mp.dig_region_start, length, "#1f77b4")):
        ax.add_patch(Rectangle((x0, 0.0), x1 - x0, width, color=colour, alpha=0.06, zorder=0))
    ax.plot([0.0, mp.start_region_end], [ap.start_split_y] * 2, ls="--", lw=0.8, c="#2ca02c")
    lo, hi = collector_span(mp)
    ax.add_patch(Rectangle((-ap.collector_depth, lo), ap.collector_depth, hi - lo,
                           facecolor="#e6d36b", edgecolor="#8a7a1c", hatch="//", zorder=1))
    ax.add_patch(Rectangle((0.0, 0.0), length, width, fill=False, lw=2.5, ec="#333333",
                           zorder=2))
    ax.set_xlim(-ap.collector_depth - 0.1, length + 0.1)
    ax.set_ylim(-0.15, width + 0.15)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m), +y on the left facing +x")


def _footprint(ax: Axes, world: MarteWorld, x: float, y: float, yaw: float, colour: str,
               *, lw: float = 1.5, ls: str = "-", alpha: float = 1.0, label: str = "") -> None:
    from matplotlib.patches import Polygon

    mp = world.params
    fl, fr, rl, rr = footprint_corners(x, y, yaw, mp.robot_length, mp.robot_width)
    ax.add_patch(Polygon([fl, fr, rr, rl], closed=True, fill=False, edgecolor=colour, lw=lw,
                         ls=ls, alpha=alpha, zorder=7 if ls != "-" else 6,
                         label=label or None))
    ax.annotate("", xy=((fl[0] + fr[0]) / 2, (fl[1] + fr[1]) / 2), xytext=(x, y),
                arrowprops={"arrowstyle": "->", "lw": lw, "color": colour, "alpha": alpha},
                zorder=6)


def _same(a: PoseEstimate, b: PoseEstimate) -> bool:
    return (math.hypot(a.x - b.x, a.y - b.y) < 0.01
            and abs(math.remainder(a.yaw - b.yaw, 2 * math.pi)) < math.radians(1.0))


def _localization(ax: Axes, world: MarteWorld, result: PerceiveResult) -> None:
    from ramp.autonomy.perception.pipeline import fuse_scans

    loc = result.localization
    candidates: list[PoseEstimate] = list(loc.candidates)
    chosen = loc.pose if not loc.lost else None
    if chosen is not None and not any(_same(c, chosen) for c in candidates):
        candidates.insert(0, chosen)
    record = fuse_scans(result.level_records)[0] if result.level_records else None
    for i, c in enumerate(candidates[:len(CANDIDATE_COLOURS)]):
        is_chosen = chosen is not None and _same(c, chosen)
        colour = CANDIDATE_COLOURS[i]
        alpha = 1.0 if is_chosen else 0.45
        if record is not None:
            pts = record.points_arena(c.x, c.y, c.yaw)
            ax.scatter(pts[:, 0], pts[:, 1], s=2.5 if is_chosen else 1.5, color=colour,
                       alpha=alpha, zorder=5)
        what = (f"chosen (confidence {chosen.confidence:.2f})" if is_chosen and chosen
                else f"candidate (p {c.confidence:.2f})")
        _footprint(ax, world, c.x, c.y, c.yaw, colour, lw=2.0 if is_chosen else 1.0,
                   alpha=alpha, label=f"{what}: x {c.x:.2f} y {c.y:.2f} "
                                      f"yaw {math.degrees(c.yaw):.1f}°")
    tx, ty, tyaw = result.true_pose
    _footprint(ax, world, tx, ty, tyaw, "#000000", lw=1.0, ls="--", label="true pose")
    if loc.lost:
        ax.text(0.5, 0.5, f"LOST: {_wrap(loc.reason)}", transform=ax.transAxes, ha="center",
                va="center", fontsize=10, color="#d62728",
                bbox={"facecolor": "white", "alpha": 0.85, "edgecolor": "#d62728"})
    ax.legend(loc="lower right", fontsize=7.5, framealpha=0.9)
    fixes = "".join(f", re-levelled from the {f.source} ({f.deg:.1f}°)"
                    for f in result.level_fixes)
    if result.retakes:
        fixes += ", scanned again after the IMU moved"
    ax.set_title(f"Localization: the level scan laid in from each candidate pose{fixes}",
                 fontsize=10)


def _wrap(text: str, width: int = 70) -> str:
    import textwrap

    return "\n".join(textwrap.wrap(text, width))


def _obstacles(ax: Axes, world: MarteWorld, result: PerceiveResult) -> None:
    from matplotlib.patches import Circle

    pose = result.localization.pose
    det = result.detection
    if pose is not None and det is not None and len(det.cloud):
        pts, h = det.cloud.points, det.heights
        shown = np.isfinite(h) & (np.arange(len(h)) % 3 == 0)
        sc = ax.scatter(pts[shown, 0], pts[shown, 1], c=np.clip(h[shown], -0.15, 0.15), s=0.6,
                        cmap="coolwarm", vmin=-0.15, vmax=0.15, zorder=3, rasterized=True)
        ax.figure.colorbar(sc, ax=ax, shrink=0.6, pad=0.01,
                           label="return above the ground the robot fitted (m)")
        _footprint(ax, world, pose.x, pose.y, pose.yaw, "#1f5fbf", label="estimated pose")
    for o in result.true_obstacles:
        ax.add_patch(Circle((o.x, o.y), o.d / 2, fill=False, edgecolor=KIND_COLOURS[o.kind],
                            lw=1.2, ls="--", zorder=4))
    for o in result.obstacles:
        colour = KIND_COLOURS.get(o.kind, "#333333")
        ax.add_patch(Circle((o.x, o.y), o.d / 2, facecolor=colour, alpha=0.55,
                            edgecolor=colour, zorder=5))
        ax.annotate(f"{o.kind} {o.d * 100:.0f} cm", (o.x, o.y + o.d / 2 + 0.03), fontsize=7,
                    ha="center", va="bottom", zorder=6)
    ax.scatter([], [], marker="o", facecolors="none", edgecolors="#555555",
               label="true obstacles (dashed)")
    ax.scatter([], [], marker="o", color=KIND_COLOURS["rock"], label="detected rock")
    ax.scatter([], [], marker="o", color=KIND_COLOURS["crater"], label="detected crater")
    ax.legend(loc="lower right", fontsize=7.5, framealpha=0.9)
    n = len(result.sweep_records)
    ax.set_title(f"Obstacles: {len(result.obstacles)} detected from a {n}-scan stop-and-go "
                 f"sweep ({len(result.true_obstacles)} in the world)", fontsize=10)
