// Who is signed in and what the role may do (GET /api/whoami with the token), and
// annotations: the Mark button and the "m" hotkey (POST /api/annotations), markers on the
// live strip charts (a uPlot draw hook added to each chart) — the look-back charts draw
// them from the recording's events. window.radarAccess for the tests.
import { $ } from "./state.js";
import { authHeader, control, request } from "./api.js";

const A = (window.radarAccess = { actor: null, role: null, can: ["read"], marks: [] });

//: buttons by what they need (the routes check the role themselves; this only hides)
const NEEDS = {
  record: ["rec-start", "rec-stop"],
  annotate: ["mark", "mark-kind", "mark-label"],
  replay: ["lb-play", "lb-pause", "lb-resume", "lb-step", "lb-stop"],
  calibrate: ["estimate", "apply"],
  runway: ["rw-go"],
};
const MARK_COLOR = "#a371f7";
const KEEP_MARKS = 200;

function applyRole() {
  const who = $("whoami");
  who.textContent = A.actor ? `${A.actor} (${A.role})` : "not signed in";
  who.title = A.actor ? `signed in as ${A.actor}, role ${A.role}: ${A.can.join(", ")}` : "no valid token";
  for (const [what, ids] of Object.entries(NEEDS)) {
    for (const id of ids) { const el = $(id); if (el) el.hidden = !A.can.includes(what); }
  }
}

export async function refreshWhoami() {
  try {
    const doc = await request("/api/whoami", { headers: authHeader() });
    Object.assign(A, { actor: doc.actor, role: doc.role, can: doc.can });
  } catch (e) {
    Object.assign(A, { actor: null, role: null, can: [] });
  }
  applyRole();
}

export async function mark() {
  const kind = $("mark-kind").value, label = $("mark-label").value.trim();
  const doc = await control("/api/annotations", { kind, label, text: "" });
  if (!doc) return null;
  A.marks.push({ t_s: doc.t_ns / 1e9, kind, label, recording: doc.recording });
  if (A.marks.length > KEEP_MARKS) A.marks.splice(0, A.marks.length - KEEP_MARKS);
  $("msg").textContent = `${kind} ${label} marked${doc.recording ? ` in ${doc.recording}` : " (no recording open: kept by the service)"}`;
  return doc;
}

/** uPlot draw hook: a vertical line (and label) at every mark in the chart's time range. */
function drawMarks(u) {
  const ctx = u.ctx, [x0, x1] = [u.scales.x.min, u.scales.x.max];
  ctx.save();
  ctx.strokeStyle = ctx.fillStyle = MARK_COLOR;
  ctx.lineWidth = 1.5;
  ctx.font = "11px sans-serif";
  for (const m of A.marks) {
    if (m.t_s < x0 || m.t_s > x1) continue;
    const x = Math.round(u.valToPos(m.t_s, "x", true));
    ctx.beginPath(); ctx.moveTo(x, u.bbox.top); ctx.lineTo(x, u.bbox.top + u.bbox.height); ctx.stroke();
    ctx.fillText(m.label || m.kind, x + 3, u.bbox.top + 12);
  }
  ctx.restore();
}

function hookCharts() {
  for (const chart of Object.values(window.radarStrip ? window.radarStrip.charts : {})) {
    if (chart.radarMarks) continue;
    chart.radarMarks = true;
    (chart.hooks.draw = chart.hooks.draw || []).push(drawMarks);
  }
}

export function initAccess() {
  $("mark").onclick = () => mark();
  document.addEventListener("keydown", (ev) => {
    const tag = (ev.target && ev.target.tagName) || "";
    if (ev.key !== "m" || ev.ctrlKey || ev.metaKey || ev.altKey || ["INPUT", "SELECT", "TEXTAREA"].includes(tag)) return;
    if (!A.can.includes("annotate")) return;
    ev.preventDefault();
    mark();
  });
  $("token").addEventListener("change", refreshWhoami);
  refreshWhoami();
  hookCharts();
  setInterval(hookCharts, 500);
}
