// radar_io operator dashboard: websocket live stream (decimated, resumable), status polling,
// plan and profile views on canvas, lamps, readouts, servo-error bars, replay controls.
"use strict";

const MAX_POINTS = 20000;
const STALE_S = 1.0;
const S = (window.radarState = {
  points: [],            // {x, y, h, g, sync}
  lastMsgSeq: null,      // resume point for ws ?from=
  instance: null,        // server instance: a change means the server restarted
  lastMsgAt: 0,          // performance.now() of the last message
  last: null,            // last message
  status: null,
  site: null,
  path: null,            // reference path polyline in the radar frame {x_m, y_m, h_m}
  air: [],               // air data samples (SI) with the radar ground range at arrival
  airSeq: 0,
  ws: null,
  connected: false,
  reconnects: 0,
  received: 0,
  stale: false,
  dirty: true,
});

const $ = (id) => document.getElementById(id);
const fmt = (v, d) => (v === null || v === undefined || Number.isNaN(v) ? "—" : Number(v).toFixed(d));

// ---------------------------------------------------------------- websocket
let backoff = 500;
async function connect() {
  try {
    const st = await (await fetch("/api/status", { cache: "no-store" })).json();
    if (S.instance !== null && st.instance !== S.instance) S.lastMsgSeq = null; // new server run
    S.instance = st.instance;
  } catch (e) {
    return retry();
  }
  const proto = location.protocol === "https:" ? "wss" : "ws";
  let url = `${proto}://${location.host}/ws/live?max_hz=25`;
  if (S.lastMsgSeq !== null) url += `&from=${S.lastMsgSeq}`;
  const ws = new WebSocket(url);
  S.ws = ws;
  ws.onopen = () => { S.connected = true; backoff = 500; S.dirty = true; };
  ws.onmessage = (ev) => {
    const m = JSON.parse(ev.data);
    if (S.lastMsgSeq !== null && m.msg_seq <= S.lastMsgSeq) return; // duplicate after resume
    S.lastMsgSeq = m.msg_seq;
    S.lastMsgAt = performance.now();
    S.received++;
    S.last = m;
    if (m.rx_good && m.x_m !== null) {
      S.points.push({ x: m.x_m, y: m.y_m, h: m.h_m, g: Math.hypot(m.x_m, m.y_m), sync: m.sync, s: m.msg_seq });
      if (S.points.length > MAX_POINTS) S.points.splice(0, S.points.length - MAX_POINTS);
    }
    S.dirty = true;
  };
  ws.onclose = () => {
    if (S.ws === ws) { S.connected = false; S.dirty = true; S.reconnects++; retry(); }
  };
  ws.onerror = () => ws.close();
}
function retry() {
  setTimeout(connect, backoff);
  backoff = Math.min(backoff * 2, 5000);
}

// ---------------------------------------------------------------- status polling
async function poll() {
  try {
    const st = await (await fetch("/api/status", { cache: "no-store" })).json();
    S.status = st;
    if (S.instance !== null && st.instance !== S.instance && S.ws) S.ws.close(); // restarted
    if (!S.site && st.site) S.site = await (await fetch("/api/site")).json();
    if (!S.path && st.path) S.path = await (await fetch("/api/path")).json();
    if (st.airdata) {
      const doc = await (await fetch(`/api/airdata?since=${S.airSeq}`)).json();
      for (const a of doc.samples) { S.air.push(a); S.airSeq = a.air_seq; }
      if (S.air.length > 8 * 600) S.air.splice(0, S.air.length - 8 * 600);
    }
  } catch (e) {
    S.status = null;
  }
  S.dirty = true;
}

// ---------------------------------------------------------------- drawing
function niceStep(span) {
  const raw = span / 5, p = Math.pow(10, Math.floor(Math.log10(raw)));
  for (const k of [1, 2, 5, 10]) if (k * p >= raw) return k * p;
  return 10 * p;
}

function referenceCourse() {
  // runway frame (2-9, 2-10): Xr = x cos ψ + y sin ψ + Xr0, Yr = −x sin ψ + y cos ψ + Yr0
  const s = S.site;
  if (!s) return null;
  const psi = (s.runway.heading_deg * Math.PI) / 180, c = Math.cos(psi), n = Math.sin(psi);
  const toRadar = (xr, yr) => {
    const a = xr - s.runway.radar_xr_m, b = yr - s.runway.radar_yr_m;
    return { x: a * c - b * n, y: a * n + b * c };
  };
  return { from: toRadar(-20000, 0), td: toRadar(0, 0), to: toRadar(3000, 0) };
}

