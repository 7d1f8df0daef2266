"use strict";
// The pages' one script: reads the JSON API (docs/web.md) and fills the page. No library.
const $ = (id) => document.getElementById(id);
const num = (v, d) => (v === null || v === undefined || !isFinite(v)) ? "–" : Number(v).toFixed(d);
const localTime = (ms) => new Date(ms).toLocaleString();

async function getJSON(url) {
  const r = await fetch(url, { cache: "no-store" });
  if (!r.ok) throw new Error("HTTP " + r.status);
  return r.json();
}

function setText(id, text, cls) {
  const el = $(id);
  el.textContent = text;
  el.className = cls || "";
}

function showStatus(s) {
  const a = $("activity");
  a.textContent = num(s.activity_mps, 3);
  a.dataset.value = s.activity_mps === null ? "" : String(s.activity_mps);
  a.dataset.heartbeat = String(s.heartbeat);
  setText("bls", num(s.activity_bls, 2));
  setText("smoothed", num(s.smoothed_mps, 3) + " m/s");
  setText("ci95", num(s.ci95_mps, 3) + " m/s");
  setText("fish", String(s.fish));
  setText("scale", s.scale);
  setText("feeding", s.feeding ? "recommended" : "no", s.feeding ? "good" : "");
  setText("status", s.status.replaceAll("_", " "));
  setText("fault", s.is_fault ? s.fault : (s.fault_code === 0 ? "none" : s.fault + " (not a fault)"), s.is_fault ? "bad" : "");
  setText("updated", localTime(s.time_unix_ms));
}

function live() {
  const img = $("frame");
  let busy = false;
  async function frame() {
    if (busy) return;
    busy = true;
    try {
      const r = await fetch("/api/latest.jpg", { cache: "no-store" });
      if (r.ok) {
        const url = URL.createObjectURL(await r.blob());
        const old = img.src;
        img.src = url;
        if (old.startsWith("blob:")) URL.revokeObjectURL(old);
      }
    } catch (e) { /* the next second tries again */ }
    busy = false;
  }
  async function tick() {
    try { showStatus(await getJSON("/api/status")); }
    catch (e) { setText("updated", "no answer from the box: " + e.message, "bad"); }
  }
  async function act(url) {
    const token = $("token").value.trim();
    sessionStorage.setItem("fme-token", token);
    try {
      const r = await fetch(url, { method: "POST", headers: token ? { "Authorization": "Bearer " + token } : {} });
      const body = await r.json().catch(() => ({}));
      setText("said", body.ok || body.error || ("HTTP " + r.status), r.ok ? "good" : "bad");
    } catch (e) { setText("said", "no answer from the box: " + e.message, "bad"); }
  }
  $("token").value = sessionStorage.getItem("fme-token") || "";
  $("snap").onclick = () => act("/api/snapshot");
  $("record").onclick = () => act("/api/record?label=" + encodeURIComponent($("label").value));
  tick(); frame();
  setInterval(() => { tick(); frame(); }, 1000);
}

const SVG = "http://www.w3.org/2000/svg";
function el(name, attrs, text) {
  const e = document.createElementNS(SVG, name);
  for (const k in attrs) e.setAttribute(k, attrs[k]);
  if (text !== undefined) e.textContent = text;
  return e;
}

// One chart: series [{values, colour}] over times `ts` (ms), horizontal lines [{y, colour}].
function chart(box, ts, series, lines, from, to, digits) {
  // Drawn at the box's own width, so the labels keep their size on a phone.
  const W = Math.max(300, Math.round(box.clientWidth || 900)), H = W < 600 ? 200 : 260;
  const L = 52, R = 12, T = 10, B = 28, ticks = W < 600 ? 2 : 4;
  const svg = el("svg", { viewBox: `0 0 ${W} ${H}`, role: "img" });
  let max = 0;
  for (const s of series) for (const v of s.values) if (v !== null && isFinite(v)) max = Math.max(max, v);
  for (const l of lines) if (l.y > 0) max = Math.max(max, l.y);
  max = max > 0 ? max * 1.1 : 1;
  const x = (t) => L + (t - from) / (to - from) * (W - L - R);
  const y = (v) => H - B - v / max * (H - T - B);
  for (let i = 0; i <= 4; i++) {
    const v = max * i / 4;
    svg.appendChild(el("line", { x1: L, x2: W - R, y1: y(v), y2: y(v), stroke: "#2a3947" }));
    svg.appendChild(el("text", { x: L - 6, y: y(v) + 4, "text-anchor": "end" }, v.toFixed(digits)));
  }
  for (let i = 0; i <= ticks; i++) {
    const t = from + (to - from) * i / ticks;
    const d = new Date(t);
    const label = to - from > 86400000 * 1.5 ? d.toLocaleDateString([], { month: "short", day: "numeric" }) + " " + d.toLocaleTimeString([], { hour: "2-digit", minute: "2-digit" }) : d.toLocaleTimeString([], { hour: "2-digit", minute: "2-digit" });
    svg.appendChild(el("text", { x: x(t), y: H - 8, "text-anchor": i === 0 ? "start" : (i === ticks ? "end" : "middle") }, label));
  }
  for (const l of lines) {
    if (l.y > 0) svg.appendChild(el("line", { x1: L, x2: W - R, y1: y(l.y), y2: y(l.y), stroke: l.colour, "stroke-dasharray": "6 4" }));
  }
  for (const s of series) {
    let d = "", pen = false;
    s.values.forEach((v, i) => {
      if (v === null || !isFinite(v)) { pen = false; return; }
      d += (pen ? "L" : "M") + x(ts[i]).toFixed(1) + " " + y(v).toFixed(1);
      pen = true;
    });
    svg.appendChild(el("path", { d, fill: "none", stroke: s.colour, "stroke-width": 1.5 }));
  }
  box.replaceChildren(svg);
}

