// Plan view: X north up, Y east right, radar at the centre; range rings, the runway
// reference course, the reference path, the track and its sync marks.
import { $, S } from "./state.js";
import { runwayToRadar } from "./api.js";

/** A round grid step (1, 2 or 5 × 10^k) giving about five divisions of span. */
export function niceStep(span) {
  const raw = span / 5, p = Math.pow(10, Math.floor(Math.log10(raw)));
  for (const k of [1, 2, 5, 10]) if (k * p >= raw) return k * p;
  return 10 * p;
}

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

export function drawPlan() {
  const cv = $("plan"), g = cv.getContext("2d"), W = cv.width, H = cv.height;
  g.clearRect(0, 0, W, H);
  const pts = S.points, ref = S.ref;
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
