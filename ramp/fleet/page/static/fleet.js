// The fleet page: every robot the broker carries, from what it publishes (GET /api/fleet),
// and the supervisor's commands (POST). No robot type is known here: a tile is whatever its
// factsheet and state say.
"use strict";
(() => {
  const $ = (id) => document.getElementById(id);
  const el = (tag, attrs = {}, ...kids) => {
    const e = document.createElement(tag);
    for (const [k, val] of Object.entries(attrs)) {
      if (k === "text") e.textContent = val; else if (val !== undefined && val !== null) e.setAttribute(k, val);
    }
    e.append(...kids);
    return e;
  };
  const post = (url) => fetch(url, { method: "POST" }).then((r) => r.json()).catch(() => ({ ok: false }));
  let last = null;

  function fact(dl, name, text, cls, testid) {
    dl.append(el("dt", { text: name }), el("dd", { text, class: cls || "", "data-testid": testid }));
  }

  function tile(r) {
    const t = el("article", { class: `tile ${r.connection}`, "data-testid": `robot-${r.serial}`, "data-serial": r.serial });
    t.append(el("h2", { text: r.serial }), el("div", { class: "type", "data-testid": "type", text: `${r.description || r.type} · ${r.manufacturer}` }));
    const dl = el("dl");
    fact(dl, "connection", `${r.connection}${r.age_s !== null ? ` · ${r.age_s.toFixed(1)} s ago` : ""}`, "", "connection");
    fact(dl, "battery", r.battery !== null ? `${r.battery.toFixed(0)} %` : (r.voltage ? `${r.voltage.toFixed(2)} V` : "–"), "", "battery");
    fact(dl, "control", r.owner || (r.mode === "SERVICE" ? "free" : "–"), "", "owner");
    fact(dl, "mode", r.mode || "–", "", "mode");
    fact(dl, "motion", r.driving ? "driving" : r.paused ? "paused" : "still", r.driving ? "driving" : "stopped", "motion");
    if (r.mission) fact(dl, "mission", r.mission, "", "mission");
    const stop = r.stop_ms !== null ? `${r.stop_ms.toFixed(0)} ms to driving=false` : r.stopping ? "stopping…" : "–";
    fact(dl, "last stop", stop, r.stop_ms !== null ? "stopped" : "", "stop-time");
    const errs = r.alerts.filter((a) => a.type !== "connection");
    fact(dl, "errors", errs.length ? errs.map((a) => `${a.type}: ${a.text}`).join("; ") : "none", errs.length ? "errors" : "", "errors");
    t.append(dl);
    const b = el("div", { class: "buttons" });
    const key = `${encodeURIComponent(r.manufacturer)}/${encodeURIComponent(r.serial)}`;
    const pause = el("button", { text: r.paused ? "Resume" : "Pause", "data-testid": "pause" });
    pause.onclick = () => post(`/api/robot/${key}/${r.paused ? "resume" : "pause"}`).then(refresh);
    const mission = el("button", { text: "Send mission", "data-testid": "send-mission", title: r.can_mission ? "an order with rmcMission: the robot's autonomy runs the whole mission" : "this robot lists no rmcMission (no autonomy)" });
    mission.disabled = !r.can_mission;
    mission.onclick = () => post(`/api/robot/${key}/mission`).then(refresh);
    b.append(pause, mission);
    if (r.console) b.append(el("a", { href: r.console, target: "_blank", text: "Open console", "data-testid": "console" }));
    t.append(b);
    return t;
  }

  function render(f) {
    last = f;
    $("broker").textContent = `broker ${f.broker} · ${f.connected ? "connected" : "NOT CONNECTED"} · ${f.robots.length} robot(s)`;
    // The console's alert model: by severity then recency (the server orders them), kept while
    // their cause holds, each with what happened and what to do.
    const alerts = f.alerts || [];
    $("alerts").replaceChildren(...alerts.map((a) => el("div", {
      class: `alert ${a.severity}`, "data-testid": "alert", "data-severity": a.severity, "data-alert": a.id,
      "data-serial": a.serial || undefined, role: a.severity === "error" ? "alert" : "status",
    }, el("span", { class: "alert-title", text: a.title }), el("span", { class: "alert-text", text: a.text }),
      el("span", { class: "alert-age", text: `for ${a.for_s.toFixed(0)} s` }))));
    const tiles = f.robots.map(tile);
    $("tiles").replaceChildren(...(tiles.length ? tiles : [el("div", { class: "empty", text: "No robot has spoken on the broker yet." })]));
  }

  function refresh() {
    return fetch("/api/fleet", { cache: "no-store" }).then((r) => r.json()).then(render).catch(() => {
      if (last) render({ ...last, connected: false, alerts: [{ id: "page", severity: "error", title: "Page server gone",
        text: "ramp-fleet does not answer: what this page shows is stale and its buttons do nothing. Restart ramp-fleet.", for_s: 0 }] });
    });
  }

  const stopAll = () => post("/api/stop_all").then(refresh);
  $("stop-all").onclick = stopAll;
  // Space is Stop all wherever the focus is, as the console's Space is its STOP: never a
  // press of the focused button (a Space on a focused Resume must not resume).
  const isSpace = (e) => e.code === "Space" || e.key === " " || e.key === "Spacebar";
  window.addEventListener("keydown", (e) => {
    if (!isSpace(e)) return;
    e.preventDefault();
    e.stopPropagation();
    if (!e.repeat) stopAll();
  }, true);
  window.addEventListener("keyup", (e) => { if (isSpace(e)) { e.preventDefault(); e.stopPropagation(); } }, true);
  refresh();
  setInterval(refresh, 250);
})();