function drawPlan() {
  const cv = $("plan"), g = cv.getContext("2d"), W = cv.width, H = cv.height;
  g.clearRect(0, 0, W, H);
  const pts = S.points, ref = referenceCourse();
  let r = 5000;
  for (let i = Math.max(0, pts.length - 5000); i < pts.length; i++) r = Math.max(r, Math.abs(pts[i].x), Math.abs(pts[i].y));
  if (ref) r = Math.max(r, Math.abs(ref.td.x), Math.abs(ref.td.y));
  const path = S.path;
  if (path) for (let i = 0; i < path.x_m.length; i += 10) r = Math.max(r, Math.abs(path.x_m[i]), Math.abs(path.y_m[i]));
  r *= 1.1;
  const k = (Math.min(W, H) / 2) / r, cx = W / 2, cy = H / 2;
  const P = (x, y) => [cx + y * k, cy - x * k]; // north up, east right
  g.strokeStyle = "#30363d"; g.fillStyle = "#7a8494"; g.font = "11px sans-serif"; g.lineWidth = 1;
  const step = niceStep(r);
  for (let rr = step; rr <= r * 1.5; rr += step) {
    g.beginPath(); g.arc(cx, cy, rr * k, 0, 2 * Math.PI); g.stroke();
    g.fillText(`${(rr / 1000).toFixed(rr < 1000 ? 1 : 0)} km`, cx + 3, cy - rr * k - 3);
  }
  g.beginPath(); g.moveTo(cx, 0); g.lineTo(cx, H); g.moveTo(0, cy); g.lineTo(W, cy); g.stroke();
  g.fillText("N", cx + 4, 12); g.fillText("E", W - 12, cy - 4);
  if (ref) {
    g.strokeStyle = "#d29922"; g.setLineDash([8, 6]); g.beginPath();
    g.moveTo(...P(ref.from.x, ref.from.y)); g.lineTo(...P(ref.to.x, ref.to.y)); g.stroke();
    g.setLineDash([]); g.fillStyle = "#d29922"; const t = P(ref.td.x, ref.td.y); g.fillRect(t[0] - 3, t[1] - 3, 6, 6);
  }
  if (path) {
    g.strokeStyle = "#a371f7"; g.lineWidth = 2; g.beginPath();
    path.x_m.forEach((x, i) => { const p = P(x, path.y_m[i]); if (i === 0) g.moveTo(p[0], p[1]); else g.lineTo(p[0], p[1]); });
    g.stroke(); g.lineWidth = 1;
  }
  g.fillStyle = "#fff"; g.beginPath(); g.arc(cx, cy, 4, 0, 2 * Math.PI); g.fill();
  g.strokeStyle = "#3b82f6"; g.lineWidth = 2; g.beginPath();
  for (let i = 0; i < pts.length; i++) {
    const p = P(pts[i].x, pts[i].y);
    if (i === 0) g.moveTo(p[0], p[1]); else g.lineTo(p[0], p[1]);
  }
  g.stroke();
  g.fillStyle = "#d29922";
  for (const p of pts) if (p.sync) { const q = P(p.x, p.y); g.fillRect(q[0] - 2, q[1] - 2, 4, 4); }
  if (pts.length) { const q = P(pts[pts.length - 1].x, pts[pts.length - 1].y); g.fillStyle = "#fff"; g.fillRect(q[0] - 4, q[1] - 4, 8, 8); }
}

