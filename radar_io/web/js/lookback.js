// The look-back view: a recording's columns over any time range, from the service's series
// index (GET /api/recordings/{id}/series: min / max per bucket, never more buckets than the
// chart has pixels) and its events (GET …/events), with plan and profile views of the range
// and one cursor shared by all of them. The view is the URL:
//   /?recording=ID&start_s=S&end_s=E&columns=a,b   (no start_s / end_s: the whole recording)
// The live flight goes on meanwhile (the header's live strip). window.radarLookback for the tests.
import { $, fmt } from "./state.js";
import { getJSON, request } from "./api.js";
import { drawPlan } from "./plan.js";
import { drawProfile } from "./profile.js";
import { fillRecordings } from "./recordings.js";
import { ColumnChart, PLOT_W, decimalsFor, fmtT, lowerBound } from "./lbcharts.js";
import * as replay from "./replays.js";

const DEFAULT_COLUMNS = ["sr_m", "el_deg", "h_m"];
const TRACK = ["x_m", "y_m", "h_m"];   // the plan and profile views
const MAX_SYNC_MARKS = 100;            // more SYNC edges in the range: not marked on the plan
const PRESENT = "seq";                 // never null in a frame: null only in an empty bucket
const FALLBACK_COLUMNS = ["seq", "tod_s", "sr_m", "dsr_m", "el_deg", "del_deg", "az_deg", "daz_deg",
  "sr_c_m", "el_c_deg", "az_c_deg", "x_m", "y_m", "h_m", "go", "rx_good", "sync", "auto"];

const L = (window.radarLookback = {
  active: false,
  recording: null,
  columns: [],
  start_s: null, end_s: null,   // the range asked for (null: the recording's start / end)
  view: [0, 1],                 // the range shown (as the service answered it)
  url: null,                    // the last series query
  doc: null,                    // its answer
  data: null,                   // {t_s, columns}: the answer without its empty buckets
  events: [],                   // {kind, t_s, …} sorted by t_s
  cursor_s: null,
  charts: {},
  track: [],                    // plan / profile points of the range
  timings: [],                  // per load: {start_s, end_s, points, values, decimated, fetch_ms, draw_ms, total_ms}
  loads: 0,
  gen: 0,
  abort: null,
  available: () => [],          // the live columns (set by main.js)
});

// ------------------------------------------------------------------------------ the URL
const num = (v) => (v === null || v === "" || !Number.isFinite(Number(v)) ? null : Number(v));
const short = (v) => String(+v.toFixed(6));

/** The look-back view named by the page URL, or null (the live view). */
export function readUrl() {
  const q = new URLSearchParams(location.search);
  const recording = q.get("recording");
  if (!recording) return null;
  return { recording, start_s: num(q.get("start_s")), end_s: num(q.get("end_s")),
    columns: (q.get("columns") || "").split(",").filter(Boolean) };
}

function viewUrl() {
  let u = `${location.pathname}?recording=${encodeURIComponent(L.recording)}`;
  if (L.start_s !== null) u += `&start_s=${short(L.start_s)}`;
  if (L.end_s !== null) u += `&end_s=${short(L.end_s)}`;
  return u + `&columns=${L.columns.map(encodeURIComponent).join(",")}`;
}

function writeUrl(push) {
  const u = viewUrl();
  $("lb-link").href = u;
  if (u !== location.pathname + location.search) history[push ? "pushState" : "replaceState"](null, "", u);
}

// ------------------------------------------------------------------------------ the view
/** Open the look-back view: {recording, start_s, end_s, columns}; push: a new history entry. */
export async function openLookback(v, push = true) {
  const changed = v.recording !== L.recording;
  L.active = true;
  L.recording = v.recording;
  L.start_s = v.start_s ?? null; L.end_s = v.end_s ?? null;
  $("lookback").hidden = false; $("live-view").hidden = true;
  $("to-live").hidden = false; $("to-lookback").hidden = true;
  const cols = v.columns && v.columns.length ? v.columns : (L.columns.length ? L.columns : DEFAULT_COLUMNS);
  for (const c of Object.keys(L.charts)) if (!cols.includes(c)) dropChart(c);
  L.columns = [...cols];
  for (const c of L.columns) addChart(c);
  writeUrl(push);
  fillColumns();
  fillRecordings($("lb-rec")).then(() => { $("lb-rec").value = L.recording; }).catch(() => {});
  if (changed) { replay.stop(); L.cursor_s = null; L.events = []; loadEvents(); }
  return load();
}

/** Back to the live view (the live data never stopped). */
export function closeLookback(push = true) {
  replay.stop();
  L.active = false;
  L.gen++;
  if (L.abort) L.abort.abort();
  $("lookback").hidden = true; $("live-view").hidden = false;
  $("to-live").hidden = true; $("to-lookback").hidden = false;
  if (push && location.search) history.pushState(null, "", location.pathname);
}

