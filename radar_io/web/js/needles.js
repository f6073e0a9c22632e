// Fly-to deviation needles, like ILS: aircraft right of the path (DY > 0) → needle left of
// centre; above the path (DZ > 0) → needle below centre. Full scale: DY ±500 m, DZ ±150 m
// (the TLM1 scales).
import { $, S } from "./state.js";

export const DY_FULL_SCALE_M = 500;
export const DZ_FULL_SCALE_M = 150;

export function drawNeedles(m) {
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
  const dx = ok ? -clamp(m.dy_m / DY_FULL_SCALE_M) : 0, dz = ok ? clamp(m.dz_m / DZ_FULL_SCALE_M) : 0;
  g.beginPath(); g.moveTo(c + (dx * (W - 30)) / 2, 8); g.lineTo(c + (dx * (W - 30)) / 2, H - 8); g.stroke();
  g.beginPath(); g.moveTo(8, c + (dz * (H - 30)) / 2); g.lineTo(W - 8, c + (dz * (H - 30)) / 2); g.stroke();
  if (!ok) { g.fillStyle = "#da3633"; g.font = "bold 13px sans-serif"; g.fillText("NO DEV", 8, 18); }
  S.needles = { dx, dz, ok };
}