function drawProfile() {
  const cv = $("profile"), g = cv.getContext("2d"), W = cv.width, H = cv.height;
  g.clearRect(0, 0, W, H);
  const pts = S.points;
  let gmax = 5000, hmax = 500;
  for (const p of pts) { gmax = Math.max(gmax, p.g); hmax = Math.max(hmax, p.h); }
  const path = S.path, pg = path ? path.x_m.map((x, i) => Math.hypot(x, path.y_m[i])) : [];
  if (path) path.h_m.forEach((h, i) => { gmax = Math.max(gmax, pg[i]); hmax = Math.max(hmax, h); });
  for (const a of S.air) if (a.pressure_altitude_m !== null) hmax = Math.max(hmax, a.pressure_altitude_m);
  gmax *= 1.05; hmax *= 1.2;
  const L = 40, B = 20, kx = (W - L - 8) / gmax, ky = (H - B - 8) / hmax;
  const P = (gr, h) => [L + gr * kx, H - B - h * ky];
  g.strokeStyle = "#30363d"; g.fillStyle = "#7a8494"; g.font = "11px sans-serif";
  for (let v = 0; v <= gmax; v += niceStep(gmax)) { const p = P(v, 0); g.beginPath(); g.moveTo(p[0], 8); g.lineTo(p[0], H - B); g.stroke(); g.fillText(`${(v / 1000).toFixed(0)} km`, p[0] + 2, H - 6); }
  for (let v = 0; v <= hmax; v += niceStep(hmax)) { const p = P(0, v); g.beginPath(); g.moveTo(L, p[1]); g.lineTo(W, p[1]); g.stroke(); g.fillText(`${v.toFixed(0)}`, 2, p[1] + 4); }
  if (path) {
    g.strokeStyle = "#a371f7"; g.lineWidth = 2; g.beginPath();
    path.h_m.forEach((h, i) => { const q = P(pg[i], h); if (i === 0) g.moveTo(q[0], q[1]); else g.lineTo(q[0], q[1]); });
    g.stroke();
  }
  g.strokeStyle = "#3b82f6"; g.lineWidth = 2; g.beginPath();
  pts.forEach((p, i) => { const q = P(p.g, p.h); if (i === 0) g.moveTo(q[0], q[1]); else g.lineTo(q[0], q[1]); });
  g.stroke();
  g.fillStyle = "#f778ba";  // aircraft pressure altitude at the radar ground range of its arrival
  for (const a of S.air) if (a.radar_ground_range_m !== null && a.pressure_altitude_m !== null) {
    const q = P(a.radar_ground_range_m, a.pressure_altitude_m); g.fillRect(q[0] - 1.5, q[1] - 1.5, 3, 3);
  }
  g.font = "11px sans-serif";
  g.fillStyle = "#3b82f6"; g.fillText("radar H", W - 170, 14);
  if (path) { g.fillStyle = "#a371f7"; g.fillText("path", W - 120, 14); }
  if (S.air.length) { g.fillStyle = "#f778ba"; g.fillText("press. alt", W - 85, 14); }
}

function drawNeedles(m) {
  // fly-to convention, like ILS: aircraft right of the path (DY > 0) → needle left of centre;
  // above the path (DZ > 0) → needle below centre. Full scale: DY ±500 m, DZ ±150 m (TLM1 scales).
  const cv = $("ils"), g = cv.getContext("2d"), W = cv.width, H = cv.height, c = W / 2;
  g.clearRect(0, 0, W, H);
  g.strokeStyle = "#30363d"; g.lineWidth = 1; g.strokeRect(0.5, 0.5, W - 1, H - 1);
  g.fillStyle = "#7a8494";
  for (let k = -2; k <= 2; k++) {
    if (!k) continue;
    g.beginPath(); g.arc(c + (k * (W - 30)) / 4, c, 3, 0, 2 * Math.PI); g.fill();
    g.beginPath(); g.arc(c, c + (k * (H - 30)) / 4, 3, 0, 2 * Math.PI); g.fill();
  }
  g.strokeStyle = "#fff"; g.strokeRect(c - 6, c - 6, 12, 12);
  const ok = m && m.dy_m !== null && m.dy_m !== undefined;
  const clamp = (v) => Math.max(-1, Math.min(1, v));
  g.lineWidth = 4;
  g.strokeStyle = ok ? "#d29922" : "#da3633";
  const dx = ok ? -clamp(m.dy_m / 500) : 0, dz = ok ? clamp(m.dz_m / 150) : 0;
  g.beginPath(); g.moveTo(c + (dx * (W - 30)) / 2, 8); g.lineTo(c + (dx * (W - 30)) / 2, H - 8); g.stroke();
  g.beginPath(); g.moveTo(8, c + (dz * (H - 30)) / 2); g.lineTo(W - 8, c + (dz * (H - 30)) / 2); g.stroke();
  if (!ok) { g.fillStyle = "#da3633"; g.font = "bold 13px sans-serif"; g.fillText("NO DEV", 8, 18); }
  S.needles = { dx, dz, ok };
}

function setBar(id, v, fullScale) {
  const el = $("b-" + id), val = $("v-" + id);
  if (v === null || v === undefined) { el.style.width = "0"; val.textContent = "—"; return; }
  const f = Math.max(-1, Math.min(1, v / fullScale));
  el.style.left = f >= 0 ? "50%" : `${50 + f * 50}%`;
  el.style.width = `${Math.abs(f) * 50}%`;
  el.classList.toggle("sat", Math.abs(v) >= 0.98 * fullScale);
  val.textContent = fmt(v, id === "dsr" ? 2 : 4);
}