/** Show [a, b] (s since the recording's start); resolves when drawn. */
export function zoom(a, b, push = true) {
  if (!(b > a)) return Promise.resolve();
  L.start_s = Math.max(0, a); L.end_s = b;
  writeUrl(push);
  return load();
}

/** The whole recording. */
export function reset(push = true) {
  L.start_s = L.end_s = null;
  writeUrl(push);
  return load();
}

function addChart(column) {
  if (L.charts[column]) return;
  const ch = new ColumnChart(column, Object.keys(L.charts).length, $("lb-charts"), () => L.view,
    () => L.events, { zoom, reset, cursor: (t) => setCursor(t) });
  ch.close.onclick = () => { dropChart(column); L.columns = L.columns.filter((c) => c !== column); writeUrl(true); };
  L.charts[column] = ch;
}

function dropChart(column) {
  L.charts[column].destroy();
  delete L.charts[column];
}

function fillColumns() {
  const live = L.available(), cols = live.length ? live : FALLBACK_COLUMNS, sel = $("lb-col"), keep = sel.value;
  if (sel.options.length === cols.length) return;
  sel.replaceChildren(...cols.map((c) => { const o = document.createElement("option"); o.value = o.textContent = c; return o; }));
  if (keep) sel.value = keep;
}

async function loadEvents() {
  const rec = L.recording;
  try {
    const doc = await getJSON(`/api/recordings/${encodeURIComponent(rec)}/events`);
    if (rec !== L.recording) return;
    L.events = doc.events.filter((e) => typeof e.t_s === "number").sort((a, b) => a.t_s - b.t_s);
    for (const ch of Object.values(L.charts)) ch.u.redraw(false, false);
    renderTrack();
  } catch (e) {
    $("lb-msg").textContent = `events: ${e.message}`;
  }
}

/** Ask for the range's buckets (as many as the charts have pixels) and draw them. */
async function load() {
  const gen = ++L.gen, t0 = performance.now(), charts = L.columns.map((c) => L.charts[c]);
  const points = Math.max(2, Math.floor(Math.min(PLOT_W, ...charts.map((c) => c.plotWidth || PLOT_W))));
  const cols = [...new Set([...L.columns, ...TRACK, PRESENT])];
  let url = `/api/recordings/${encodeURIComponent(L.recording)}/series?columns=${cols.join(",")}&points=${points}`;
  if (L.start_s !== null) url += `&start_s=${L.start_s}`;
  if (L.end_s !== null) url += `&end_s=${L.end_s}`;
  if (L.abort) L.abort.abort();
  const ac = (L.abort = new AbortController());
  L.url = url;
  let doc;
  try {
    doc = await request(url, { signal: ac.signal });
  } catch (e) {
    if (gen === L.gen) $("lb-msg").textContent = e.message;
    return;
  }
  if (gen !== L.gen) return; // a newer range was asked for meanwhile
  const t1 = performance.now();
  $("lb-msg").textContent = "";
  L.doc = doc;
  L.data = withoutEmptyBuckets(doc);
  L.view = [doc.start_s, doc.end_s];
  const none = { min: [], max: [] };
  await Promise.all(charts.map((ch) => {
    const c = L.data.columns[ch.column] || none;
    return ch.setData(L.data.t_s, c.min, c.max);
  }));
  renderTrack();
  const t2 = performance.now();
  const span = doc.end_s - doc.start_s;
  const n = doc.frames ?? doc.t_s.length;
  $("lb-range").textContent = `${fmtT(doc.start_s, span)} – ${fmtT(doc.end_s, span)} (${fmtT(span, span)}: ` +
    `${n.toLocaleString("en")} frames${doc.decimated ? ` in ${doc.t_s.length} buckets` : ""})`;
  L.timings.push({ start_s: doc.start_s, end_s: doc.end_s, points, values: doc.t_s.length,
    decimated: doc.decimated, fetch_ms: t1 - t0, draw_ms: t2 - t1, total_ms: t2 - t0 });
  L.loads++;
}

/** The answer without the buckets that hold no frame (PRESENT null). Frames carry the time
 * of the chunk that completed them, so a view zoomed to a few chunks has many empty buckets:
 * lines and the track go straight across them, and break only at null values of frames that
 * exist (NG rows of the coordinate columns). */
function withoutEmptyBuckets(doc) {
  const p = doc.columns[PRESENT];
  if (!p || !doc.decimated) return doc;
  const keep = [];
  p.min.forEach((v, i) => { if (v !== null) keep.push(i); });
  const pick = (a) => keep.map((i) => a[i]);
  const columns = {};
  for (const [c, v] of Object.entries(doc.columns)) columns[c] = { min: pick(v.min), max: pick(v.max) };
  return { ...doc, t_s: pick(doc.t_s), columns };
}

