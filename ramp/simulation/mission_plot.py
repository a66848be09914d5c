"""`ramp sim mission --plot`: one picture of a whole run (thesis figures 5.38-5.40 in one).

The map: the arena's walls and regions, the collector, the true rocks and craters (filled),
what the 3D scan detected (red circles) and the disc the planner kept off (dashed), every
plan the mission made (thin, dashed where driven backwards), the path the robot really drove
(from the ground truth, coloured by what the mission was doing), the trenches dug, the
start and end footprints, and any collision or crater entry (red crosses). Below it, the bin
and the delivered regolith over time, on bands of the mission's states. matplotlib (the
`plot` extra).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from ramp.autonomy.executive.scan import coverage_of
from ramp.common.outputs import save_figure

if TYPE_CHECKING:
    from ramp.simulation.mission import MissionRun

#: What the driven path is coloured by: the mission's states, grouped.
PHASES = {
    "sensing": ("initial_localization", "scan_for_obstacles", "detect_obstacles", "relevel",
                "rescan", "relocalize"),
    "to the vantage point": ("prepare_for_scan",),
    "out to dig": ("plan_path_to_dig", "cross_to_dig"),
    "digging": ("excavate",),
    "home": ("plan_path_home", "cross_home"),
    "at the collector": ("dock", "deposit", "decouple"),
    "stopped / waiting": ("stop", "paused", "waiting_for_operator", "done", "idle",
                          "acquire_control"),
}
COLOURS = {"sensing": "tab:purple", "to the vantage point": "tab:cyan",
           "out to dig": "tab:blue", "digging": "tab:olive", "home": "tab:orange",
           "at the collector": "tab:green", "stopped / waiting": "tab:grey"}
PHASE_OF = {state: phase for phase, states in PHASES.items() for state in states}


def draw_mission(run: MissionRun, path: str) -> None:
    """Write the picture of `run` (after `run.run()`) to `path`."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, tl) = plt.subplots(2, 1, figsize=(11, 8.2),
                                 gridspec_kw={"height_ratios": [3.2, 1.0]})
    _map(ax, run)
    _timeline(tl, run)
    o = run.options
    s = run.summary()
    fig.suptitle(f"ramp sim mission: {run.world.layout.source}, start {s['start_box']} box "
                 f"heading {s['heading']}, fault {o.fault} — {s['outcome']}, "
                 f"{s['delivered_kg']:.1f} kg delivered, {s['collisions']} collisions, "
                 f"{s['crater_entries']} crater entries", fontsize=10)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)
    plt.close(fig)


def _footprint(ax: Any, x: float, y: float, yaw_deg: float, **style: Any) -> None:
    from matplotlib.patches import Polygon

    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    hl, hw = 0.6, 0.375
    corners = [(x + c * u - s * v, y + s * u + c * v)
               for u, v in ((hl, hw), (hl, -hw), (-hl, -hw), (-hl, hw))]
    ax.add_patch(Polygon(corners, fill=False, **style))


