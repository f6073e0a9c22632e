// Strip charts: any numeric (or null) column of the live messages against receive time (UTC), chosen
// from a list, several at once, the choice kept in localStorage. Drawn with uPlot (vendored).
// window.radarStrip for the tests.
import uPlot from "../vendor/uPlot.esm.js";
import { $, onMessage } from "./state.js";

export const KEEP = 3000;          // messages kept (2 min at the websocket's 25 Hz)
export const REDRAW_S = 0.25;      // charts refreshed at most this often
export const STORE_KEY = "radar_io_strip_columns";
const SKIP = new Set(["msg_seq", "t_ns"]); // bookkeeping, not measurements
export const COLORS = ["#3b82f6", "#d29922", "#2ea043", "#f778ba", "#a371f7", "#da3633"];
export const AXIS = { stroke: "#7a8494", grid: { stroke: "#30363d", width: 1 }, ticks: { stroke: "#30363d" } };

const T = (window.radarStrip = { columns: [], available: [], charts: {}, messages: [], draws: 0 });
let lastDraw = 0;

function loadChoice() {
  try {
    const v = JSON.parse(localStorage.getItem(STORE_KEY) || "[]");
    return Array.isArray(v) ? v.filter((c) => typeof c === "string") : [];
  } catch (e) { return []; }
}
const saveChoice = () => localStorage.setItem(STORE_KEY, JSON.stringify(T.columns));

/** [times (s, UTC), values] of one column over the kept messages; missing values are null. */
export function seriesOf(column) {
  const t = [], y = [];
  for (const m of T.messages) {
    t.push(m.t_ns / 1e9);
    const v = m[column];
    y.push(typeof v === "number" ? v : typeof v === "boolean" ? Number(v) : null);
  }
  return [t, y];
}

function options(column, i) {
  return {
    width: 640, height: 140, legend: { show: true },
    tzDate: (ts) => uPlot.tzDate(new Date(ts * 1e3), "Etc/UTC"), // axis in UTC, not browser time
    scales: { x: { time: true } },
    series: [{ label: "UTC" }, { label: column, stroke: COLORS[i % COLORS.length], width: 1.5, spanGaps: false }],
    axes: [{ ...AXIS }, { ...AXIS, size: 60 }],
  };
}

/** A chart's box in parent: a head (the column's name, extra elements, a × button) above
 * the element uPlot draws in. */
export function chartBox(parent, column, ...extra) {
  const box = document.createElement("div");
  box.className = "strip";
  box.dataset.column = column;
  const head = document.createElement("div");
  head.className = "strip-head";
  const name = document.createElement("span");
  name.textContent = column;
  const close = document.createElement("button");
  close.textContent = "×"; close.title = `remove ${column}`;
  head.append(name, ...extra, close);
  const plot = document.createElement("div");
  box.append(head, plot);
  parent.appendChild(box);
  return { box, plot, close };
}

function addChart(column) {
  if (T.charts[column]) return;
  const { plot, close } = chartBox($("strip-charts"), column);
  close.onclick = () => removeColumn(column);
  T.charts[column] = new uPlot(options(column, Object.keys(T.charts).length), seriesOf(column), plot);
}

export function addColumn(column) {
  if (!column || T.columns.includes(column)) return;
  T.columns.push(column);
  saveChoice();
  addChart(column);
}

export function removeColumn(column) {
  T.columns = T.columns.filter((c) => c !== column);
  saveChoice();
  const chart = T.charts[column];
  if (chart) { chart.root.parentElement.parentElement.remove(); chart.destroy(); delete T.charts[column]; }
}

function updateAvailable(m) {
  let added = false;
  for (const [k, v] of Object.entries(m)) {
    // numeric columns; null counts (x_m is null while RX is NG, but it is a column)
    if (SKIP.has(k) || (v !== null && typeof v !== "number" && typeof v !== "boolean") || T.available.includes(k)) continue;
    T.available.push(k); added = true;
  }
  if (!added) return;
  T.available.sort();
  const sel = $("strip-col"), keep = sel.value;
  sel.replaceChildren(...T.available.map((k) => { const o = document.createElement("option"); o.value = o.textContent = k; return o; }));
  if (keep) sel.value = keep;
}

function onLive(m) {
  if (typeof m.t_ns !== "number") return;
  T.messages.push(m);
  if (T.messages.length > KEEP) T.messages.splice(0, T.messages.length - KEEP);
  updateAvailable(m);
}

/** Called from the render loop: refresh the charts at most every REDRAW_S. */
export function drawStripCharts(now) {
  if (now - lastDraw < REDRAW_S * 1000 || !T.columns.length) return;
  lastDraw = now;
  for (const c of T.columns) T.charts[c].setData(seriesOf(c));
  T.draws++;
}

export function initStripCharts() {
  onMessage.push(onLive);
  $("strip-add").onclick = () => addColumn($("strip-col").value);
  for (const c of loadChoice()) { T.columns.push(c); addChart(c); }
}
