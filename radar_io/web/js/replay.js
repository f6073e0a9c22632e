// Recordings and replay: start/stop recording, the recordings list with download and report
// links, replay controls (pause, resume, step, seek, back to live).
import { $, S } from "./state.js";
import { control, getJSON, onControl } from "./api.js";

/** The report of a recording (built by the service: GET /api/recordings/{id}/report). */
export const reportUrl = (id) => `/api/recordings/${encodeURIComponent(id)}/report`;

function updateLinks() {
  const id = $("rec-list").value, rep = $("rec-report"), pdf = $("rec-report-pdf");
  rep.hidden = pdf.hidden = !id;
  if (id) { rep.href = reportUrl(id); pdf.href = reportUrl(id) + "?format=pdf"; }
}

export async function listRecordings() {
  try {
    const list = await getJSON("/api/recordings"), sel = $("rec-list"), keep = sel.value;
    sel.innerHTML = "";
    for (const r of list) {
      const o = document.createElement("option");
      o.value = r.id; o.textContent = `${r.id} (${(r.size_bytes / 1e6).toFixed(1)} MB)${r.open ? " ●" : ""}`;
      sel.appendChild(o);
    }
    if (keep && list.some((r) => r.id === keep)) sel.value = keep;
  } catch (e) { /* offline */ }
  updateLinks();
}

export function renderReplay(st) {
  if (!st) return;
  const r = st.replay;
  $("replay-state").textContent = r ? `${r.recording}: ${r.position_s.toFixed(1)} / ${r.duration_s.toFixed(1)} s ×${r.speed}${r.paused ? " paused" : ""}${r.finished ? " (end)" : ""}` : "";
  if (r && document.activeElement !== $("seek")) $("seek").value = r.duration_s ? (100 * r.position_s) / r.duration_s : 0;
}

export function initReplay() {
  onControl(listRecordings);
  $("rec-list").onchange = updateLinks;
  $("rec-start").onclick = () => control("/api/recordings/start");
  $("rec-stop").onclick = () => control("/api/recordings/stop");
  $("replay").onclick = () => { S.points = []; control("/api/replay", { recording: $("rec-list").value, speed: Number($("speed").value) }); };
  $("pause").onclick = () => control("/api/replay/pause");
  $("resume").onclick = () => control("/api/replay/resume");
  $("step").onclick = () => control("/api/replay/step", { n: 1 });
  $("live").onclick = () => { S.points = []; control("/api/replay/stop"); };
  $("seek").onchange = () => {
    const r = S.status && S.status.replay;
    if (r) control("/api/replay/seek", { position_s: (Number($("seek").value) / 100) * r.duration_s });
  };
  listRecordings();
  setInterval(listRecordings, 5000);
}