function render() {
  requestAnimationFrame(render);
  const age = S.lastMsgAt ? (performance.now() - S.lastMsgAt) / 1000 : Infinity;
  const st = S.status;
  const srvAge = st && st.last_frame_age_s !== null ? st.last_frame_age_s : Infinity;
  const stale = Math.min(age, srvAge) > STALE_S || (st && !st.connected) || !S.connected;
  if (stale !== S.stale) { S.stale = stale; S.dirty = true; }
  if (stale) $("stale-age").textContent = Number.isFinite(Math.min(age, srvAge)) ? Math.min(age, srvAge).toFixed(1) : "∞";
  if (!S.dirty) return;
  S.dirty = false;
  $("stale").hidden = !stale;
  document.body.classList.toggle("stale", stale);
  const m = S.last;
  for (const k of ["go", "rx_good", "sync", "auto"]) $("lamp-" + k).classList.toggle("on", !!(m && m[k]) && !stale);
  if (m) {
    const good = m.rx_good;
    $("r-sr").textContent = fmt(good ? m.sr_c_m : m.sr_m, 1);
    $("r-el").textContent = fmt(good ? m.el_c_deg : m.el_deg, 4);
    $("r-az").textContent = fmt(good ? m.az_c_deg : m.az_deg, 4);
    $("r-x").textContent = fmt(m.x_m, 1); $("r-y").textContent = fmt(m.y_m, 1); $("r-h").textContent = fmt(m.h_m, 1);
    $("r-tod").textContent = fmt(m.tod_s, 3); $("r-seq").textContent = m.seq;
    setBar("dsr", m.dsr_m, 50); setBar("del", m.del_deg, 1); setBar("daz", m.daz_deg, 1);
    $("r-dy").textContent = fmt(m.dy_m, 1); $("r-dz").textContent = fmt(m.dz_m, 1);
    $("r-along").textContent = fmt(m.along_m, 0); $("r-leg").textContent = m.leg === undefined ? "—" : m.leg;
  }
  $("needles").hidden = !(st && st.path);
  if (st && st.path) drawNeedles(stale ? null : m);
  $("air").hidden = !(st && st.airdata);
  const a = S.air.length ? S.air[S.air.length - 1] : null;
  if (a) {
    $("a-ias").textContent = fmt(a.ias_mps, 1) + " m/s"; $("a-alt").textContent = fmt(a.pressure_altitude_m, 1) + " m";
    $("a-pitch").textContent = fmt(a.pitch_deg, 2) + "°"; $("a-roll").textContent = fmt(a.roll_deg, 2) + "°";
    $("a-hdg").textContent = fmt(a.heading_deg, 1) + "°"; $("a-shut").textContent = a.shutter_count ?? "—";
    $("a-dme1").textContent = fmt(a.dme1_m, 0) + " m"; $("a-dme2").textContent = fmt(a.dme2_m, 0) + " m";
    $("air-age").textContent = st && st.airdata && st.airdata.last_sample_age_s !== null ? `${st.airdata.last_sample_age_s.toFixed(1)} s ago` : "";
  }
  $("link").textContent = S.connected ? "ONLINE" : "OFFLINE";
  $("link").className = "tag " + (S.connected ? "ok" : "bad");
  if (st) {
    $("mode").textContent = st.mode.toUpperCase();
    $("source").textContent = st.source + (st.connected ? "" : ` (disconnected: ${st.last_error || "…"})`);
    $("calib").textContent = `cal: ${st.calibration}`;
    $("cal-active").textContent = st.calibration;
    $("rec").className = "tag " + (st.recording ? "on" : "off");
    $("rec").title = st.recording || "not recording";
    $("c-rate").textContent = fmt(st.rate_hz, 0) + " Hz"; $("c-frames").textContent = st.frames;
    $("c-crc").textContent = st.crc_errors; $("c-impl").textContent = st.implausible;
    $("c-disc").textContent = st.bytes_discarded; $("c-gaps").textContent = st.seq_gaps;
    $("c-ws").textContent = st.ws_clients; $("c-drop").textContent = st.ws_dropped;
    $("c-reconn").textContent = st.reconnects;
    const r = st.replay;
    $("replay-state").textContent = r ? `${r.recording}: ${r.position_s.toFixed(1)} / ${r.duration_s.toFixed(1)} s ×${r.speed}${r.paused ? " paused" : ""}${r.finished ? " (end)" : ""}` : "";
    if (r && document.activeElement !== $("seek")) $("seek").value = r.duration_s ? (100 * r.position_s) / r.duration_s : 0;
  }
  $("c-points").textContent = S.points.length;
  drawPlan();
  drawProfile();
}

