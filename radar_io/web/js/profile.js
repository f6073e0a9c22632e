// Vertical profile: radar height vs ground range, the reference path, aircraft pressure altitude.
import { $, S } from "./state.js";
import { niceStep } from "./plan.js";

export function drawProfile() {
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
