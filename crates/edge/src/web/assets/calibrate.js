"use strict";
// The Calibrate page: a frozen frame, a click per reference, its measured x, y, z; Solve and
// Apply post them to /api/calibration (docs/web.md) and the overlay shows each one's error.

// The page's state: the marked references ({name, u, v, x, y, z}: image pixels and metres), the
// last answer's rows and the name of a bad reference, and the calibration in use.
const cal = { refs: [], solved: null, current: null };
const img = $("still"), canvas = $("marks");
function countText() {
  const n = cal.refs.length;
  setText("count", n === 0 ? "no reference marked (4 at least with the intrinsics, 6 or more without)"
    : n + " reference" + (n === 1 ? "" : "s") + " marked", n < 4 && n > 0 ? "bad" : "muted");
}
function draw() {
  if (!img.naturalWidth) return;
  canvas.width = img.naturalWidth; canvas.height = img.naturalHeight;
  const g = canvas.getContext("2d");
  // Marks and labels of one size on the screen, whatever the picture is scaled to.
  const s = img.naturalWidth / (canvas.clientWidth || img.naturalWidth);
  g.lineWidth = 2 * s; g.font = ((canvas.clientWidth < 500 ? 11 : 13) * s) + "px system-ui, sans-serif";
  cal.refs.forEach((r, i) => {
    const row = cal.solved && cal.solved.rows ? cal.solved.rows.find((x) => x.name === r.name) : null;
    const bad = cal.solved && cal.solved.bad === r.name;
    if (row && row.projected) {
      g.strokeStyle = "#ff5c5c";
      g.beginPath(); g.arc(row.projected[0], row.projected[1], 6 * s, 0, 2 * Math.PI); g.stroke();
      g.beginPath(); g.moveTo(r.u, r.v); g.lineTo(row.projected[0], row.projected[1]); g.stroke();
    }
    g.strokeStyle = bad ? "#ff5c5c" : "#5cd67a";
    g.beginPath(); g.moveTo(r.u - 7 * s, r.v); g.lineTo(r.u + 7 * s, r.v); g.moveTo(r.u, r.v - 7 * s); g.lineTo(r.u, r.v + 7 * s); g.stroke();
    let label = r.name;
    if (row && row.error_px !== null) label += " " + num(row.error_px, 1) + " px";
    if (bad) label += " BAD";
    const w = g.measureText(label).width + 6 * s;
    const x = Math.min(r.u + 8 * s, canvas.width - w), y = Math.max(r.v - 8 * s, 16 * s);
    g.fillStyle = "rgba(0,0,0,.65)"; g.fillRect(x, y - 13 * s, w, 17 * s);
    g.fillStyle = bad ? "#ff5c5c" : "#ffffff"; g.fillText(label, x + 3 * s, y);
  });
}
function field(r, key, i) {
  const inp = Object.assign(document.createElement("input"), { className: key, inputMode: "decimal", value: r[key] === null ? "" : String(r[key]), placeholder: key + " m" });
  inp.setAttribute("aria-label", key + " of " + r.name);
  inp.oninput = () => { r[key] = inp.value.trim() === "" ? null : Number(inp.value); };
  inp.dataset.index = String(i);
  return inp;
}
function list() {
  const box = $("refs");
  box.replaceChildren();
  cal.refs.forEach((r, i) => {
    const row = cal.solved && cal.solved.rows ? cal.solved.rows.find((x) => x.name === r.name) : null;
    const bad = cal.solved && cal.solved.bad === r.name;
    const div = document.createElement("div");
    div.className = "ref" + (bad ? " badref" : "");
    const name = Object.assign(document.createElement("input"), { className: "name", value: r.name, maxLength: 64 });
    name.setAttribute("aria-label", "name");
    name.onchange = () => { r.name = name.value.trim() || r.name; cal.solved = null; list(); draw(); };
    const px = Object.assign(document.createElement("span"), { className: "px muted", textContent: "u " + num(r.u, 1) + " v " + num(r.v, 1) });
    const err = Object.assign(document.createElement("span"), { className: "err" + (bad ? " bad" : ""), textContent: row && row.error_px !== null ? num(row.error_px, 2) + " px" + (row.error_m !== null ? " · " + num(row.error_m * 100, 1) + " cm" : "") : "" });
    const del = Object.assign(document.createElement("button"), { type: "button", textContent: "✕", title: "remove " + r.name });
    del.onclick = () => { cal.refs.splice(i, 1); cal.solved = null; list(); draw(); };
    div.append(name, px, field(r, "x", i), field(r, "y", i), field(r, "z", i), err, del);
    box.appendChild(div);
  });
  countText();
}
async function freeze() {
  try {
    const r = await fetch("/api/frame.jpg", { cache: "no-store" });
    if (!r.ok) throw new Error("HTTP " + r.status + " " + (await r.text()));
    const url = URL.createObjectURL(await r.blob());
    const old = img.src;
    img.onload = () => { draw(); img.dataset.frozen = String(Date.now()); };
    img.src = url;
    if (old.startsWith("blob:")) URL.revokeObjectURL(old);
    setText("said", "frame frozen: click each reference", "good");
  } catch (e) { setText("said", "no frame from the box: " + e.message, "bad"); }
}
function intrinsics() {
  const k = ["fx", "fy", "cx", "cy"].map((id) => $(id).value.trim());
  if (k.every((v) => v === "")) return null;
  return { fx: Number(k[0]), fy: Number(k[1]), cx: Number(k[2]), cy: Number(k[3]) };
}
async function post(apply) {
  const missing = cal.refs.find((r) => r.x === null || r.y === null || r.z === null || !isFinite(r.x) || !isFinite(r.y) || !isFinite(r.z));
  if (missing) { setText("said", "type x, y and z of " + missing.name, "bad"); return; }
  const token = $("token").value.trim();
  sessionStorage.setItem("fme-token", token);
  const body = { width: img.naturalWidth, height: img.naturalHeight, apply, references: cal.refs.map((r) => ({ name: r.name, x: r.x, y: r.y, z: r.z, u: r.u, v: r.v })) };
  const k = intrinsics();
  if (k) body.intrinsics = k;
  setText("said", apply ? "solving and applying…" : "solving…", "muted");
  try {
    const headers = { "Content-Type": "application/json" };
    if (token) headers.Authorization = "Bearer " + token;
    const r = await fetch("/api/calibration", { method: "POST", headers, body: JSON.stringify(body) });
    const a = await r.json().catch(() => ({}));
    cal.solved = { rows: a.references || [], bad: a.bad_reference || null };
    list(); draw();
    if (a.ok) {
      const what = "RMS " + num(a.rms_px, 2) + " px over " + cal.refs.length + " references";
      setText("said", a.applied ? "applied: " + what + ". " + (a.said || "") : "solved: " + what + (apply ? "" : ". Apply writes it and the box uses it."), "good");
      if (a.applied) inUse();
    } else {
      setText("said", (a.bad_reference ? a.bad_reference + " is bad: " : "") + (a.error || ("HTTP " + r.status)), "bad");
    }
    $("said").dataset.status = String(r.status);
  } catch (e) { setText("said", "no answer from the box: " + e.message, "bad"); }
}
async function inUse() {
  try {
    const c = await getJSON("/api/calibration");
    cal.current = c;
    const dl = $("inuse");
    dl.replaceChildren();
    const add = (k, v) => { dl.appendChild(Object.assign(document.createElement("dt"), { textContent: k })); dl.appendChild(Object.assign(document.createElement("dd"), { textContent: v })); };
    add("Calibration", c.calibrated ? c.file : "none: not calibrated");
    if (c.camera) {
      const m = c.camera;
      add("Camera at", "x " + num(m.center_w[0], 3) + " y " + num(m.center_w[1], 3) + " z " + num(m.center_w[2], 3) + " m");
      add("Intrinsics", "fx " + num(m.fx, 1) + " fy " + num(m.fy, 1) + " cx " + num(m.cx, 1) + " cy " + num(m.cy, 1) + " px");
    }
    add("References", c.references.length + (c.rms_px !== null ? ", RMS " + num(c.rms_px, 2) + " px when solved" : ""));
    add("Depth fit", c.fit.fitted ? "from " + c.fit.scale_from + ", residual " + num(c.fit.residual_m, 3) + " m, " + c.fit.references_visible + " visible" : "not fitted");
    add("Apply writes", c.apply_writes || "nothing: camera.calibration is not set");
    dl.dataset.applied = String(c.applied);
  } catch (e) { $("inuse").textContent = "no answer from the box: " + e.message; }
}
function calibrate() {
  canvas.addEventListener("click", (e) => {
    if (!img.naturalWidth) { setText("said", "freeze a frame first", "bad"); return; }
    const b = canvas.getBoundingClientRect();
    const u = (e.clientX - b.left) * img.naturalWidth / b.width, v = (e.clientY - b.top) * img.naturalHeight / b.height;
    let k = cal.refs.length + 1;
    while (cal.refs.some((r) => r.name === "r" + k)) k++;
    cal.refs.push({ name: "r" + k, u: Math.round(u * 10) / 10, v: Math.round(v * 10) / 10, x: null, y: null, z: null });
    cal.solved = null; list(); draw();
  });
  $("kuse").onclick = () => {
    if (!cal.current || !cal.current.camera) { setText("said", "no calibration in use to take the intrinsics from", "bad"); return; }
    for (const id of ["fx", "fy", "cx", "cy"]) $(id).value = String(cal.current.camera[id]);
  };
  $("token").value = sessionStorage.getItem("fme-token") || "";
  $("freeze").onclick = freeze;
  $("clear").onclick = () => { cal.refs.length = 0; cal.solved = null; list(); draw(); };
  $("solve").onclick = () => post(false);
  $("apply").onclick = () => post(true);
  window.addEventListener("resize", draw);
  list(); inUse();
  setInterval(inUse, 2000);
}
calibrate();