// ---------------------------------------------------------------- control
const token = $("token");
token.value = localStorage.getItem("radar_io_token") || "";
token.onchange = () => localStorage.setItem("radar_io_token", token.value);

async function control(path, body, method = "POST") {
  const res = await fetch(path, {
    method, headers: { "Content-Type": "application/json", Authorization: `Bearer ${token.value}` },
    body: body === undefined ? undefined : JSON.stringify(body),
  });
  const doc = await res.json().catch(() => ({}));
  $("msg").textContent = res.ok ? "" : `${res.status}: ${typeof doc.detail === "string" ? doc.detail : JSON.stringify(doc.detail)}`;
  poll(); listRecordings();
  return doc;
}
async function listRecordings() {
  try {
    const list = await (await fetch("/api/recordings")).json(), sel = $("rec-list"), keep = sel.value;
    sel.innerHTML = "";
    for (const r of list) { const o = document.createElement("option"); o.value = r.id; o.textContent = `${r.id} (${(r.size_bytes / 1e6).toFixed(1)} MB)${r.open ? " ●" : ""}`; sel.appendChild(o); }
    if (keep) sel.value = keep;
  } catch (e) { /* offline */ }
}
$("rec-start").onclick = () => control("/api/recordings/start");
$("rec-stop").onclick = () => control("/api/recordings/stop");
$("replay").onclick = () => { S.points = []; control("/api/replay", { recording: $("rec-list").value, speed: Number($("speed").value) }); };
$("pause").onclick = () => control("/api/replay/pause");
$("resume").onclick = () => control("/api/replay/resume");
$("step").onclick = () => control("/api/replay/step", { n: 1 });
$("live").onclick = () => { S.points = []; control("/api/replay/stop"); };
$("seek").onchange = () => {
  const r = S.status && S.status.replay;
  if (r) control("/api/replay/seek", { position_s: (Number($("seek").value) / 100) * r.duration_s });
};

// ---------------------------------------------------------------- calibration
let proposed = null;
function parseObservations(text) {
  const lines = text.trim().split(/\r?\n/).filter((l) => l.trim());
  const head = lines.shift().split(",").map((h) => h.trim());
  return lines.map((l) => {
    const v = l.split(","), o = {};
    head.forEach((h, i) => { o[h] = ["group", "recording"].includes(h) ? v[i].trim() : Number(v[i]); });
    return o;
  });
}
$("estimate").onclick = async () => {
  let observations;
  try { observations = parseObservations($("obs").value); } catch (e) { $("cal-result").textContent = "cannot read the table: " + e; return; }
  const doc = await control("/api/calibration/bias", { id: $("cal-id").value || "photo", observations });
  if (!doc.statistics) { $("cal-result").textContent = $("msg").textContent; $("apply").disabled = true; return; }
  proposed = doc.calibration;
  const f = (s) => `${s.mean.toFixed(4)} ± ${s.std.toFixed(4)}`, lines = [];
  for (const [g, s] of [...Object.entries(doc.statistics.groups), ["combined", doc.statistics.combined]])
    lines.push(`${g.padEnd(10)} n=${String(s.n).padEnd(3)} ΔSR ${f(s.dsr_m)} m  ΔEL ${f(s.del_deg)}°  ΔAZ ${f(s.daz_deg)}°`);
  $("cal-result").textContent = lines.join("\n");
  $("apply").disabled = false;
};
$("apply").onclick = async () => {
  if (!proposed) return;
  await control("/api/calibration", proposed, "PUT");
  $("apply").disabled = true;
};

