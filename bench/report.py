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


def _each_run(m: dict[str, Any]) -> str:
    """`The medians of 3 runs: 50.3, 58.6, 63.8 (world.step alone 333, 457, 592). `"""
    factors, bases = m.get("real_time_factors", []), m.get("world_step_factors", [])
    if len(factors) < 2:
        return ""
    return (f"The medians of {len(factors)} runs: real-time factors "
            f"{', '.join(f'{x:g}' for x in factors)} (`world.step` alone "
            f"{', '.join(f'{x:g}' for x in bases)}). ")


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
        labels = {"idle": "idle", "loaded": "4 clients polling",
                  "real_drivers_idle": "real drivers, idle"}
        for run, label in labels.items():
            r = t.get(run)
            if r is None:
                continue
            out += _pcts(f"{label}: lateness", r["late_us"], " µs")
            out += [_row(f"{label}: overruns", r["overruns"]),
                    _row(f"{label}: CPU % of a core", r["cpu_pct"])]
            if "tick_busy_us" in r:
                out += _pcts(f"{label}: tick cost", r["tick_busy_us"], " µs",
                             ("p50", "p99", "mean"))
        rtt = t["loaded"]["load"]["rtt_us"]
        out += ["", f"Polling clients' round trip (base.get + ble.get): p50 {_num(rtt['p50'])} "
                f"µs, p99 {_num(rtt['p99'])} µs, max {_num(rtt['max'])} µs. A tick's cost is "
                "what its tasks take, timed by the loop; its baseline is what one iteration "
                "of the bare loop costs the machine (its CPU over its iterations).",
                ""]
        tasks = t["idle"].get("tasks")
        if tasks:
            out += ["Tasks of an idle tick (`ramp run --sim`, mean / max per run):", "",
                    "| task | runs | mean | max |", "|---|---|---|---|"]
            out += [f"| {name} | {v['runs']:,} | {_num(v['mean_us'])} µs | "
                    f"{_num(v['max_us'])} µs |" for name, v in tasks.items()]
            out.append("")
    fl = doc.get("fleet")
    if fl and "error" not in fl:
        st = fl["stop_all_to_driving_false_ms"]
        out += [f"**fleet** (Stop all from the page's supervisor to {fl['robots']} simulated "
                f"agents through a local Mosquitto, {fl['rounds']} rounds): publish to every "
                f"robot's `driving=false` p50 {_num(st['p50'])} ms, p99 {_num(st['p99'])} ms, "
                f"max {_num(st['max'])} ms; broker CPU {fl['broker_cpu_pct']} % of a core.", ""]
    t = doc.get("tls")
    if t and "error" not in t:
        f = t["flood"]
        out += [f"**tls** (`{t['request']}` over mutual TLS; baseline: the same server over "
                f"plain TCP, median of {t['trials']} trials)", "", HEAD]
        out += _pcts("sequential RTT", t["rtt_us"], " µs")
        out += ["", f"During {f['seconds']:g} s of bad handshakes ({f['attempts']} attempts): "
                f"tick lateness p99 {_num(f['tick_late_us']['flood']['p99'])} µs (quiet: "
                f"{_num(f['tick_late_us']['quiet']['p99'])} µs), max "
                f"{_num(f['tick_late_us']['flood']['max'])} µs; an operator's connect + "
                f"handshake + stop answered in p50 "
                f"{_num(f['operator_connect_to_stop_ms']['p50'])} ms, max "
                f"{_num(f['operator_connect_to_stop_ms']['max'])} ms.", ""]
    r = doc.get("round_trip")
    if r and "error" not in r:
        out += [f"**round_trip** (`{r['request']}`, {r['response_bytes']}-byte answer; "
                "baseline: bare select server answering the same size; client and servers "
                f"pinned to core {r.get('pinned_cpu', '?')}, median of "
                f"{r['sequential'].get('trials', r.get('trials', 1))} sequential and "
                f"{r.get('trials', 1)} pipelined trials)", "", HEAD]
        out += _pcts(f"sequential ×{r['sequential']['requests']:,}: RTT", r["sequential"]["rtt_us"],
                     " µs")
        paired = r["sequential"].get("p50_ratio_paired")
        if paired and paired["median"] is not None:
            out.append(f"| sequential RTT p50, trial by trial (median of {len(paired['trials'])}"
                       f" pairs) | | | ×{paired['median']:g} |")
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
    i = doc.get("interlocks")
    if i and "error" not in i:
        out += [f"**interlocks** ({i['rules']} rules beside none, `ramp run --sim`; every rule "
                f"guards `{i['request']}`; median of {i.get('trials', 1)} trials)", "", HEAD,
                _row("tick cost (all tasks), mean", i["tick_cost_us"], " µs"),
                _row("request RTT p50", i["request_rtt_p50_us"], " µs"),
                _row("request RTT mean", i["request_rtt_mean_us"], " µs"), "",
                f"The rules add {_num(i['tick_cost_added_us'])} µs to a tick (their task: "
                f"{_num(i['interlocks_task_us']['mean'])} µs mean, "
                f"{_num(i['interlocks_task_us']['max'])} µs max) and "
                f"{_num(i['request_rtt_added_p50_us'])} µs to a guarded request's round trip "
                "(p50).", ""]
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
                *([_row("idle CPU % of a core (baseline: bare select loop)",
                        s["idle_cpu_pct"], "")] if "idle_cpu_pct" in s else []),
                *([_row("idle CPU %, idle ticks off (every base period)",
                        s["idle_cpu_pct_every_tick"], "")]
                  if "idle_cpu_pct_every_tick" in s else []),
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
    rc = doc.get("recorder")
    if rc and "error" not in rc:
        e, t = rc["encode"], rc["tick"]
        out += ["**recorder** (encoding on the tick, ns per record, median of batches of 100; "
                "baseline: the supervisor's own work on the same item)", "",
                "| record | recorder | baseline | ratio | baseline is |", "|---|---|---|---|---|"]
        for kind in ("mcp_in", "mcp_out", "health", "module_rows", "command", "event"):
            cell = e[kind]["ns_per_record"]["p50"]
            out.append(f"| {kind} | {_num(cell['value'])} ns | {_num(cell['baseline'])} ns | "
                       f"{_num(cell['ratio'])} | {e[kind]['baseline_is']} |")
        w = e["writer"]
        out += ["", f"Writer thread (off the tick): {w['cpu_us_per_record']} µs of CPU per record "
                f"to frame, compress and write ({w['us_per_record']} µs of wall time with its "
                f"pauses); {w['bytes_per_record']} bytes per record on disk.", "",
                f"Tick at {t['rate_hz']:g} Hz for {t['duration_s']:g} s with "
                f"{t['records_per_s']:,} records/s; three processes at the same time, baseline: "
                "the same loop with the recorder off.", "", HEAD]
        crowded = t.get("crowded_dir")
        for key, label in (("on", "recorder on"),
                           ("slow_disk", f"slow disk ({t['slow_disk_bytes_per_s']:,} B/s)"),
                           ("crowded_dir", f"{crowded['files_before']:,} files in the dir"
                            if crowded else "")):
            if key not in t:
                continue
            r = t[key]
            out += _pcts(f"{label}: lateness", r["late_us"], " µs", ("p50", "p99", "max"))
            out += [_row(f"{label}: overruns", r["overruns"]),
                    _row(f"{label}: CPU % of a core", r["cpu_pct"])]
        sd = t["slow_disk"]
        out += ["", f"Slow disk: {sd['dropped']:,} records dropped and counted, "
                f"{sd['written']:,} taken by the writer, the queue ({t['queue_records']:,} "
                f"records) full at the end; recorder on: {t['on']['dropped']} dropped, "
                f"{t['on']['bytes_per_record']} bytes per record on disk.", ""]
        if crowded:
            out += [f"Crowded directory ({crowded['files_before']:,} files of earlier runs, "
                    f"keep {crowded['keep']}, a new file every {crowded['max_mb']:g} MB): "
                    f"{crowded['dropped']:,} records dropped, {crowded['written']:,} written, "
                    f"{crowded['files_left']} file left.", ""]
        rr = rc.get("ramp_run")
        if rr:
            on, sd = rr["on"], rr["slow_disk"]
            out += [f"`ramp run --sim` for {rr['duration_s']:g} s, {rr['clients']} clients "
                    f"each sending `{rr['message']}` at {rr['hz_each']:g} Hz; three "
                    "processes at the same time, baseline: the one without `--record`.", "",
                    HEAD]
            for label, r in (("--record", on),
                             (f"--record, slow disk ({rr['slow_disk_bytes_per_s']:,} B/s)",
                              sd)):
                out += _pcts(f"{label}: lateness", r["late_us"], " µs", ("p50", "p99", "max"))
                out += _pcts(f"{label}: tick's work", r["tick_busy_us"], " µs",
                             ("p50", "mean"))
                out += [_row(f"{label}: overruns", r["overruns"]),
                        _row(f"{label}: CPU % of a core", r["cpu_pct"]),
                        _row(f"{label}: round trip p50", r["rtt_us_p50"], " µs")]
            task = on.get("recorder_task_us") or {}
            out += ["", f"Recording: {on['records_per_s']:,} records/s, {on['dropped']} "
                    f"dropped, {on['bytes_per_record']} bytes per record on disk; the 10 Hz "
                    f"sampling task {_num(task.get('mean_us'))} µs per run. Slow disk: "
                    f"{sd['dropped']:,} records dropped and counted (robot.get's "
                    f"recorder.dropped), {sd['messages_in_files']:,} reached the file.", ""]
    pl = doc.get("planner")
    if pl and "error" not in pl:
        g = pl["grid"]
        out += [f"**planner** ({pl['queries']} random SPEC 6.1 layouts, start region to the far "
                f"end of the digging region, grid {g['cells'][0]} x {g['cells'][1]} cells of "
                f"{g['resolution_m']:g} m; baseline: BFS on the same grid for A*, A* alone for "
                "the whole plan)", "", HEAD]
        out += _pcts("A*", pl["astar_ms"], " ms", ("p50", "p99", "max"))
        out += _pcts("whole plan (A*, shortcuts, footprint checks)", pl["plan_ms"], " ms",
                     ("p50", "p99", "max"))
        out += [_row("A* across the empty arena", pl["empty_arena_corner_to_corner_ms"],
                     " ms"),
                "", f"Plans found: {pl['plans_found']}/{pl['queries']}; A* expanded "
                f"{_num(pl['astar_expanded']['p50'])} cells at p50 "
                f"(max {_num(pl['astar_expanded']['max'])}); grid build p50 "
                f"{_num(pl['grid_build_ms']['p50'])} ms.", ""]
    r = doc.get("rig")
    if r and "error" not in r:
        out += [f"**rig** (the simulation rig, {r['simulated_s']:g} simulated s of a robot "
                "driving a weave; baseline: `world.step` alone on the same script)", "", HEAD]
        for key, label in (("sensors", "world + emulators + drivers + perception, 40 scans/s"),
                           ("sensors_scans_on_demand", "the same, scans on demand 4/s"),
                           ("with_backend", "streaming, with the backend over MCP")):
            out += [_row(f"{label}: real-time factor", r[key]["real_time_factor"], "x"),
                    _row(f"{label}: CPU s per simulated minute",
                         r[key]["cpu_s_per_simulated_minute"], " s")]
        out.append("")
    o = doc.get("obstacles")
    if o and "error" not in o:
        acc = o["accuracy"]
        out += [f"**obstacles** (one 3D scan: {o['scans']} scans, {o['cloud_points']:,} points, "
                f"over {o['layouts']} seeded layouts; baseline: a least-squares plane through "
                "the same cloud)", "", HEAD,
                _row("merge + detection, median", o["merge_and_detect_ms"]["p50"], " ms"),
                _row("merge + detection, worst", o["merge_and_detect_ms"]["max"], " ms"),
                "", f"Merge alone {_num(o['merge_ms']['p50'])} ms, detection alone "
                f"{_num(o['detect_ms']['p50'])} ms (medians); the sweep itself takes "
                f"{o['sweep_duration_s']} s of gimbal time. On these layouts: "
                f"{acc['found']}/{acc['required']} obstacles of 15 cm or more found, worst "
                f"position error {acc['worst_position_cm']} cm, worst diameter error "
                f"{acc['worst_diameter_cm']} cm, {acc['false_per_layout']} false obstacles "
                "per layout.", ""]
    pc = doc.get("perception")
    if pc and "error" not in pc:
        f = pc["flow"]
        out += [f"**perception** (the integrated chain on the rig, {pc['layouts']} layouts from "
                "the start region facing the obstacle region; baselines: a least-squares line "
                "through the fused scan, `world.step` alone for the sweep's simulated time, a "
                "least-squares plane through the sweep's cloud)", "", HEAD]
        out += _pcts("one localization (10 scans fused)", pc["localize_ms"], " ms",
                     ("p50", "max"))
        out += _pcts(f"one 3D scan ({pc['sweep_scans']} tilts), CPU with the simulator",
                     pc["sweep"]["cpu_s"], " s", ("p50", "max"))
        out += _pcts(f"merge + detection ({pc['cloud_points']:,} points)", pc["detect_ms"],
                     " ms", ("p50", "max"))
        out += ["", f"The sweep takes {pc['sweep']['simulated_s']['p50']} s of gimbal and "
                f"LIDAR time; one whole `ramp sim perceive` flow is {f['simulated_s']} "
                f"simulated s for {f['cpu_s']} s of CPU, of which the localizer "
                f"{f['localize_cpu_s']} s and the detector {f['detect_cpu_s']} s.", ""]
    m = doc.get("mission")
    if m and "error" not in m:
        out += [f"**mission** (`ramp sim mission` on the default seed, {m['simulated_s']:g} "
                "simulated s: world, backend, emulators, drivers, perception, executive and "
                "mission on one virtual clock; baseline: `world.step` alone over the same "
                "time)", "", HEAD,
                _row("real-time factor", m["real_time_factor"], "x"),
                _row("CPU s per simulated minute", m["cpu_s_per_simulated_minute"], " s"),
                "", _each_run(m) + f"A 10-minute mission takes {m['ten_minutes_wall_s']} s of "
                "wall time at "
                f"this rate; this run ended `{m['outcome']}` ({m['final_state']}), "
                f"{m['delivered_kg']} kg delivered, {m['collisions']} collisions, "
                f"{m['crater_entries']} crater entries. Wall time by part: "
                + ", ".join(f"{k} {v} %" for k, v in m["wall_pct_by_part"].items()) + ".", ""]
    b = doc.get("console_bandwidth")
    if b and "error" not in b:
        out += [f"**console_bandwidth** (`ramp-teleop --autonomy` at its defaults on a realtime "
                f"mission, seed {b['seed']}, {b['seconds']:g} s, each link through a counting "
                "TCP proxy; budget: 16 kB/s for both together)", "",
                "| link | bytes/s | up | down |", "|---|---|---|---|"]
        for name, label in (("mcp", "MCP (status poll and commands)"),
                            ("view", "autonomy's view")):
            x = b[name]
            out.append(f"| {label} | {_num(x['bps'])} | {_num(x['up_bps'])} | "
                       f"{_num(x['down_bps'])} |")
        out += [f"| **both** | **{_num(b['total_bps'])}** | | |", "",
                f"Busiest second {_num(b['busiest_second_bps'])} B/s; the mission went "
                f"through {', '.join(b['states'])}.", ""]
    r = doc.get("realtime")
    if r and "error" not in r:
        out += [f"**realtime** (the backend's tick during `ramp sim mission --realtime`, seed "
                f"{r['seed']}, {r['seconds']:g} s each, measured in the backend's process, run "
                "as `ramp run` runs, over the whole run; bare: nobody attached; attached: the "
                "live view, the console and a headless Chromium page on it; default priority: "
                "the same with the backend not SCHED_FIFO; baseline: a bare 100 Hz select "
                "loop in the same window, at the default priority)", "",
                "| | p50 µs | p99 µs | max µs | stalls | overruns | baseline p50/p99/max µs |",
                "|---|---|---|---|---|---|---|"]
        for name in ("bare", "attached", "attached_default_priority"):
            x = r.get(name)
            if x is None:
                continue
            late, base = x["late_us"] or {}, x["baseline_late_us"] or {}
            out.append(f"| {name} | {_num(late.get('p50'))} | {_num(late.get('p99'))} | "
                       f"{_num(late.get('max'))} | {x['stalls']} | {x['overruns']} | "
                       f"{_num(base.get('p50'))} / {_num(base.get('p99'))} / "
                       f"{_num(base.get('max'))} |")
        out.append("")
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
