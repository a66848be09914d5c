"""`python -m bench.report bench.json`: the figures of one run as Markdown tables.

Used to refresh docs/benchmarks.md from a new run, so the tables there are never typed by
hand. Sections missing from the document (`--only`) or failed are skipped.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any


def _num(x: Any, unit: str = "") -> str:
    if x is None:
        return "–"
    if isinstance(x, float):
        text = f"{x:,.0f}" if abs(x) >= 1000 else f"{x:.3g}" if abs(x) < 10 else f"{x:.0f}"
    else:
        text = f"{x:,}" if isinstance(x, int) else str(x)
    return text + unit


def _row(label: str, cell: dict[str, Any], unit: str = "") -> str:
    return (f"| {label} | {_num(cell.get('value'), unit)} | {_num(cell.get('baseline'), unit)} "
            f"| {_num(cell.get('ratio'))} |")


HEAD = "| figure | RAMP | baseline | ratio |\n|---|---|---|---|"


def _pcts(prefix: str, block: dict[str, Any], unit: str,
          keys: Sequence[str] = ("p50", "p99", "p99_9", "max")) -> list[str]:
    names = {"p50": "p50", "p99": "p99", "p99_9": "p99.9", "max": "max", "mean": "mean"}
    return [_row(f"{prefix} {names[k]}", block[k], unit) for k in keys if k in block]


def render(doc: dict[str, Any]) -> str:
    m = doc["machine"]
    out = [f"Run: `{doc['profile']}` profile, {m['date']}, {m['cpu_model']}, {m['cores']} cores, "
           f"{m['python']}, {m['kernel']}; load average at start "
           f"{'/'.join(map(str, m['loadavg_at_start']))}, at end "
           f"{'/'.join(map(str, m.get('loadavg_at_end', [])))}; {doc.get('elapsed_s')} s.", ""]
    t = doc.get("tick")
    if t and "error" not in t:
        out += [f"**tick** ({t['rate_hz']:g} Hz, {t['duration_s']:g} s each; baseline: bare "
                "select loop running beside it)", "", HEAD]
        for run in ("idle", "loaded"):
            r = t[run]
            label = "idle" if run == "idle" else "4 clients polling"
            out += _pcts(f"{label}: lateness", r["late_us"], " µs")
            out += [_row(f"{label}: overruns", r["overruns"]),
                    _row(f"{label}: CPU % of a core", r["cpu_pct"])]
        rtt = t["loaded"]["load"]["rtt_us"]
        out += ["", f"Polling clients' round trip (base.get + ble.get): p50 {_num(rtt['p50'])} "
                f"µs, p99 {_num(rtt['p99'])} µs, max {_num(rtt['max'])} µs.", ""]
    r = doc.get("round_trip")
    if r and "error" not in r:
        out += [f"**round_trip** (`{r['request']}`, {r['response_bytes']}-byte answer; "
                "baseline: minimal selectors server answering the same size)", "", HEAD]
        out += _pcts(f"sequential ×{r['sequential']['requests']:,}: RTT", r["sequential"]["rtt_us"],
                     " µs")
        pip = r["pipelined"]
        for key, v in pip.items():
            if not key.startswith("clients_"):
                continue
            n = key.split("_")[1]
            out += [_row(f"{n} client(s) × {pip['in_flight_per_client']} in flight: req/s",
                         v["req_per_s"]),
                    _row(f"{n} client(s): latency p99", v["latency_us"]["p99"], " µs")]
        out += ["", "Supervisor's own ticks while pipelined clients saturate it:", "",
                "| clients | tick late p50 | p99 | max | overruns |", "|---|---|---|---|---|"]
        for key, v in pip.items():
            if key.startswith("clients_"):
                tl = v["tick_late_us"]
                out.append(f"| {key.split('_')[1]} | {_num(tl['p50'])} µs | {_num(tl['p99'])} µs"
                           f" | {_num(tl['max'])} µs | {v['tick_overruns']} |")
        out.append("")
    c = doc.get("command_to_wire")
    if c and "error" not in c:
        out += [f"**command_to_wire** ({c['baud']} baud: {c['wire_ms_per_packet']} ms per "
                f"packet, {c['wire_packets_per_s']} packets/s on a real wire; baseline: relay "
                "writing every line straight to the pty)", "", HEAD]
        out += _pcts("single: send → wire", c["single"]["send_to_wire_us"], " µs",
                     ("p50", "p99", "max"))
        for key, label in (("flood_one_wheel", "flood 1000/s, lf_wheel"),
                           ("flood_four_wheels", "flood 1000/s, 4 wheels")):
            f = c[key]
            out += _pcts(f"{label}: send → wire", f["latency_us"], " µs", ("p50", "p99"))
            out += [_row(f"{label}: commands reaching the wire", f["reached_wire_pct"], " %"),
                    _row(f"{label}: bus load", f["bus_load_pct"], " %")]
        out += ["", "| flood | packets carrying the newest value | lag behind newest p99 | "
                "last command → wire (max) | packets/s |", "|---|---|---|---|---|"]
        for key, label in (("flood_one_wheel", "lf_wheel"), ("flood_four_wheels", "4 wheels")):
            f = c[key]
            out.append(f"| {label} | {f['packets_carrying_newest_pct']} % | "
                       f"{_num(f['lag_behind_newest_us']['p99'])} µs | "
                       f"{_num(f['last_command_latency_us']['max'])} µs | {f['packets_per_s']} |")
        out += ["", f"Driver `max_pending`: {c['driver_max_pending']} (stats: "
                f"{', '.join(f'{k} {v}' for k, v in c['driver_stats'].items())}).", ""]
    w = doc.get("watchdog_to_wire")
    if w and "error" not in w:
        out += [f"**watchdog_to_wire** (timeout {w['watchdog_timeout_s']:g} s; baseline: relay "
                "with a select-timeout watchdog)", "", HEAD]
        for key, label in (("silent_beyond_timeout_ms", "silent: zeros on wire − timeout"),
                           ("close_to_zeros_ms", "TCP close → zeros on wire"),
                           ("zeros_spread_ms", "first → last channel's zero")):
            out += _pcts(label, w[key], " ms", ("p50", "max"))
        out.append("")
    s = doc.get("startup")
    if s and "error" not in s:
        out += [f"**startup** (`{s['command']}`, {s['runs']} runs; baseline: bare interpreter)",
                "", HEAD,
                _row("start → ready, median", s["start_to_ready_ms"]["median"], " ms"),
                _row("start → ready, max", s["start_to_ready_ms"]["max"], " ms"),
                _row("VmRSS at ready", s["rss_mb_at_ready"], " MB"),
                _row(f"VmRSS after {s['rss_mb_after']['seconds']:g} s", s["rss_mb_after"], " MB"),
                _row("SIGTERM → exit, median", s["sigterm_to_exit_ms"]["median"], " ms"), ""]
    a = doc.get("autonomy_sensors")
    if a and "error" not in a:
        out += [f"**autonomy_sensors** (IMU and gimbal emulators, {a['simulated_s']:g} "
                f"simulated s, a sample every {a['data_interval_ms']} ms; baseline: 6 normals "
                "and two tuples per sample)", "", HEAD]
        for fault in ("none", "gyro-drift", "imu-shift"):
            out.append(_row(f"IMU, fault {fault}: CPU per sample",
                            a[f"imu_{fault}"]["us_per_sample"], " µs"))
        g = a["gimbal"]
        out += ["", f"Gimbal emulator: {_num(g['us_per_tick'])} µs per 10 ms tick; IMU "
                f"{_num(a['imu_none']['cpu_s_per_simulated_minute'])} s of CPU per simulated "
                "minute.", ""]
    lc = doc.get("lidar_codec")
    if lc and "error" not in lc:
        out += [f"**lidar_codec** (one {lc['steps']}-step MD scan, {lc['reply_bytes']:,} bytes in "
                f"{lc['data_lines']} data lines, {lc['calls']:,} calls; baseline: splitting and "
                "joining the same reply's lines)", "", HEAD]
        for key, label in (("decode_reply_us", "decode_reply"), ("feed_us", "streaming feed"),
                           ("decode_to_scan_us", "feed + Scan in metres"),
                           ("emulator_scan_us", "emulator: one scan out")):
            out += _pcts(label, lc[key], " µs", ("p50", "p99", "max"))
        out += [_row("CPU % of a core at 40 scans/s", lc["cpu_pct_at_40_scans_per_s"], " %"), ""]
    lo = doc.get("localizer")
    if lo and "error" not in lo:
        out += [f"**localizer** (one wall-based localization of a 1081-beam scan, "
                f"~{lo['wall_points']} wall points; baseline: one `np.linalg.lstsq` line fit "
                "of the same points)", "", HEAD]
        for key, label in (("localize_us", "localize, start box hint"),
                           ("track_us", "localize, odometry + yaw prior"),
                           ("extract_us", "line extraction alone"),
                           ("relevel_us", "tilted 4-8 deg: detect, re-level, localize")):
            out += _pcts(label, lo[key], " µs", ("p50", "max"))
        t = lo["tilted_outcomes"]
        out += ["", f"Tilted scans ({lo['tilted_scans']}): {t['relevelled']} re-levelled and "
                f"localized, {t['kept']} localized as they were, {t['lost']} reported lost.",
                ""]
    a = doc.get("arena")
    if a and "error" not in a:
        out += ["**arena** (CPU per call in this process; baselines: the empty level arena's "
                "step, one numpy pass over 1081 elements)", "", HEAD,
                _row("world.step(0.01), median", a["world_step_us"]["p50"], " µs"),
                _row("scan level, median", a["scan_level_us"]["p50"], " µs"),
                _row("scan tilted 20°, median", a["scan_tilted_us"]["p50"], " µs"),
                _row("scan tilted, gimbal moving, median", a["scan_tilted_gimbal_moving_us"][
                    "p50"], " µs"),
                _row("scan standing still, median", a["scan_standing_still_us"]["p50"], " µs"),
                "", f"A 10-minute mission's physics and LIDAR (60 000 steps, 24 000 scans): "
                f"{a['mission_world_and_lidar_cpu_s']} s of CPU.", ""]
    return "\n".join(out)


def main(argv: Sequence[str] | None = None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    if len(args) != 1:
        print("usage: python -m bench.report BENCH.json", file=sys.stderr)
        return 2
    print(render(json.loads(Path(args[0]).read_text())))
    return 0


if __name__ == "__main__":
    sys.exit(main())