// ------------------------------------------------------------------------------ cursor
/** The index of the bucket holding t_s (or the last one with frames before it), or of the
 * nearest frame, in L.data; -1: none. */
function indexAt(t_s) {
  const t = L.data ? L.data.t_s : [];
  if (!t.length || t_s === null) return -1;
  if (L.data.decimated) return Math.min(Math.max(lowerBound(t, t_s + 1e-12) - 1, 0), t.length - 1);
  const i = lowerBound(t, t_s); // the nearest frame
  return i === 0 ? 0 : i === t.length || t_s - t[i - 1] < t[i] - t_s ? i - 1 : i;
}

const mid = (c, i) => (c.min[i] === null || c.max[i] === null ? null : (c.min[i] + c.max[i]) / 2);

/** "612.3" or "610.1 … 615.0" (a bucket's min and max). */
function valueText(c, i) {
  if (i < 0 || !c || c.min[i] === null) return "—";
  const d = Math.abs(c.max[i]) >= 1000 ? 1 : 4, lo = fmt(c.min[i], d), hi = fmt(c.max[i], d);
  return lo === hi ? lo : `${lo} … ${hi}`;
}

let cursorQueued = false;
/** Move the shared cursor (mouse over a chart, or the replay position). */
export function setCursor(t_s) {
  L.cursor_s = t_s;
  if (!cursorQueued) { cursorQueued = true; requestAnimationFrame(renderCursor); }
}

function renderCursor() {
  cursorQueued = false;
  const i = indexAt(L.cursor_s), cols = L.data ? L.data.columns : {}, span = L.view[1] - L.view[0];
  for (const ch of Object.values(L.charts)) ch.showCursor(L.cursor_s, i < 0 ? "" : `${valueText(cols[ch.column], i)}`);
  const d = decimalsFor(+(span / PLOT_W).toPrecision(1)); // to a pixel
  $("lb-cursor").textContent = L.cursor_s === null ? "" : `t = ${fmtT(L.cursor_s, span, d)}`;
  const rows = [...new Set([...L.columns, ...TRACK])].map((c) => {
    const tr = document.createElement("tr"), th = document.createElement("th"), td = document.createElement("td");
    th.textContent = c; td.textContent = valueText(cols[c], i); tr.append(th, td); return tr;
  });
  $("lb-values").replaceChildren(...rows);
  drawTrack(i);
}

/** The replay position: the cursor follows it, a zoomed view pages along with it. */
function follow(t_s) {
  setCursor(t_s);
  const span = L.view[1] - L.view[0];
  if (L.start_s !== null && (t_s < L.view[0] || t_s > L.view[1])) zoom(t_s, t_s + span, false);
}

function renderTrack() {
  const d = L.data;
  L.track = [];
  if (d && TRACK.every((c) => d.columns[c])) {
    const [x, y, h] = TRACK.map((c) => d.columns[c]);
    for (let i = 0; i < d.t_s.length; i++) {
      const p = { x: mid(x, i), y: mid(y, i), h: mid(h, i) };
      L.track.push(p.x === null || p.y === null || p.h === null ? null : { ...p, g: Math.hypot(p.x, p.y), sync: false });
    }
    const syncs = L.events.filter((e) => e.kind === "sync" && e.t_s >= L.view[0] && e.t_s <= L.view[1]);
    if (syncs.length <= MAX_SYNC_MARKS) for (const e of syncs) { const p = L.track[indexAt(e.t_s)]; if (p) p.sync = true; }
  }
  renderCursor();
}

function drawTrack(i) {
  const mark = i >= 0 ? L.track[i] || null : null;
  drawPlan($("lb-plan"), L.track, { mark, fit: true });
  drawProfile($("lb-profile"), L.track, { air: [], mark, fit: true });
}

// ------------------------------------------------------------------------------ wiring
/** available(): the columns the live messages carry. */
export function initLookback(available) {
  L.available = available;
  $("lb-rec").onchange = () => openLookback({ recording: $("lb-rec").value, columns: L.columns });
  $("lb-add").onclick = () => {
    const c = $("lb-col").value;
    if (!c || L.columns.includes(c)) return;
    L.columns.push(c); addChart(c); writeUrl(true); load();
  };
  $("lb-reset").onclick = () => reset();
  $("lb-play").onclick = () => replay.play(L.recording, L.cursor_s ?? L.view[0], Number($("lb-speed").value),
    () => L.events, follow);
  $("lb-pause").onclick = replay.pause;
  $("lb-resume").onclick = replay.resume;
  $("lb-step").onclick = replay.step;
  $("lb-stop").onclick = replay.stop;
  window.addEventListener("popstate", () => { const v = readUrl(); if (v) openLookback(v, false); else if (L.active) closeLookback(false); });
}
