// The dashboard's entry point: wires the panels and runs the render loop.
import { $, S, STALE_S } from "./state.js";
import { onControl } from "./api.js";
import { connect, poll } from "./live.js";
import { drawPlan } from "./plan.js";
import { drawProfile } from "./profile.js";
import { drawNeedles } from "./needles.js";
import { renderAir, renderMessage, renderStatus } from "./readouts.js";
import { initReplay, renderReplay } from "./replay.js";
import { initCalibration } from "./calibration.js";
import { initRunway } from "./runway.js";
import { drawStripCharts, initStripCharts } from "./stripchart.js";
import { initAlarms } from "./alarms.js";

function render(now) {
  requestAnimationFrame(render);
  drawStripCharts(now);
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
  renderMessage(S.last, stale);
  $("needles").hidden = !(st && st.path);
  if (st && st.path) drawNeedles(stale ? null : S.last);
  renderAir(st);
  renderStatus(st);
  renderReplay(st);
  drawPlan();
  drawProfile();
}

onControl(poll);
initReplay();
initCalibration();
initRunway();
initStripCharts();
initAlarms();
connect();
poll();
setInterval(poll, 500);
requestAnimationFrame(render);
window.radarReadyAt = performance.now(); // ms since navigation start
window.radarReady = true;