def _map(ax: Any, run: MissionRun) -> None:
    from matplotlib.lines import Line2D
    from matplotlib.patches import Circle, Rectangle

    w = run.world
    d = w.describe()
    arena = d["arena"]
    length, width = arena["length"], arena["width"]  # type: ignore[index]
    ax.add_patch(Rectangle((0, 0), length, width, fill=False, lw=2.0, color="black"))
    for x in (arena["start_end_x"], arena["obstacle_end_x"]):  # type: ignore[index]
        ax.axvline(x, color="grey", lw=0.7, ls=":")
    ax.plot([0, arena["start_end_x"]], [arena["start_split_y"]] * 2,  # type: ignore[index]
            color="grey", lw=0.7, ls=":")
    cy, cw = arena["collector_y"], arena["collector_width"]  # type: ignore[index]
    ax.add_patch(Rectangle((-0.12, cy - cw / 2), 0.12, cw, color="tab:green", clip_on=False))
    ax.text(-0.14, cy, "collector", rotation=90, va="center", ha="right", fontsize=8,
            color="tab:green")
    for r in d["rocks"]:  # type: ignore[attr-defined]
        ax.add_patch(Circle((r["x"], r["y"]), r["d"] / 2, color="saddlebrown", alpha=0.8))
    for c in d["craters"]:  # type: ignore[attr-defined]
        ax.add_patch(Circle((c["x"], c["y"]), c["d"] / 2, color="navy", alpha=0.55))
    kit = run.autonomy.kit if run.autonomy is not None else None
    ctx = run.autonomy.context if run.autonomy is not None else None
    if kit is not None:
        for o in kit.log["obstacles"]:
            ax.add_patch(Circle((o.x, o.y), o.d / 2, fill=False, color="red", lw=1.2))
    if ctx is not None:
        coverage = coverage_of(ctx)
        if coverage is not None:
            cell = coverage.cell_m
            for x, y in coverage.poorly_seen_centres().tolist():
                ax.add_patch(Rectangle((x - cell / 2, y - cell / 2), cell, cell, lw=0,
                                       color="grey", alpha=0.18))
        for disc in (*ctx.rocks, *ctx.craters):
            ax.add_patch(Circle((disc.x, disc.y), disc.radius, fill=False, color="red",
                                lw=0.6, ls="--"))
        if ctx.dig_sites is not None:
            for t in ctx.dig_sites.dug:
                ax.add_patch(Rectangle((t.x0, t.y0), t.x1 - t.x0, t.y1 - t.y0,
                                       color="tab:olive", alpha=0.5))
    if kit is not None:
        for _kind, result in kit.log["planned"]:
            for leg in result.legs:
                pts = leg.points
                ax.plot(pts[:, 0], pts[:, 1], color="black", lw=0.5, alpha=0.45,
                        ls="--" if leg.reverse else "-")
    samples = run.samples
    if samples:
        start = 0
        for i in range(1, len(samples) + 1):
            if i == len(samples) or (PHASE_OF.get(samples[i].state)
                                     != PHASE_OF.get(samples[start].state)):
                seg = samples[max(0, start - 1):i]
                phase = PHASE_OF.get(samples[start].state, "stopped / waiting")
                ax.plot([s.x for s in seg], [s.y for s in seg], color=COLOURS[phase], lw=1.8)
                start = i
        first, last = samples[0], samples[-1]
        _footprint(ax, first.x, first.y, first.yaw, color="black", lw=1.0, ls=":")
        _footprint(ax, last.x, last.y, last.yaw, color="black", lw=1.0)
        ax.annotate("start", (first.x, first.y), fontsize=8, ha="center", va="center")
        times = [s.t for s in samples]
        for when, _what in [*w.collision_log, *w.crater_log]:
            k = min(range(len(times)), key=lambda j: abs(times[j] - when))
            ax.plot(samples[k].x, samples[k].y, "x", color="red", ms=12, mew=2.5)
    handles = [Line2D([], [], color=c, lw=1.8, label=p) for p, c in COLOURS.items()]
    handles += [Line2D([], [], color="saddlebrown", marker="o", ls="", label="rock (true)"),
                Line2D([], [], color="navy", marker="o", ls="", alpha=0.55,
                       label="crater (true)"),
                Line2D([], [], color="red", marker="o", ls="", fillstyle="none",
                       label="detected (dashed: kept off)"),
                Line2D([], [], color="black", lw=0.6, alpha=0.5, label="planned"),
                Line2D([], [], color="grey", marker="s", ls="", alpha=0.35,
                       label="seen too thinly (kept off)")]
    ax.legend(handles=handles, loc="center left", bbox_to_anchor=(1.01, 0.5), fontsize=8)
    ax.set_xlim(-0.3, length + 0.05)
    ax.set_ylim(-0.05, width + 0.05)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m) from the collector wall")
    ax.set_ylabel("y (m), +y left")


def _timeline(ax: Any, run: MissionRun) -> None:
    samples = run.samples
    if not samples:
        return
    t = [s.t for s in samples]
    start = 0
    for i in range(1, len(samples) + 1):
        if i == len(samples) or (PHASE_OF.get(samples[i].state)
                                 != PHASE_OF.get(samples[start].state)):
            phase = PHASE_OF.get(samples[start].state, "stopped / waiting")
            ax.axvspan(t[start], t[i - 1] + 0.1, color=COLOURS[phase], alpha=0.18, lw=0)
            start = i
    ax.plot(t, [s.bin_kg for s in samples], color="tab:brown", label="in the bin")
    ax.plot(t, [s.delivered_kg for s in samples], color="tab:green", lw=2.0, label="delivered")
    ax.axhline(10.0, color="tab:green", lw=0.7, ls=":")
    ax.set_xlim(t[0], t[-1])
    ax.set_xlabel("simulated time (s)")
    ax.set_ylabel("regolith (kg)")
    ax.legend(loc="upper left", fontsize=8)
