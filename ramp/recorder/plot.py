"""`ramp log plot`: the time series a team looks at after a run, on one page.

Panels, top to bottom, sharing the time axis (seconds since the recording started):
the battery voltage; the motor commands handed to each bus's drivers (wheel duties on the
Base's bus, lift and chain on the BLE's; digital outputs such as LEDs are left out); each
numeric get property by name across modules (`vel` of the wheels, lift and chain, `pos` of
the lift, `kg` of the load); the tick's lateness (p50, p99, max). Events are marked on
every panel: watchdog trips, module faults, control changes, stalls, and logged errors.

The panels come from what the file holds, not from a list of MARTE's devices, so another
robot's recording plots the same way. matplotlib is an optional extra (`pip install
'.[log]'`); everything else in `ramp log` works without it.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ramp.common.outputs import figure_path, save_figure
from ramp.recorder.reading import Msg
from ramp.recorder.schemas import (
    TOPIC_COMMANDS,
    TOPIC_EVENTS,
    TOPIC_HEALTH,
    TOPIC_LOG,
    TOPIC_MODULE_STATE,
)

#: Panel titles of the get properties MARTE's modules report (SPEC 2.1), in this order; other
#: properties follow under their own names.
PROPERTY_PANELS = {"vel": "velocity (% of full)", "pos": "position (0 retracted, 1 extended)",
                   "kg": "load (kg)"}
#: Event marks: (label, colour, line style).
MARKS = {"watchdog_trip": ("watchdog trip", "tab:red", "-"),
         "fault": ("module fault", "tab:orange", "-"),
         "control": ("control change", "tab:blue", "--"),
         "stall": ("tick stall", "tab:purple", "-"),
         "log_error": ("logged error", "0.4", ":")}

Series = dict[str, tuple[list[float], list[float]]]


@dataclass
class PlotData:
    """Time series gathered from a recording, times in seconds since its first message."""

    start: int | None = None
    battery: Series = field(default_factory=dict)
    commands: dict[str, Series] = field(default_factory=lambda: defaultdict(dict))
    props: dict[str, Series] = field(default_factory=lambda: defaultdict(dict))
    late: Series = field(default_factory=dict)
    marks: dict[str, list[float]] = field(default_factory=lambda: defaultdict(list))
    #: Watchdog trips and control changes seen in the health rows, used when the file has
    #: no event channel (events are exact; 10 Hz samples can miss a short trip).
    guessed: dict[str, list[float]] = field(default_factory=lambda: defaultdict(list))
    has_events: bool = False
    _watchdog: str | None = None
    _owner: str | None = None

    def add(self, msg: Msg) -> None:
        if self.start is None:
            self.start = msg.log_time
        topic, t_ns, data = msg
        if not isinstance(data, dict):
            return
        t = (t_ns - self.start) / 1e9
        if topic == TOPIC_COMMANDS:
            if data.get("kind") == "output":
                return  # LEDs and relays: the motor duties are what a team looks at
            bus, ch = str(data.get("bus")), str(data.get("channel"))
            _point(self.commands[bus], ch, t, data.get("duty"))
        elif topic == TOPIC_HEALTH:
            late = _prop(data, "tick", "late")
            if isinstance(late, list) and len(late) == 3:
                for name, v in zip(("p50", "p99", "max"), late, strict=True):
                    _point(self.late, name, t, v)
            wd = _prop(data, "watchdog", "state")
            if wd == "tripped" and self._watchdog != "tripped":
                self.guessed["watchdog_trip"].append(t)
            self._watchdog = wd if isinstance(wd, str) else self._watchdog
            owner = _prop(data, "control", "owner")
            if owner is not None and self._owner is not None and owner != self._owner:
                self.guessed["control"].append(t)
            self._owner = owner if isinstance(owner, str) else self._owner
        elif topic.endswith("/get"):
            module = topic[1:-4]
            for device, props in data.items():
                if not isinstance(props, dict):
                    continue
                for prop, v in props.items():
                    label = f"{module}:{device}"
                    if prop == "volt":
                        _point(self.battery, label, t, v)
                    else:
                        _point(self.props[prop], label, t, v)
        elif topic == TOPIC_EVENTS:
            self.has_events = True
            kind = data.get("kind")
            if kind in ("watchdog_trip", "control", "stall"):
                self.marks[str(kind)].append(t)
        elif topic == TOPIC_MODULE_STATE:
            if data.get("state") == "fault":
                self.marks["fault"].append(t)
        elif topic == TOPIC_LOG and int(data.get("level", 0)) >= 4:
            self.marks["log_error"].append(t)

    def all_marks(self) -> dict[str, list[float]]:
        marks = {k: v for k, v in self.marks.items() if v}
        if not self.has_events:
            marks.update({k: v for k, v in self.guessed.items() if v})
        return marks


def _prop(data: dict[str, Any], device: str, prop: str) -> Any:
    props = data.get(device)
    return props.get(prop) if isinstance(props, dict) else None


def _point(series: Series, label: str, t: float, v: Any) -> None:
    if isinstance(v, bool) or not isinstance(v, int | float):
        return
    xs, ys = series.setdefault(label, ([], []))
    xs.append(t)
    ys.append(float(v))


def _binary(series: Series) -> bool:
    return all(set(ys) <= {0.0, 1.0} for _, ys in series.values())


def plot(data: PlotData, out: Path, title: str = "") -> Path:
    """Draw the panels into `out` (PNG, or any format matplotlib knows by the suffix; `.png`
    added when there is none); returns the path written."""
    out = Path(figure_path(str(out)))
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels: list[tuple[str, Series, bool]] = []  # (title, series, drawn as steps)
    if data.battery:
        panels.append(("battery (V)", data.battery, False))
    for bus, series in sorted(data.commands.items()):
        panels.append((f"commands to {bus} (duty)", series, True))
    order = [*PROPERTY_PANELS, *sorted(set(data.props) - set(PROPERTY_PANELS))]
    for prop in order:
        by_label = data.props.get(prop, {})
        if by_label and not _binary(by_label):
            panels.append((PROPERTY_PANELS.get(prop, prop), by_label, False))
    if data.late:
        panels.append(("tick lateness (µs)", data.late, False))
    if not panels:
        raise ValueError("nothing to plot: the recording has no health, get rows or commands")

    fig, axes = plt.subplots(len(panels), 1, sharex=True, squeeze=False,
                             figsize=(11, 1.9 * len(panels) + 0.9))
    marks = data.all_marks()
    for ax, (name, series, steps) in zip(axes[:, 0], panels, strict=True):
        for label, (xs, ys) in sorted(series.items()):
            if steps:
                ax.step(xs, ys, where="post", label=label, linewidth=1.2)
            else:
                ax.plot(xs, ys, label=label, linewidth=1.2)
        ax.set_ylabel(name, fontsize=8)
        ax.grid(True, alpha=0.3)
        ax.tick_params(labelsize=8)
        if name.startswith("tick lateness"):
            top = max((max(ys) for _, ys in series.values() if ys), default=0.0)
            if top > 2000.0:  # a rare long tick must not flatten the rest
                ax.set_yscale("symlog", linthresh=100.0)
            else:  # on time (zero throughout on a virtual clock): a plain 0-1 ms axis
                ax.set_ylim(0.0, max(1000.0, 1.1 * top))
        ax.legend(loc="upper right", fontsize=7, ncol=min(4, len(series)), framealpha=0.8)
        for kind, ts in marks.items():
            _, colour, style = MARKS.get(kind, (kind, "0.5", ":"))
            for t in ts:
                ax.axvline(t, color=colour, linestyle=style, linewidth=1.0, alpha=0.8)
    axes[-1, 0].set_xlabel("time since the recording started (s)")
    if marks:
        from matplotlib.lines import Line2D

        handles = []
        for kind, ts in marks.items():
            label, colour, style = MARKS.get(kind, (kind, "0.5", ":"))
            line_style: Any = style
            handles.append(Line2D([], [], color=colour, linestyle=line_style,
                                  label=f"{label} ({len(ts)})"))
        fig.legend(handles=handles, loc="lower center", ncol=len(handles), fontsize=8,
                   frameon=False)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout(rect=(0, 0.03 if marks else 0, 1, 1))
    save_figure(fig, out, dpi=110)
    plt.close(fig)
    return out