function history() {
  async function load(span) {
    const to = Date.now(), from = to - span * 1000;
    $("csv").href = `/api/activity?format=csv&from=${from}&to=${to}`;
    try {
      const a = await getJSON(`/api/activity?from=${from}&to=${to}&points=900`);
      const ts = a.rows.map((r) => r.t);
      const th = a.feeding_thresholds_mps;
      chart($("activity-chart"), ts, [
        { values: a.rows.map((r) => r.activity_mps), colour: "#3fb3ff" },
        { values: a.rows.map((r) => r.smoothed_mps), colour: "#ffd23f" },
      ], [{ y: th.on_above, colour: "#e67800" }, { y: th.off_below, colour: "#9646c8" }], from, to, 3);
      chart($("fish-chart"), ts, [{ values: a.rows.map((r) => r.fish), colour: "#5cd67a" }], [], from, to, 0);
      setText("range", `${localTime(from)} – ${localTime(to)} (local time), ${a.rows.length} points`, "muted");
    } catch (e) { setText("range", "no history: " + e.message, "bad"); }
  }
  for (const b of document.querySelectorAll("[data-span]")) {
    b.onclick = () => {
      for (const o of document.querySelectorAll("[data-span]")) o.classList.toggle("on", o === b);
      load(Number(b.dataset.span));
    };
  }
  load(3600);
}

function health() {
  async function tick() {
    try {
      const s = await getJSON("/api/status");
      const h = s.health, r = h.record;
      const rows = [
        ["Frames/s (camera)", num(h.camera_fps, 1)],
        ["Detector runs/s", num(h.detector_hz, 1)],
        ["Depth runs/s", num(h.depth_hz, 1)],
        ["Frames captured / processed", h.frames_captured + " / " + h.frames_processed],
        ["Frames dropped", String(h.frames_dropped)],
        ["Capture errors, reconnects", h.capture_errors + ", " + h.reconnects],
        ["Pipeline errors", String(h.pipeline_errors)],
        ["Latency p50 / p99", num(h.latency_p50_ms, 1) + " / " + num(h.latency_p99_ms, 1) + " ms"],
        ["Status", s.status.replaceAll("_", " ")],
        ["Fault", s.fault],
        ["Modbus", h.modbus],
        ["Modbus clients, requests", `${h.modbus_clients} open, ${h.modbus_requests} answered, ${h.modbus_polled_last_10s ? "polled in the last 10 s" : "no poll in the last 10 s"}`],
        ["MQTT", h.mqtt],
        ["Metrics", h.metrics],
        ["History", h.history],
        ["Black box", r.active ? `on, ${num(r.ring_mb, 1)} MB, ${r.frames_dropped} dropped, ${r.write_errors} errors${r.disk_fault ? ", DISK FAULT" : ""}` : "off"],
        ["Saved, snapshots", r.saved + ", " + r.snapshots],
        ["Last file", r.last || "–"],
        ["Source", h.source],
        ["Uptime", s.uptime_s + " s"],
        ["Version", h.version + " (" + h.backend + ")"],
        ["Networks", ["detector", "depth"].map((k) => { const n = h.networks[k]; return n ? `${k} ${n.file} (${n.form}, ${n.backend})` : k + " none"; }).join("; ")],
      ];
      const dl = $("health");
      dl.replaceChildren();
      for (const [k, v] of rows) { dl.appendChild(Object.assign(document.createElement("dt"), { textContent: k })); dl.appendChild(Object.assign(document.createElement("dd"), { textContent: v })); }
    } catch (e) { $("health").textContent = "no answer from the box: " + e.message; }
  }
  tick();
  setInterval(tick, 2000);
}

const page = ({ live, history, health })[document.body.dataset.page];
if (page) page();