// ---------------------------------------------------------------- runway vision
const RW = (window.runwayState = { img: null, width: 0, height: 0, points: { horizon: [], left_edge: [], right_edge: [] }, lines: null, result: null });
const RW_COLORS = { horizon: "#50dc50", left_edge: "#e63c3c", right_edge: "#2878e6" };
function rwDraw() {
  const cv = $("rw-canvas"), g = cv.getContext("2d");
  if (!RW.img) return;
  cv.width = RW.width; cv.height = RW.height;
  g.drawImage(RW.img, 0, 0);
  for (const [k, pts] of Object.entries(RW.points)) {
    g.fillStyle = RW_COLORS[k];
    for (const [x, y] of pts) { g.beginPath(); g.arc(x, y, 4, 0, 2 * Math.PI); g.fill(); }
  }
}
function rwShow(doc) {
  RW.result = doc;
  const f = (v, d, u) => (v === null || v === undefined ? "—" : `${Number(v).toFixed(d)}${u}`);
  $("rw-result").textContent = doc.found
    ? `bank ${f(doc.bank_deg, 2, "°")}  pitch ${f(doc.pitch_deg, 2, "°")}  yaw ${f(doc.yaw_deg, 2, "°")}  height ${f(doc.height_m, 1, " m")}  lateral ${f(doc.lateral_m, 1, " m")}  quality ${f(doc.quality, 2, "")}`
    : `no runway found: ${doc.reason || doc.detail || "?"}`;
}
function rwLoadImage(src, w, h) {
  return new Promise((resolve) => {
    const im = new Image();
    im.onload = () => { RW.img = im; RW.width = w || im.naturalWidth; RW.height = h || im.naturalHeight; rwDraw(); resolve(); };
    im.src = src;
  });
}
$("rw-file").onchange = async () => {
  const file = $("rw-file").files[0];
  if (file && file.type.startsWith("image/")) {
    RW.points = { horizon: [], left_edge: [], right_edge: [] };
    await rwLoadImage(URL.createObjectURL(file));
  }
};
$("rw-go").onclick = async () => {
  const file = $("rw-file").files[0];
  if (!file) { $("rw-result").textContent = "choose an image or a video first"; return; }
  $("rw-result").textContent = "…";
  const q = `focal_px=${$("rw-f").value}&half_width_m=${$("rw-d").value}`;
  const res = await fetch(`/api/runway?${q}`, { method: "POST", body: file, headers: { "Content-Type": file.type || "application/octet-stream", Authorization: `Bearer ${token.value}` } });
  let doc = await res.json();
  if (!res.ok) { $("rw-result").textContent = `${res.status}: ${typeof doc.detail === "string" ? doc.detail : JSON.stringify(doc.detail)}`; return; }
  if (res.status === 202) { // a video: a job on the server, polled until it ends
    for (;;) {
      await new Promise((ok) => setTimeout(ok, 500));
      const job = await (await fetch(doc.status_url)).json();
      $("rw-result").textContent = `${job.state}: ${job.frames_done} / ${job.frames_total ?? "?"} frames`;
      if (job.state === "done") { doc = job.result; break; }
      if (job.state === "failed" || job.state === "cancelled") { $("rw-result").textContent = `${job.state}: ${job.error || ""}`; return; }
    }
  }
  if (doc.frames) { RW.result = doc; $("rw-result").textContent = doc.frames.map((r) => `#${r.frame} ` + (r.found ? `bank ${r.bank_deg} pitch ${r.pitch_deg} yaw ${r.yaw_deg} h ${r.height_m} lat ${r.lateral_m} q ${r.quality}` : `not found: ${r.reason}`)).join("\n"); return; }
  if (doc.overlay_png_base64) await rwLoadImage("data:image/png;base64," + doc.overlay_png_base64, doc.image.width, doc.image.height);
  rwShow(doc);
};
$("rw-canvas").onclick = (ev) => {
  if (!RW.img) return;
  const cv = $("rw-canvas"), r = cv.getBoundingClientRect();
  const x = ((ev.clientX - r.left) * cv.width) / r.width, y = ((ev.clientY - r.top) * cv.height) / r.height;
  RW.points[$("rw-line").value].push([x, y]);
  rwDraw();
};
$("rw-clear").onclick = () => { RW.points = { horizon: [], left_edge: [], right_edge: [] }; rwDraw(); };
$("rw-manual").onclick = async () => {
  if (!RW.img) { $("rw-result").textContent = "load an image first"; return; }
  const body = { points: RW.points, focal_px: Number($("rw-f").value), half_width_m: Number($("rw-d").value), principal_point: [RW.width / 2, RW.height / 2] };
  const res = await fetch("/api/runway/manual", { method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify(body) });
  const doc = await res.json();
  if (!res.ok) { $("rw-result").textContent = `${res.status}: ${typeof doc.detail === "string" ? doc.detail : JSON.stringify(doc.detail)}`; return; }
  rwShow(doc);
};

connect();
poll();
listRecordings();
setInterval(poll, 500);
setInterval(listRecordings, 5000);
requestAnimationFrame(render);
