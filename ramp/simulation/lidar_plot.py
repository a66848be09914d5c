"""Draw one emulated LIDAR scan over the arena map, so a person can check the emulator.

Left: the arena from above (SPEC 6.1 frame, +y to the left of +x, so y grows upwards on the
page with x to the right): regions, start boxes, collector bin, the ground's height field,
rocks and craters, the robot's footprint and the scanner, a fan of beams, and every hit point
coloured by what it hit. Right: the same scan as range and as hit height against the beam's
angle, as the sensor would report it. matplotlib is an optional extra (`pip install
'ramp[plot]'`); it is imported only here.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from firmware_like.arena import collector_span, footprint_corners
from firmware_like.arena_params import HIT_NAMES, HIT_NONE
from ramp.common.outputs import save_figure

if TYPE_CHECKING:
    from firmware_like.lidar_view import Scan
    from firmware_like.marte import MarteWorld

#: Colour of each hit kind (index = arena_params.HIT_*).
HIT_COLOURS = ("#bbbbbb", "#1f5fbf", "#c08a3e", "#d62728", "#7b3fa0", "#111111", "#8c8c8c")


def draw_scan(world: MarteWorld, scan: Scan, angles: np.ndarray, path: str | Path, *,
              pan_deg: float, tilt_deg: float) -> None:
    """Write a PNG of `scan` taken in `world` to `path`; `angles` (rad) of each step."""
    import matplotlib

    matplotlib.use("Agg")  # files only: no display needed on a robot or in CI
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle, Polygon, Rectangle

    mp, ap = world.params, world.arena
    length, width = mp.arena_length, mp.arena_width
    fig = plt.figure(figsize=(15, 6.2), layout="constrained")
    grid = fig.add_gridspec(2, 2, width_ratios=(2.1, 1.0))
    ax = fig.add_subplot(grid[:, 0])
    ax_r = fig.add_subplot(grid[0, 1])
    ax_z = fig.add_subplot(grid[1, 1], sharex=ax_r)

    # Ground height field as a faint background: rocks stand out light, craters dark.
    xs = np.linspace(0.0, length, 370)
    ys = np.linspace(0.0, width, 195)
    gx, gy = np.meshgrid(xs, ys)
    heights = world.terrain.height(gx, gy)
    image = ax.imshow(heights, origin="lower", extent=(0.0, length, 0.0, width),
                      cmap="BrBG_r", vmin=-0.15, vmax=0.15, alpha=0.55, zorder=0)
    fig.colorbar(image, ax=ax, shrink=0.6, pad=0.01, label="surface height (m)")

    # Regions and start boxes.
    for x0, x1, colour, label in ((0.0, mp.start_region_end, "#2ca02c", "start"),
                                  (mp.start_region_end, mp.dig_region_start, "#ff7f0e",
                                   "obstacles"),
                                  (mp.dig_region_start, length, "#1f77b4", "digging")):
        ax.add_patch(Rectangle((x0, 0.0), x1 - x0, width, color=colour, alpha=0.07, zorder=0))
        ax.text((x0 + x1) / 2, width + 0.06, label, ha="center", va="bottom", fontsize=9)
    ax.plot([0.0, mp.start_region_end], [ap.start_split_y] * 2, ls="--", lw=0.8, c="#2ca02c")
    ax.text(0.05, ap.start_split_y + 0.05, "left box", fontsize=8, color="#2ca02c")
    ax.text(0.05, ap.start_split_y - 0.15, "right box", fontsize=8, color="#2ca02c")
    for x in (mp.start_region_end, mp.dig_region_start):
        ax.axvline(x, color="#888888", lw=0.6, ls=":")
    lo, hi = collector_span(mp)
    ax.add_patch(Rectangle((-ap.collector_depth, lo), ap.collector_depth, hi - lo,
                           facecolor="#e6d36b", edgecolor="#8a7a1c", hatch="//", zorder=1))
    ax.text(-ap.collector_depth / 2, (lo + hi) / 2, "collector", rotation=90, ha="center",
            va="center", fontsize=8)
    ax.add_patch(Rectangle((0.0, 0.0), length, width, fill=False, lw=3.0, ec="#333333",
                           zorder=2))

    for i, rock in enumerate(world.layout.rocks):
        ax.add_patch(Circle((rock.x, rock.y), rock.radius, facecolor="#9a8f85",
                            edgecolor="#d62728", lw=1.2, zorder=3))
        ax.annotate(f"rock {i}\n{rock.height:.2f} m", (rock.x, rock.y + rock.radius),
                    fontsize=7, ha="center", va="bottom", zorder=6)
    for i, crater in enumerate(world.layout.craters):
        ax.add_patch(Circle((crater.x, crater.y), crater.radius, facecolor="#3b2a1a",
                            edgecolor="#7b3fa0", lw=1.2, ls="--", zorder=3))
        ax.annotate(f"crater {i}\n-{crater.depth:.2f} m", (crater.x, crater.y + crater.radius),
                    fontsize=7, ha="center", va="bottom", zorder=6)

    corners = footprint_corners(world.x, world.y, world.heading, mp.robot_length,
                                mp.robot_width)
    fl, fr, rl, rr = corners
    ax.add_patch(Polygon([fl, fr, rr, rl], closed=True, facecolor="#ffffff", alpha=0.7,
                         edgecolor="#000000", lw=1.5, zorder=4))
    ax.annotate("", xy=((fl[0] + fr[0]) / 2, (fl[1] + fr[1]) / 2), xytext=(world.x, world.y),
                arrowprops={"arrowstyle": "->", "lw": 1.5}, zorder=5)

    origin = scan.pose.origin
    points = scan.points()
    hit = scan.kinds != HIT_NONE
    for k in np.nonzero(hit)[0][::12]:  # a fan of beams, every 3 degrees
        ax.plot([origin[0], points[k, 0]], [origin[1], points[k, 1]], lw=0.3,
                color=HIT_COLOURS[scan.kinds[k]], alpha=0.35, zorder=4)
    angles = np.degrees(angles)
    for kind, name in enumerate(HIT_NAMES):
        mask = scan.kinds == kind
        if kind == HIT_NONE or not mask.any():
            continue
        label = f"{name} ({int(mask.sum())})"
        ax.scatter(points[mask, 0], points[mask, 1], s=5, color=HIT_COLOURS[kind],
                   label=label, zorder=5)
        ax_r.scatter(angles[mask], scan.ranges[mask], s=3, color=HIT_COLOURS[kind])
        ax_z.scatter(angles[mask], points[mask, 2], s=3, color=HIT_COLOURS[kind])
    ax.plot(origin[0], origin[1], marker="o", ms=6, mec="#000000", mfc="#ffdd00", zorder=6)
    none = int((~hit).sum())
    ax.scatter([], [], s=5, color=HIT_COLOURS[HIT_NONE], label=f"no echo ({none})")
    ax.legend(loc="lower right", fontsize=8, framealpha=0.9, markerscale=2.5)
    ax.set_xlim(-ap.collector_depth - 0.1, length + 0.1)
    ax.set_ylim(-0.1, width + 0.35)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m), +y on the left facing +x")
    ax.set_title(f"{world.layout.source}: robot at x {world.x:.2f} m, y {world.y:.2f} m, "
                 f"yaw {world.heading_deg:.0f}°; pan {pan_deg:g}°, tilt {tilt_deg:g}° down; "
                 f"chassis pitch {math.degrees(world.pitch):.1f}°, "
                 f"roll {math.degrees(world.roll):.1f}°", fontsize=10)

    ax_r.set_ylabel("range (m)")
    ax_r.set_title("the scan as the sensor reports it (step 540 = 0°, CCW +)", fontsize=9)
    ax_r.grid(alpha=0.3)
    ax_z.axhline(0.0, color="#c08a3e", lw=0.6)
    ax_z.set_ylabel("hit height z (m)")
    ax_z.set_xlabel("beam angle (deg)")
    ax_z.grid(alpha=0.3)
    ax_z.set_xlim(-136, 136)
    save_figure(fig, path, dpi=110)
    plt.close(fig)

