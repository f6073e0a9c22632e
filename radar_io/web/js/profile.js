// Vertical profile: radar height vs ground range, the reference path, aircraft pressure
// altitude; from 0 (live) or fitted to the track (look-back).
import { S } from "./state.js";
import { lengthLabel, niceStep, polyline } from "./plan.js";

/** Draw the profile on canvas cv. pts: {g, h} (ground range, height, m), null = gap;
 * air: CAN samples to overlay; mark: a point to highlight; fit: frame the track only. */
export function drawProfile(cv, pts = S.points, { air = S.air, mark = null, fit = false } = {}) {
  const g = cv.getContext("2d"), W = cv.width, H = cv.height;
  g.clearRect(0, 0, W, H);
  const have = pts.filter((p) => p), path = fit ? null : S.path;
  let g0 = 0, g1 = 5000, h0 = 0, h1 = 500;
  if (fit && have.length) {
    g0 = h0 = Infinity; g1 = h1 = -Infinity;
    for (const p of have) { g0 = Math.min(g0, p.g); g1 = Math.max(g1, p.g); h0 = Math.min(h0, p.h); h1 = Math.max(h1, p.h); }
    const pg = Math.max(g1 - g0, 10) * 0.05, ph = Math.max(h1 - h0, 2) * 0.1;
    g0 -= pg; g1 += pg; h0 -= ph; h1 += ph;
  } else {
    for (const p of have) { g1 = Math.max(g1, p.g); h1 = Math.max(h1, p.h); }
    const pg = path ? path.x_m.map((x, i) => Math.hypot(x, path.y_m[i])) : [];
    if (path) path.h_m.forEach((h, i) => { g1 = Math.max(g1, pg[i]); h1 = Math.max(h1, h); });
    for (const a of air) if (a.pressure_altitude_m !== null) h1 = Math.max(h1, a.pressure_altitude_m);
    g1 *= 1.05; h1 *= 1.2;
  }
  const L = 44, B = 20, kx = (W - L - 8) / (g1 - g0), ky = (H - B - 8) / (h1 - h0);
  const P = (gr, h) => [L + (gr - g0) * kx, H - B - (h - h0) * ky];
  g.strokeStyle = "#30363d"; g.fillStyle = "#7a8494"; g.font = "11px sans-serif"; g.lineWidth = 1;
  const sg = niceStep(g1 - g0), sh = niceStep(h1 - h0);
  for (let v = Math.ceil(g0 / sg) * sg; v <= g1; v += sg) {
    const p = P(v, h0); g.beginPath(); g.moveTo(p[0], 8); g.lineTo(p[0], H - B); g.stroke();
    g.fillText(lengthLabel(v, g1 - g0), p[0] + 2, H - 6);
  }
  for (let v = Math.ceil(h0 / sh) * sh; v <= h1; v += sh) {
    const p = P(g0, v); g.beginPath(); g.moveTo(L, p[1]); g.lineTo(W, p[1]); g.stroke();
    g.fillText(v.toFixed(sh < 1 ? 1 : 0), 2, p[1] + 4);
  }
  if (path) {
    g.strokeStyle = "#a371f7"; g.lineWidth = 2;
    polyline(g, path.h_m.map((h, i) => ({ g: Math.hypot(path.x_m[i], path.y_m[i]), h })), P, (p) => P(p.g, p.h));
  }
  g.strokeStyle = "#3b82f6"; g.lineWidth = 2;
  polyline(g, pts, P, (p) => P(p.g, p.h));
  g.lineWidth = 1;
  g.fillStyle = "#f778ba";  // aircraft pressure altitude at the radar ground range of its arrival
  for (const a of air) if (a.radar_ground_range_m !== null && a.pressure_altitude_m !== null) {
    const q = P(a.radar_ground_range_m, a.pressure_altitude_m); g.fillRect(q[0] - 1.5, q[1] - 1.5, 3, 3);
  }
  if (mark) { const q = P(mark.g, mark.h); g.fillStyle = "#fff"; g.fillRect(q[0] - 4, q[1] - 4, 8, 8); }
  g.font = "11px sans-serif";
  g.fillStyle = "#3b82f6"; g.fillText("radar H", W - 170, 14);
  if (path) { g.fillStyle = "#a371f7"; g.fillText("path", W - 120, 14); }
  if (air.length) { g.fillStyle = "#f778ba"; g.fillText("press. alt", W - 85, 14); }
}
