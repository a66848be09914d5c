// RAMP teleop page. It talks only to ramp-teleop over one WebSocket: it sends what the operator
// does (inputs ~20 times a second, calls, STOP) and draws what the console tells it. Everything
// it shows about the robot comes from the robot's own describe answers, never from tables here.
// The page decides nothing about safety: ramp-teleop gates every motion on this page being
// connected, fresh and focused, so a frozen or closed page stops the robot.
"use strict";
(() => {
  const INPUT_PERIOD_MS = 50;
  const RECONNECT_MS = 1000;
  const RESULT_SHOW_MS = 6000;
  const DRIVE_KEYS = new Set(["w", "a", "s", "d"]);
  const $ = (id) => document.getElementById(id);

  const st = {
    ws: null,
    connected: false,
    hello: null,
    modules: [],
    status: null,
    drive: {},
    values: new Map(), // "module:device.prop" -> element showing it
    keys: new Set(),
    pad: null,
    padNote: "none detected (press a button)",
    callId: 0,
    calls: new Map(), // id -> result element
    autonomy: null, // the last "autonomy" summary
    map: {},
    scan: [],
    interlocks: {}, // rule name -> {severity, message}, from the robot's describe
  };

  // ---- helpers --------------------------------------------------------------------------
  function el(tag, attrs = {}, ...children) {
    const e = document.createElement(tag);
    for (const [k, v] of Object.entries(attrs)) {
      if (v === undefined || v === null || v === false) continue;
      if (k === "class") e.className = v;
      else if (k === "text") e.textContent = v;
      else if (k.startsWith("on")) e.addEventListener(k.slice(2), v);
      else e.setAttribute(k, v === true ? "" : String(v));
    }
    for (const c of children) if (c !== null && c !== undefined) e.append(c);
    return e;
  }
  function setClass(e, cls, on) { if (e) e.classList.toggle(cls, !!on); }
  function setState(e, state, names) {
    if (!e) return;
    for (const n of names) e.classList.remove(n);
    if (state) e.classList.add(state);
  }
  const STATE_CLASSES = ["ok", "bad", "warn", "drive", "fault", "detached"];
  function stateClass(s) { return s === "ok" ? "ok" : s === "fault" ? "fault" : s === "detached" ? "detached" : ""; }
  function value(key) { return st.status && st.status.values ? st.status.values[key] : undefined; }
  function nowText() { return new Date().toLocaleTimeString(); }
  function event(level, text) {
    const list = $("events");
    // Entries carry "ev-LEVEL", never a bare level: "stop" is the big STOP button's class.
    list.prepend(el("li", { class: `ev-${level}`, "data-testid": "event" }, el("time", { text: nowText() }), text));
    while (list.children.length > 60) list.lastChild.remove();
  }

  // ---- WebSocket ------------------------------------------------------------------------
  function connect() {
    const proto = location.protocol === "https:" ? "wss" : "ws";
    const ws = new WebSocket(`${proto}://${location.host}/ws`);
    st.ws = ws;
    ws.onopen = () => { st.connected = true; refreshBanner(); refreshConnection(); sendInput(); };
    ws.onmessage = (ev) => {
      let msg;
      try { msg = JSON.parse(ev.data); } catch (e) { return; }
      handle(msg);
    };
    ws.onclose = () => {
      if (st.ws === ws) st.ws = null;
      if (st.connected) event("error", "lost the console (ramp-teleop); retrying");
      st.connected = false;
      refreshPills();
      refreshBanner();
      refreshConnection();
      setTimeout(connect, RECONNECT_MS);
    };
  }
  function send(obj) {
    if (st.ws && st.ws.readyState === WebSocket.OPEN) {
      st.ws.send(JSON.stringify(obj));
      return true;
    }
    return false;
  }

  function handle(msg) {
    switch (msg.type) {
      case "hello": onHello(msg); break;
      case "catalog": st.interlocks = msg.interlocks || {}; renderModules(msg.modules || []); break;
      case "status": onStatus(msg); break;
      case "drive": st.drive = msg; refreshDrive(); break;
      case "result": onResult(msg); break;
      case "event": event(msg.level || "info", msg.text || ""); break;
      case "profile": onProfile(msg.profiles, msg.profile); break;
      case "profile_error": onProfileError(msg.text); break;
      case "autonomy": onAutonomy(msg); break;
      case "autonomy_map": st.map = msg.map || {}; drawMap(); break;
      case "autonomy_scan": st.scan = msg.points || []; drawMap(); break;
      case "alerts": renderAlerts(msg.alerts || []); break;
      case "bandwidth": onBandwidth(msg); break;
      default: break;
    }
  }

  // ---- hello, profile -------------------------------------------------------------------
  function onHello(msg) {
    st.hello = msg;
    $("backend").textContent = `robot ${msg.backend} · operator ${msg.name}`;
    $("conn-backend").textContent = msg.backend;
    onProfile(msg.profiles, msg.profile);
    if (!msg.autonomy) {
      $("autonomy-status").textContent = "No autonomy view: start ramp-teleop with --autonomy HOST:PORT "
        + "(ramp-autonomy --foxglove-port). Teleoperation works as usual.";
      $("autonomy-state").textContent = "no autonomy";
      $("autonomy-map").classList.add("hidden");
      $("autonomy-card").classList.add("compact"); // one line, not a page of empty fields
    } else {
      $("autonomy-map").classList.remove("hidden");
      $("autonomy-card").classList.remove("compact");
    }
  }

  // ---- the autonomy's view ----------------------------------------------------------------
  function fmt(x, digits, unit) {
    return typeof x === "number" && Number.isFinite(x) ? `${x.toFixed(digits)}${unit || ""}` : "–";
  }
  function onAutonomy(msg) {
    st.autonomy = msg;
    const status = $("autonomy-status");
    if (!msg.connected) status.textContent = `autonomy view unreachable (${msg.address}): ${msg.detail}. Teleoperation works as usual.`;
    else if (msg.stale) status.textContent = `autonomy view ${msg.address}: stale (no news for 3 s)`;
    else status.textContent = `autonomy view ${msg.address}`;
    setState(status, !msg.connected || msg.stale ? "warn" : "", ["warn"]);
    const stateEl = $("autonomy-state");
    const since = msg.in_state_s != null ? ` · ${formatAge(msg.in_state_s)}` : "";
    stateEl.textContent = msg.state ? `${msg.state}${since}` : (msg.connected ? "waiting for the mission" : "–");
    // The localization is the view's enum (none, ok, lost, relocalizing), not a list of names.
    const bad = msg.state === "waiting_for_operator" || msg.localization === "lost";
    const warn = msg.state === "paused" || msg.localization === "relocalizing";
    setState(stateEl, bad ? "bad" : warn ? "warn" : "", ["bad", "warn"]);
    $("autonomy-localization").textContent = msg.localization || "–";
    $("autonomy-reason").textContent = msg.reason || "";
    const n = msg.numbers || {};
    const conf = $("autonomy-confidence");
    conf.textContent = fmt(n.pose_confidence, 2);
    setState(conf, typeof n.pose_confidence === "number" ? (n.pose_confidence < 0.5 ? "bad" : n.pose_confidence < 0.8 ? "warn" : "ok") : "", STATE_CLASSES);
    $("autonomy-bin").textContent = fmt(n.bin_kg, 1, " kg");
    $("autonomy-delivered").textContent = fmt(n.delivered_kg, 1, " kg");
    $("autonomy-lift").textContent = fmt(n.lift, 2);
    $("autonomy-losses").textContent = n.localization_losses ?? "–";
    const p = msg.pose;
    $("autonomy-pose").textContent = p ? `x ${p[0].toFixed(2)} y ${p[1].toFixed(2)} · ${(p[2] * 180 / Math.PI).toFixed(0)}°` : "none (no fix)";
    drawMap();
  }
  function formatAge(s) {
    if (s < 60) return `${s.toFixed(0)} s`;
    return `${Math.floor(s / 60)} min ${(s % 60).toFixed(0)} s`;
  }

  // The arena seen from above: x along the canvas, y up. Everything in arena metres.
  function drawMap() {
    const c = $("autonomy-map");
    if (!c || c.classList.contains("hidden")) return;
    const g = c.getContext("2d");
    const W = c.width, H = c.height, m = st.map || {};
    g.clearRect(0, 0, W, H);
    // The arena's size as the autonomy publishes it (/arena); the walls until it has come.
    const size = m.arena || {};
    const xs = (m.walls || []).map((p) => p[0]), ys = (m.walls || []).map((p) => p[1]);
    const L = size.length_m || (xs.length ? Math.max(...xs) : 1), Wd = size.width_m || (ys.length ? Math.max(...ys) : 1);
    const pad = 16, back = 0.35;
    const k = Math.min((W - 2 * pad) / (L + back), (H - 2 * pad) / Wd);
    const X = (x) => pad + (x + back) * k, Y = (y) => H - pad - y * k;
    const line = (pts, colour, width, dash) => {
      if (!pts || pts.length < 2) return;
      g.beginPath(); g.setLineDash(dash || []); g.strokeStyle = colour; g.lineWidth = width;
      pts.forEach(([x, y], i) => (i ? g.lineTo(X(x), Y(y)) : g.moveTo(X(x), Y(y))));
      g.stroke(); g.setLineDash([]);
    };
    const disc = ([x, y, r], colour) => {
      g.beginPath(); g.fillStyle = colour; g.arc(X(x), Y(y), Math.max(2, r * k), 0, 2 * Math.PI); g.fill();
    };
    line(m.walls && m.walls.length ? m.walls : [[0, 0], [L, 0], [L, Wd], [0, Wd], [0, 0]], "#c8ccd4", 3);
    for (const r of m.regions || []) line(r, "#6c7480", 1, [6, 5]);
    for (const r of m.collector || []) line(r, "#f0c020", 3);
    const OBSTACLE_COLOURS = { rock: "rgba(229,56,59,.8)", crater: "rgba(68,102,221,.75)" };
    for (const o of m.obstacles || []) {
      disc([o.x, o.y, o.radius], OBSTACLE_COLOURS[o.kind] || "rgba(160,160,160,.8)");
    }
    for (const leg of m.plan || []) line(leg, "#2fb062", 2);
    g.fillStyle = "#f0a020";
    for (const [x, y] of st.scan || []) g.fillRect(X(x) - 1.5, Y(y) - 1.5, 3, 3);
    const a = st.autonomy;
    const [len, wid] = m.robot || [1.2, 0.75];
    const footprint = (pose, colour, dash, fill) => {
      if (!pose) return;
      const [x, y, yaw] = pose, cs = Math.cos(yaw), sn = Math.sin(yaw);
      const corners = [[len / 2, wid / 2], [-len / 2, wid / 2], [-len / 2, -wid / 2], [len / 2, -wid / 2], [len / 2, wid / 2]]
        .map(([u, v]) => [x + u * cs - v * sn, y + u * sn + v * cs]);
      if (fill) {
        g.beginPath(); g.fillStyle = fill;
        corners.forEach(([px, py], i) => (i ? g.lineTo(X(px), Y(py)) : g.moveTo(X(px), Y(py))));
        g.fill();
      }
      line(corners, colour, 2, dash);
      line([[x, y], [x + (len / 2) * cs, y + (len / 2) * sn]], colour, 2, dash);
    };
    if (a && a.connected) {
      footprint(a.true_pose, "#e6e9ee", [5, 4], null);
      footprint(a.pose, "#3d8bfd", null, "rgba(61,139,253,.25)");
    }
    if (!a || !a.connected) {
      g.fillStyle = "#8b94a3"; g.font = "14px system-ui"; g.fillText("no autonomy view", X(L * 0.4), Y(Wd / 2));
    }
  }

  // ---- alerts ----------------------------------------------------------------------------
  const alertSeen = new Map(); // alert id -> when this page first showed it
  function renderAlerts(alerts) {
    const box = $("alerts");
    const ids = new Set(alerts.map((a) => a.id));
    for (const id of [...alertSeen.keys()]) if (!ids.has(id)) alertSeen.delete(id);
    for (const a of alerts) if (!alertSeen.has(a.id)) alertSeen.set(a.id, new Date().toLocaleTimeString());
    box.replaceChildren(...alerts.map((a) => {
      const buttons = [];
      if (a.takeover) buttons.push(el("button", { type: "button", class: "takeover", "data-testid": "alert-takeover",
        title: "take control: the robot stops and the mission pauses", text: "Take control",
        onclick: () => send({ type: "control", action: "acquire" }) }));
      if (a.reset) buttons.push(el("button", { type: "button", "data-testid": "alert-reset",
        title: `${a.reset}.reset=()`, text: "Reset", onclick: () => send({ type: "reset", target: a.reset }) }));
      if (a.id === "mission-paused") buttons.push(el("button", { type: "button", "data-testid": "alert-handback",
        text: "Hand back", onclick: () => send({ type: "control", action: "release" }) }));
      return el("div", { class: "alert", "data-testid": "alert", "data-severity": a.severity, "data-alert": a.id, role: a.severity === "error" ? "alert" : "status" },
        el("div", { class: "alert-body" }, el("span", { class: "alert-title", text: a.title }), el("span", { class: "alert-text", text: a.text })),
        el("span", { class: "alert-age", text: `since ${alertSeen.get(a.id)}` }),
        ...buttons);
    }));
  }

  function onBandwidth(msg) {
    const kb = (b) => (b >= 1000 ? `${(b / 1000).toFixed(1)} kB/s` : `${b} B/s`);
    const e = $("pill-bandwidth");
    e.textContent = msg.autonomy ? `links ${kb(msg.total_bps)} (MCP ${kb(msg.mcp_bps)} · view ${kb(msg.view_bps)}) · avg ${kb(msg.average_bps)}`
      : `link ${kb(msg.total_bps)} · avg ${kb(msg.average_bps)}`;
    setState(e, msg.average_bps > 16000 ? "warn" : "", STATE_CLASSES);
  }
  function onProfile(names, profile) {
    if (st.hello) { st.hello.profile = profile; st.hello.profiles = names; }
    const sel = $("profile");
    sel.replaceChildren(...(names || []).map((n) => el("option", { value: n, text: n })));
    sel.value = profile.name;
    $("profile-description").textContent = `${profile.description || ""} (${profile.source})`;
    $("mapping").replaceChildren(...profile.rows.map((r) =>
      el("tr", {}, el("td", { text: r.input }), el("td", { text: r.does }))));
    $("profile-error").classList.add("hidden");
    refreshConnection();
  }
  function onProfileError(text) {
    const e = $("profile-error");
    e.textContent = text;
    e.classList.remove("hidden");
    if (st.hello) $("profile").value = st.hello.profile.name;
    event("error", `profile: ${text}`);
  }

  // ---- modules: tree and panels ---------------------------------------------------------
  function renderModules(modules) {
    // Keep what the operator typed across a rebuild (a module attached or faulted).
    const typed = new Map();
    document.querySelectorAll("input[data-testid^='call:']").forEach((i) => typed.set(i.dataset.testid, i.value));
    st.modules = modules;
    st.values = new Map();
    const ordered = [...modules.filter((m) => m.name !== "robot"), ...modules.filter((m) => m.name === "robot")];
    $("tree").replaceChildren(...ordered.map(treeItem));
    $("modules").replaceChildren(...ordered.map(modulePanel));
    document.querySelectorAll("input[data-testid^='call:']").forEach((i) => {
      if (typed.has(i.dataset.testid)) i.value = typed.get(i.dataset.testid);
    });
    renderBatteries();
    if (st.status) onStatus(st.status);
  }

  function treeItem(m) {
    const dot = el("span", { class: "dot-state", "data-module-dot": m.name });
    return el("li", { role: "treeitem", "aria-expanded": "true", "data-testid": `tree:${m.name}` },
      el("a", { class: "tree-module", href: `#mod-${m.name}` }, dot, m.name),
      el("ul", { role: "group" }, ...m.devices.map((d) =>
        el("li", { role: "treeitem", class: "tree-device", "data-testid": `tree:${m.name}:${d.name}` },
          el("a", { href: `#dev-${m.name}-${d.name}` }, d.name)))));
  }

  function modulePanel(m) {
    const panel = el("article", { class: "card module", id: `mod-${m.name}`, "data-module": m.name },
      el("div", { class: "module-head" },
        el("h3", { text: m.name }),
        el("span", { class: "badge", "data-module-badge": m.name, text: m.name === "robot" ? "supervisor" : m.state })),
      el("p", { class: "module-problem hidden", "data-module-problem": m.name }));
    for (const d of m.devices) panel.append(devicePanel(m.name, d));
    return panel;
  }

  function devicePanel(module, d) {
    const body = el("div", { class: "device-body" });
    if (d.properties.length) {
      const props = el("div", { class: "props" });
      for (const p of d.properties) {
        const key = `${module}:${d.name}.${p.name}`;
        const v = el("span", { class: "prop-value", "data-testid": `value:${key}` });
        st.values.set(key, v);
        props.append(el("div", { class: "prop", title: `${key} (${p.type || "?"})` },
          el("span", { class: "prop-name", text: p.name }), v,
          p.unit ? el("span", { class: "prop-unit", text: p.unit }) : null));
      }
      body.append(props);
    }
    if (d.functions.length) {
      const fns = el("div", { class: "fns" });
      for (const f of d.functions) fns.append(functionControl(module, d.name, f));
      body.append(fns);
    }
    return el("div", { class: "device", id: `dev-${module}-${d.name}` },
      el("div", { class: "device-name", text: d.name }), body);
  }

  function functionControl(module, device, f) {
    const target = `${module}:${device}.${f.name}`;
    const result = el("span", { class: "fn-result", "aria-live": "polite" });
    if (!f.params.length) {
      const b = el("button", { type: "button", class: `call${f.name === "stop" ? " stop-fn" : ""}`,
        "data-testid": `call:${target}`, title: `${target}=()`, text: f.name,
        onclick: () => sendCall(target, "", result) });
      return el("span", { class: "fn" }, b, result);
    }
    const id = `in-${module}-${device}-${f.name}`;
    const input = el("input", { id, type: "text", inputmode: "decimal", autocomplete: "off",
      spellcheck: "false", "data-testid": `call:${target}`, placeholder: f.params.join(", "),
      title: `${target}=(${f.params.join(", ")}); Enter sends`, class: f.params.length > 1 ? "wide" : "" });
    if (target === "robot:control.acquire" && st.hello) input.value = st.hello.name;
    input.addEventListener("keydown", (e) => {
      if (e.key === "Enter") { e.preventDefault(); sendCall(target, input.value, result); }
    });
    const wrap = el("span", { class: "fn" },
      el("label", { for: id, text: f.name }), input,
      el("button", { type: "button", class: "send", title: "send", "aria-label": `send ${target}`,
        text: "▶", onclick: () => sendCall(target, input.value, result) }));
    for (const p of presets(f.params)) {
      wrap.append(el("button", { type: "button", class: "preset", title: `${target}=(${p})`, text: p,
        onclick: () => { input.value = p; sendCall(target, p, result); } }));
    }
    wrap.append(result);
    return wrap;
  }

  // A single float parameter over a short range (a position, say): quarter-step presets.
  function presets(params) {
    if (params.length !== 1) return [];
    const m = /^float\s+(-?[\d.]+)\.\.(-?[\d.]+)$/.exec(params[0].trim());
    if (!m) return [];
    const lo = Number(m[1]), hi = Number(m[2]);
    if (!(hi > lo) || hi - lo > 10) return [];
    return [0, 0.25, 0.5, 0.75, 1].map((q) => String(Math.round((lo + q * (hi - lo)) * 1000) / 1000));
  }

  function sendCall(target, params, resultEl) {
    const id = ++st.callId;
    st.calls.set(id, resultEl);
    if (!send({ type: "call", id, target, params })) {
      showResult(resultEl, false, "console not connected");
      return;
    }
    resultEl.textContent = "…";
    resultEl.className = "fn-result";
  }
  function onResult(msg) {
    if (msg.id === "stop") {
      if (!msg.ok) event("error", `STOP: ${msg.text}`);
      return;
    }
    if (msg.id === "control" || msg.id === "reset") {
      event(msg.ok ? "info" : "error", `${msg.request || msg.id}: ${msg.text}`);
      return;
    }
    const resultEl = st.calls.get(msg.id);
    st.calls.delete(msg.id);
    if (resultEl) showResult(resultEl, msg.ok, msg.text);
    if (!msg.ok) event("error", `${msg.request || "call"}: ${msg.text}`);
  }
  function showResult(e, ok, text) {
    e.textContent = text;
    e.className = `fn-result ${ok ? "ok" : "bad"}`;
    const shown = text;
    setTimeout(() => { if (e.textContent === shown) { e.textContent = ""; e.className = "fn-result"; } }, RESULT_SHOW_MS);
  }

  // ---- status ---------------------------------------------------------------------------
  function onStatus(msg) {
    st.status = msg;
    for (const [key, text] of Object.entries(msg.values || {})) {
      const e = st.values.get(key);
      if (e && e.textContent !== text) e.textContent = text;
    }
    // The robot panel's active interlocks carry each rule's severity (the text stays the value).
    const active = st.values.get("robot:interlock.active");
    if (active) {
      const names = (active.textContent || "").split(",").filter((n) => n && n !== "none");
      const sev = (n) => (st.interlocks[n] && st.interlocks[n].severity) || "warning";
      active.title = names.map((n) => `${n}: ${sev(n)}${st.interlocks[n] && st.interlocks[n].message ? " — " + st.interlocks[n].message : ""}`).join("\n");
      active.dataset.severity = names.some((n) => sev(n) === "error") ? "error"
        : names.some((n) => sev(n) === "warning") ? "warning" : names.length ? "info" : "";
    }
    for (const m of st.modules) {
      if (m.name === "robot") continue;
      const s = (msg.states || {})[m.name] || m.state || "unknown";
      const panel = document.querySelector(`[data-module="${m.name}"]`);
      setState(panel, stateClass(s), STATE_CLASSES);
      setClass(panel, "stale", s !== "ok" || !msg.reachable);
      const badge = document.querySelector(`[data-module-badge="${m.name}"]`);
      if (badge) { badge.textContent = s; setState(badge, stateClass(s), STATE_CLASSES); }
      setState(document.querySelector(`[data-module-dot="${m.name}"]`), stateClass(s), STATE_CLASSES);
      const problem = document.querySelector(`[data-module-problem="${m.name}"]`);
      const text = (msg.errors || {})[m.name] || m.problem || "";
      if (problem) { problem.textContent = text; setClass(problem, "hidden", !text); }
    }
    const robotPanel = document.querySelector(`[data-module="robot"]`);
    setState(robotPanel, msg.reachable ? "ok" : "fault", STATE_CLASSES);
    setState(document.querySelector(`[data-module-dot="robot"]`), msg.reachable ? "ok" : "fault", STATE_CLASSES);
    refreshPills();
    refreshHealth();
    refreshBatteries();
    refreshConnection();
    refreshBanner();
  }

  function refreshPills() {
    const s = st.status;
    const link = $("pill-link");
    if (!st.connected) { link.textContent = "console lost"; setState(link, "bad", STATE_CLASSES); }
    else if (!s || !s.reachable) { link.textContent = "robot link lost"; setState(link, "bad", STATE_CLASSES); }
    else { link.textContent = `link ok ${s.rtt_ms != null ? s.rtt_ms.toFixed(1) + " ms" : ""}`; setState(link, "ok", STATE_CLASSES); }
    const wd = value("robot:watchdog.state") || "?";
    const pw = $("pill-watchdog");
    pw.textContent = `watchdog ${wd}`;
    setState(pw, wd === "tripped" ? "warn" : wd === "armed" ? "drive" : wd === "idle" ? "ok" : "", STATE_CLASSES);
    const owner = value("robot:control.owner") || "?";
    const pc = $("pill-control");
    const mine = s && s.control && s.control.mine;
    pc.textContent = owner === "none" ? "control free" : `control: ${owner}${mine ? " (you)" : ""}`;
    setState(pc, mine ? "drive" : owner === "none" ? "" : "warn", STATE_CLASSES);
    // Who the robot says this console is (SPEC 13: robot:access.me=(IDENTITY,ROLE)).
    const me = (value("robot:access.me") || "").split(",");
    const pm = $("pill-me");
    pm.hidden = me.length !== 2;
    if (me.length === 2) {
      pm.textContent = `you: ${me[0]} (${me[1]})`;
      setState(pm, me[1] === "observer" ? "warn" : "", STATE_CLASSES);
    }
    $("take-control").disabled = !!mine;
    $("hand-back").disabled = !(s && s.control && s.control.want);
  }

  function fact(dl, name, text, cls) {
    dl.append(el("dt", { text: name }), el("dd", { class: cls || "", text }));
  }
  function refreshHealth() {
    const dl = $("health");
    dl.replaceChildren();
    const v = (k) => value(k);
    const late = (v("robot:tick.late") || "").split(",");
    fact(dl, "uptime", v("robot:robot.uptime") ? `${Number(v("robot:robot.uptime")).toFixed(0)} s` : "–");
    fact(dl, "tick rate", v("robot:tick.rate") ? `${v("robot:tick.rate")} Hz` : "–");
    fact(dl, "late p50/p99/max", late.length === 3 ? `${late[0]} / ${late[1]} / ${late[2]} µs` : "–",
      late.length === 3 && Number(late[1]) > 5000 ? "warn" : "");
    const over = v("robot:tick.overruns");
    fact(dl, "overruns", over ?? "–", over && Number(over) > 0 ? "warn" : "ok");
    const wd = v("robot:watchdog.state");
    fact(dl, "watchdog", wd ? `${wd} (${v("robot:watchdog.timeout") || "?"} s)` : "–",
      wd === "tripped" ? "warn" : wd === "armed" ? "drive" : "ok");
    const owner = v("robot:control.owner");
    fact(dl, "control owner", owner ?? "–", owner && owner !== "none" ? "warn" : "");
    fact(dl, "clients", v("robot:clients.count") ?? "–");
    // Interlocks, with the severity the robot gives each rule: an info rule (normal work,
    // such as digging_creep) is state here and a line in Events, never an alert.
    const active = (v("robot:interlock.active") || "none").split(",").filter((n) => n && n !== "none");
    const sev = (n) => (st.interlocks[n] && st.interlocks[n].severity) || "warning";
    const worst = active.some((n) => sev(n) === "error") ? "bad" : active.some((n) => sev(n) === "warning") ? "warn" : active.length ? "drive" : "ok";
    fact(dl, "interlocks", active.length ? active.map((n) => `${n} (${sev(n)})`).join(", ") : "none", worst);
    dl.lastChild.setAttribute("data-testid", "robot-interlocks");
    const states = (st.status && st.status.states) || {};
    for (const [m, s] of Object.entries(states)) {
      fact(dl, `module ${m}`, s, s === "ok" ? "ok" : s === "fault" ? "bad" : "warn");
    }
  }

  // Every property the robot reports in volts gets a gauge; its charge is the device's own
  // `charge` row in % (the robot's battery model) where it has one.
  function renderBatteries() {
    const box = $("batteries");
    const gauges = [];
    for (const m of st.modules) for (const d of m.devices) for (const p of d.properties) {
      if (p.unit === "V") {
        const key = `${m.name}:${d.name}.${p.name}`;
        const charge = d.properties.find((q) => q.unit === "%" && q.name === "charge");
        gauges.push(el("div", { class: "gauge", "data-gauge": key, "data-charge": charge ? `${m.name}:${d.name}.charge` : null },
          el("div", { class: "gauge-label" }, el("span", { text: `${m.name} ${d.name}` }),
            el("span", { class: "gauge-volts" })),
          el("div", { class: "gauge-bar" }, el("div", { class: "gauge-fill", style: "width:0%" }))));
      }
    }
    if (gauges.length) box.replaceChildren(...gauges);
  }
  function refreshBatteries() {
    const [empty, full] = (st.hello && st.hello.battery) || [17, 21];
    document.querySelectorAll("[data-gauge]").forEach((g) => {
      const text = value(g.dataset.gauge);
      const volts = Number(text);
      const fill = g.querySelector(".gauge-fill");
      if (text === undefined || !Number.isFinite(volts)) { g.querySelector(".gauge-volts").textContent = "–"; return; }
      const charge = g.dataset.charge ? Number(value(g.dataset.charge)) : NaN;
      const pct = Number.isFinite(charge) ? Math.max(0, Math.min(100, charge))
        : Math.max(0, Math.min(100, (100 * (volts - empty)) / (full - empty)));
      g.querySelector(".gauge-volts").textContent = `${volts.toFixed(2)} V · ${pct.toFixed(0)} %`;
      fill.style.width = `${pct}%`;
      setState(fill, pct < 20 ? "bad" : pct < 50 ? "warn" : "", ["bad", "warn"]);
    });
  }

  function refreshConnection() {
    const s = st.status;
    const set = (id, text, cls) => { const e = $(id); e.textContent = text; setState(e, cls, STATE_CLASSES); };
    set("conn-console", st.connected ? "connected" : "lost: ramp-teleop not reachable", st.connected ? "ok" : "bad");
    if (s) {
      set("conn-reachable", s.reachable ? "yes" : `no: ${s.detail}`, s.reachable ? "ok" : "bad");
      set("conn-rtt", s.rtt_ms != null ? `${s.rtt_ms.toFixed(2)} ms` : "–", "");
      const c = s.command_link || {};
      set("conn-command", c.up ? "up" : `down: ${c.detail || ""}`, c.up ? "ok" : "bad");
    }
    const profile = st.hello && st.hello.profile ? st.hello.profile.name : "?";
    set("conn-gamepad", st.pad ? `${st.pad.id.slice(0, 40)} · standard mapping · profile ${profile}` : st.padNote, st.pad ? "ok" : "");
  }

  function refreshBanner() {
    const b = $("banner");
    let text = "", cls = "";
    if (!st.connected) { text = "CONSOLE DISCONNECTED: ramp-teleop is not reachable. The robot stops by itself (watchdog)."; cls = "bad"; }
    // The robot's link, faults and watchdog are alerts (one place, with what to do); the
    // banner is only for what no alert can say: the console itself is gone.
    b.textContent = text;
    b.className = `banner ${cls}${text ? "" : " hidden"}`;
  }

  function refreshDrive() {
    const d = st.drive || {};
    const pill = $("pill-drive");
    const text = $("drive-text");
    let label = "idle", cls = "";
    if (d.engaged) { label = `DRIVING · ${d.source}`; cls = "drive"; }
    else if (d.latched) { label = "LATCHED · release the dead-man"; cls = "warn"; }
    else if (d.outstanding && d.outstanding.length) { label = `HOLDING · ${d.outstanding.join(", ")}`; cls = "drive"; }
    else if (d.live === false) { label = "page not live"; cls = "warn"; }
    pill.textContent = label;
    setState(pill, cls, STATE_CLASSES);
    text.textContent = label;
    setState(text, cls, STATE_CLASSES);
    $("drive-note").textContent = d.note || (d.engaged ? "" : "hold the dead-man (LB) or W/A/S/D to drive");
  }

  // ---- inputs: gamepad, keys, focus -----------------------------------------------------
  function readPad() {
    let pads = [];
    try { pads = navigator.getGamepads ? Array.from(navigator.getGamepads() || []) : []; } catch (e) { pads = []; }
    let std = null, other = null;
    for (const p of pads) {
      if (!p || p.connected === false) continue;
      if (p.mapping === "standard") { if (!std) std = p; } else if (!other) other = p;
    }
    if (!std) {
      st.pad = null;
      st.padNote = other ? `${other.id}: mapping "${other.mapping || "none"}" is not standard, not used` : "none detected (press a button)";
      return null;
    }
    const pad = {
      mapping: "standard",
      id: String(std.id || "gamepad"),
      axes: Array.from(std.axes || []).map((a) => Number(a) || 0),
      buttons: Array.from(std.buttons || []).map((b) => (typeof b === "number" ? [b >= 0.5, b]
        : [!!(b && b.pressed), Number(b && b.value !== undefined ? b.value : (b && b.pressed ? 1 : 0)) || 0])),
    };
    st.pad = pad;
    return pad;
  }
  function focused() { return document.hasFocus() && document.visibilityState !== "hidden"; }
  function sendInput() {
    const pad = readPad();
    send({ type: "input", focused: focused(), pad, keys: [...st.keys] });
    drawStick(pad);
  }
  function drawStick(pad) {
    const dot = $("stick-dot");
    const x = pad ? pad.axes[0] || 0 : 0, y = pad ? pad.axes[1] || 0 : 0;
    dot.style.left = `${34 + 30 * Math.max(-1, Math.min(1, x))}px`;
    dot.style.top = `${34 + 30 * Math.max(-1, Math.min(1, y))}px`;
    setClass(dot, "live", !!(st.drive && st.drive.engaged));
  }

  function isTyping(target) {
    return target && (target.tagName === "INPUT" || target.tagName === "TEXTAREA" || target.tagName === "SELECT");
  }
  function isSpace(e) { return e.code === "Space" || e.key === " " || e.key === "Spacebar"; }

  function stopNow() {
    const b = $("stop");
    b.classList.add("flash");
    setTimeout(() => b.classList.remove("flash"), 200);
    st.keys.clear();
    if (!send({ type: "stop" })) event("error", "STOP not delivered: the console is not connected (the robot's watchdog stops it)");
  }

  window.addEventListener("keydown", (e) => {
    if (isSpace(e)) {
      // Space is STOP wherever the focus is: never a character, never a button press.
      e.preventDefault();
      e.stopPropagation();
      if (!e.repeat) stopNow();
      return;
    }
    const key = (e.key || "").toLowerCase();
    if (key === "shift") { st.keys.add("shift"); return; }
    if (DRIVE_KEYS.has(key) && !isTyping(e.target) && !e.ctrlKey && !e.altKey && !e.metaKey) {
      e.preventDefault();
      if (!st.keys.has(key)) { st.keys.add(key); sendInput(); }
    }
  }, true);
  window.addEventListener("keyup", (e) => {
    if (isSpace(e)) { e.preventDefault(); e.stopPropagation(); return; }
    const key = (e.key || "").toLowerCase();
    if (st.keys.delete(key)) sendInput();
  }, true);
  window.addEventListener("blur", () => { st.keys.clear(); sendInput(); });
  window.addEventListener("focus", sendInput);
  document.addEventListener("visibilitychange", () => { st.keys.clear(); sendInput(); });
  window.addEventListener("gamepadconnected", (e) => {
    const pad = e && e.gamepad;
    event("info", `gamepad connected${pad && pad.id ? ": " + pad.id : ""}`);
    sendInput();
    refreshConnection();
  });
  window.addEventListener("gamepaddisconnected", () => { event("warning", "gamepad disconnected"); sendInput(); refreshConnection(); });

  $("stop").addEventListener("click", stopNow);
  $("take-control").addEventListener("click", () => send({ type: "control", action: "acquire" }));
  $("hand-back").addEventListener("click", () => send({ type: "control", action: "release" }));
  $("profile").addEventListener("change", (e) => send({ type: "profile", name: e.target.value }));

  setInterval(() => { sendInput(); }, INPUT_PERIOD_MS);
  setInterval(refreshConnection, 500);
  refreshDrive();
  refreshBanner();
  connect();
})();
