// The dashboard's entry point: wires the panels and runs the render loop.
import { $, S, STALE_S } from "./state.js";
import { onControl } from "./api.js";
import { connect, poll } from "./live.js";
import { drawPlan } from "./plan.js";
import { drawProfile } from "./profile.js";
import { drawNeedles } from "./needles.js";
import { renderAir, renderMessage, renderStatus } from "./readouts.js";
import { initRecordings } from "./recordings.js";
import { initCalibration } from "./calibration.js";
import { initRunway } from "./runway.js";
import { drawStripCharts, initStripCharts } from "./stripchart.js";
import { initAlarms } from "./alarms.js";
import { closeLookback, initLookback, openLookback, readUrl } from "./lookback.js";
import { initAccess } from "./access.js";

function render(now) {
  requestAnimationFrame(render);
  const lookback = window.radarLookback.active; // live panels hidden: only the live strip
  if (!lookback) drawStripCharts(now);
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
  renderStatus(st);
  if (lookback) { $("mode").textContent = "LOOK-BACK"; return; }
  renderMessage(S.last, stale);
  $("needles").hidden = !(st && st.path);
  if (st && st.path) drawNeedles(stale ? null : S.last);
  renderAir(st);
  drawPlan($("plan"));
  drawProfile($("profile"));
}

const lookAt = (recording) => openLookback({ recording, columns: [] });
onControl(poll);
initRecordings(lookAt);
initCalibration();
initRunway();
initStripCharts();
initAlarms();
initAccess();
initLookback(() => window.radarStrip.available);
$("to-live").onclick = () => { closeLookback(); S.dirty = true; };
$("to-lookback").onclick = () => { const id = $("rec-list").value; if (id) lookAt(id); };
const start = readUrl();
if (start) openLookback(start, false);
connect();
poll();
setInterval(poll, 500);
requestAnimationFrame(render);
window.radarReadyAt = performance.now(); // ms since navigation start
window.radarReady = true;
