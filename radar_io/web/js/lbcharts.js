// Look-back strip charts (uPlot): one chart per column over the chosen time range, the
// min / max band of each bucket from GET /api/recordings/{id}/series, GO (rise solid, fall
// dashed) / SYNC / alarm / clock-step markers, drag to zoom, double-click for the whole
// recording, a cursor line shared by every chart. X axis: seconds since the recording's
// first chunk.
import uPlot from "../vendor/uPlot.esm.js";
import { AXIS, COLORS, chartBox } from "./stripchart.js";

const CHART_W = 700;       // CSS px of a chart
const CHART_H = 150, Y_AXIS = 64, PAD = [10, 24, 0, 0];
/** CSS px of a chart's plot area (the padding and the y axis are fixed for that). */
export const PLOT_W = CHART_W - Y_AXIS - PAD[1] - PAD[3];

/** Marker colour of an event kind: go (edge rise / fall) green, sync amber, alarm… red,
 * clock… pink, annotations purple, others grey. */
export function eventColor(kind) {
  if (kind.startsWith("go")) return "#2ea043";
  if (kind === "sync") return "#d29922";
  if (kind.includes("alarm")) return "#da3633";
  if (kind.includes("clock")) return "#f778ba";
  if (kind === "annotation") return "#a371f7"; // notes, markers, test points
  return "#7a8494";
}

/** Decimals that show a step (s) exactly, or that resolve a twentieth of a span. */
export function decimalsFor(step) {
  for (let d = 0; d < 6; d++) if (Math.abs(step * 10 ** d - Math.round(step * 10 ** d)) < 1e-6 * 10 ** d) return d;
  return 6;
}

/** "1:02:03.5" (spans of 10 min and more) or "62.125 s": a time since the start with d decimals. */
export function fmtT(t, span, d = decimalsFor(+(span / 20).toPrecision(1))) {
  if (span < 600) return `${t.toFixed(d)} s`;
  const r = Number(t.toFixed(d)), h = Math.floor(r / 3600), m = Math.floor((r % 3600) / 60), s = r - 3600 * h - 60 * m;
  const ss = s.toFixed(d).padStart(d ? d + 3 : 2, "0");
  return h ? `${h}:${String(m).padStart(2, "0")}:${ss}` : `${m}:${ss}`;
}

/** More SYNC edges than this in the view: drawn as ticks at the top, not across the chart. */
const SYNC_LINES = 60;

/** The first index with arr[i] >= v (arr ascending). */
export function lowerBound(arr, v, key = (x) => x) {
  let lo = 0, hi = arr.length;
  while (lo < hi) { const mid = (lo + hi) >> 1; if (key(arr[mid]) < v) lo = mid + 1; else hi = mid; }
  return lo;
}

/**
 * A chart of one column. view(): the [start_s, end_s] shown; events(): the markers (sorted by
 * t_s); on: {zoom(a, b), reset(), cursor(t_s)} — what the operator did.
 */
export class ColumnChart {
  constructor(column, index, parent, view, events, on) {
    this.column = column;
    this.waiters = [];
    const color = COLORS[index % COLORS.length];
    this.value = document.createElement("span");  // the value at the cursor
    this.value.className = "strip-value";
    const { box, plot, close } = chartBox(parent, column, this.value);
    this.box = box;
    this.close = close;
    const markers = (u) => this.drawMarkers(u, events());
    this.u = new uPlot({
      width: CHART_W, height: CHART_H, legend: { show: false }, padding: PAD,
      scales: { x: { time: false, range: () => view() } },
      series: [{}, { label: `${column} min`, stroke: color, width: 1, spanGaps: false },
        { label: `${column} max`, stroke: color, width: 1, spanGaps: false }],
      bands: [{ series: [2, 1], fill: color + "55" }],
      axes: [{ ...AXIS, space: 90, values: (u, ticks, _a, _s, incr) => { const v = view(); return ticks.map((t) => fmtT(t, v[1] - v[0], decimalsFor(incr))); } },
        { ...AXIS, size: Y_AXIS }],
      cursor: { x: false, y: false, sync: { key: "lookback" }, drag: { x: true, y: false, setScale: false }, points: { show: false } },
      hooks: {
        draw: [markers, () => this.waiters.splice(0).forEach((f) => f())],
        setSelect: [(u) => {
          if (u.select.width < 3) return;
          const a = u.posToVal(u.select.left, "x"), b = u.posToVal(u.select.left + u.select.width, "x");
          u.setSelect({ left: 0, top: 0, width: 0, height: 0 }, false);
          on.zoom(a, b);
        }],
        setCursor: [(u) => { if (u.cursor.left >= 0 && u.cursor.event) on.cursor(u.posToVal(u.cursor.left, "x")); }],
      },
    }, [[], [], []], plot);
    this.u.over.addEventListener("dblclick", () => on.reset());
    this.line = document.createElement("div"); // the shared cursor, also when the mouse is away
    this.line.className = "lb-cursor";
    this.u.over.appendChild(this.line);
  }

  /** Plot width in CSS px (0 before the first layout). */
  get plotWidth() { return this.u.over.clientWidth; }

  /** New data; resolves once uPlot has drawn it. */
  setData(t, min, max) {
    const drawn = new Promise((resolve) => this.waiters.push(resolve));
    this.u.setData([t, min, max]);
    return drawn;
  }

  /** Vertical lines at the events inside the view (SYNC thin, the others thick). */
  drawMarkers(u, events) {
    const ctx = u.ctx, { left, top, width, height } = u.bbox, [v0, v1] = [u.scales.x.min, u.scales.x.max];
    const i0 = lowerBound(events, v0, (e) => e.t_s), i1 = lowerBound(events, v1 + 1e-9, (e) => e.t_s);
    let syncs = 0;
    for (let i = i0; i < i1; i++) if (events[i].kind === "sync") syncs++;
    const tick = 6 * devicePixelRatio;
    ctx.save();
    ctx.beginPath(); ctx.rect(left, top, width, height); ctx.clip();
    for (let i = i0; i < i1; i++) {
      const e = events[i], x = Math.round(u.valToPos(e.t_s, "x", true)) + 0.5;
      const bottom = e.kind === "sync" && syncs > SYNC_LINES ? top + tick : top + height;
      ctx.strokeStyle = eventColor(e.kind);
      ctx.globalAlpha = e.kind === "sync" ? 0.55 : 0.95;
      ctx.lineWidth = (e.kind === "sync" ? 1 : 2) * devicePixelRatio;
      const fall = e.kind === "go" && e.edge === "fall";
      ctx.setLineDash(fall ? [4 * devicePixelRatio, 3 * devicePixelRatio] : []);
      ctx.beginPath(); ctx.moveTo(x, top); ctx.lineTo(x, bottom); ctx.stroke();
    }
    ctx.restore();
  }

  /** Place the cursor line at t_s (hidden outside the view); text: the value there. */
  showCursor(t_s, text) {
    const x = t_s === null ? -1 : this.u.valToPos(t_s, "x");
    this.line.hidden = !(x >= 0 && x <= this.plotWidth);
    this.line.style.left = `${x}px`;
    this.value.textContent = text;
  }

  destroy() { this.u.destroy(); this.box.remove(); }
}
