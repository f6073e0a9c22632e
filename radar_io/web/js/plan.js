// Plan view: X north up, Y east right; range rings around the radar (live) or a grid fitted
// to the track (look-back); the runway reference course, the reference path, the track, its
// sync marks and one marked point (the latest, or the cursor).
import { S } from "./state.js";
import { runwayToRadar } from "./api.js";

/** A round grid step (1, 2 or 5 × 10^k) giving about five divisions of span. */
export function niceStep(span) {
  const raw = span / 5, p = Math.pow(10, Math.floor(Math.log10(raw)));
  for (const k of [1, 2, 5, 10]) if (k * p >= raw) return k * p;
  return 10 * p;
}

/** A length in m for an axis label: km above 5 km of span, else m (d decimals). */
export const lengthLabel = (v, span) =>
  span > 5000 ? `${(v / 1000).toFixed(span > 50000 ? 0 : 1)} km` : `${v.toFixed(span < 20 ? 1 : 0)} m`;

/** The runway centre line from 20 km before to 3 km past the runway origin, in the radar
 * frame, converted by the service (the formulas live in Python only). */
export async function loadReferenceCourse() {
  try {
    const r = await runwayToRadar([-20000, 0, 3000], [0, 0, 0], [0, 0, 0]);
    const pt = (i) => ({ x: r.x_m[i], y: r.y_m[i] });
    return { from: pt(0), td: pt(1), to: pt(2) };
  } catch (e) {
    return null; // no site: no reference course
  }
}

/** Stroke a polyline of points {x, y, …} (null breaks the line) through P. */
export function polyline(g, pts, P, key = (p) => P(p.x, p.y)) {
  g.beginPath();
  let pen = false;
  for (const p of pts) {
    if (!p) { pen = false; continue; }
    const q = key(p);
    if (pen) g.lineTo(q[0], q[1]); else g.moveTo(q[0], q[1]);
    pen = true;
  }
  g.stroke();
}

/** Draw the plan view on canvas cv. pts: {x, y, sync} in the radar frame (m), null = gap;
 * mark: the point to highlight (default the last); fit: frame the track instead of the radar. */
export function drawPlan(cv, pts = S.points, { mark, fit = false } = {}) {
  const g = cv.getContext("2d"), W = cv.width, H = cv.height;
  g.clearRect(0, 0, W, H);
  const ref = fit ? null : S.ref, path = S.path, have = pts.filter((p) => p);
  let ox = 0, oy = 0, r = 5000; // view centre (m) and half-span
  if (fit && have.length) {
    let x0 = Infinity, x1 = -Infinity, y0 = Infinity, y1 = -Infinity;
    for (const p of have) { x0 = Math.min(x0, p.x); x1 = Math.max(x1, p.x); y0 = Math.min(y0, p.y); y1 = Math.max(y1, p.y); }
    ox = (x0 + x1) / 2; oy = (y0 + y1) / 2; r = Math.max(x1 - x0, y1 - y0, 10) / 2;
  } else {
    for (let i = Math.max(0, have.length - 5000); i < have.length; i++) r = Math.max(r, Math.abs(have[i].x), Math.abs(have[i].y));
    if (ref) r = Math.max(r, Math.abs(ref.td.x), Math.abs(ref.td.y));
    if (path) for (let i = 0; i < path.x_m.length; i += 10) r = Math.max(r, Math.abs(path.x_m[i]), Math.abs(path.y_m[i]));
  }
  r *= 1.1;
  const k = (Math.min(W, H) / 2) / r, cx = W / 2, cy = H / 2;
  const P = (x, y) => [cx + (y - oy) * k, cy - (x - ox) * k]; // north up, east right
  g.strokeStyle = "#30363d"; g.fillStyle = "#7a8494"; g.font = "11px sans-serif"; g.lineWidth = 1;
  const step = niceStep(r);
  if (fit) { // a grid in the radar frame, labelled in m / km from the radar
    const gs = niceStep(2 * r), hx = (W / 2) / k, hy = (H / 2) / k;
    for (let y = Math.ceil((oy - hx) / gs) * gs; y <= oy + hx; y += gs) {
      const p = P(ox, y); g.beginPath(); g.moveTo(p[0], 0); g.lineTo(p[0], H); g.stroke();
      g.fillText(lengthLabel(y, 2 * r), p[0] + 2, H - 4);
    }
    for (let x = Math.ceil((ox - hy) / gs) * gs; x <= ox + hy; x += gs) {
      const p = P(x, oy); g.beginPath(); g.moveTo(0, p[1]); g.lineTo(W, p[1]); g.stroke();
      g.fillText(lengthLabel(x, 2 * r), 3, p[1] - 3);
    }
    g.fillText("X ↑  Y →", W - 60, 12);
  } else {
    for (let rr = step; rr <= r * 1.5; rr += step) {
      g.beginPath(); g.arc(cx, cy, rr * k, 0, 2 * Math.PI); g.stroke();
      g.fillText(`${(rr / 1000).toFixed(rr < 1000 ? 1 : 0)} km`, cx + 3, cy - rr * k - 3);
    }
    g.beginPath(); g.moveTo(cx, 0); g.lineTo(cx, H); g.moveTo(0, cy); g.lineTo(W, cy); g.stroke();
    g.fillText("N", cx + 4, 12); g.fillText("E", W - 12, cy - 4);
  }
  if (ref) {
    g.strokeStyle = "#d29922"; g.setLineDash([8, 6]); g.beginPath();
    g.moveTo(...P(ref.from.x, ref.from.y)); g.lineTo(...P(ref.to.x, ref.to.y)); g.stroke();
    g.setLineDash([]); g.fillStyle = "#d29922"; const t = P(ref.td.x, ref.td.y); g.fillRect(t[0] - 3, t[1] - 3, 6, 6);
  }
  if (path) {
    g.strokeStyle = "#a371f7"; g.lineWidth = 2;
    polyline(g, path.x_m.map((x, i) => ({ x, y: path.y_m[i] })), P);
    g.lineWidth = 1;
  }
  const radar = P(0, 0);
  g.fillStyle = "#fff"; g.beginPath(); g.arc(radar[0], radar[1], 4, 0, 2 * Math.PI); g.fill();
  g.strokeStyle = "#3b82f6"; g.lineWidth = 2;
  polyline(g, pts, P);
  g.lineWidth = 1;
  g.fillStyle = "#d29922";
  for (const p of have) if (p.sync) { const q = P(p.x, p.y); g.fillRect(q[0] - 2, q[1] - 2, 4, 4); }
  const m = mark === undefined ? have[have.length - 1] : mark;
  if (m) { const q = P(m.x, m.y); g.fillStyle = "#fff"; g.fillRect(q[0] - 4, q[1] - 4, 8, 8); }
}
