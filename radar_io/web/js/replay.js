// Recordings and replay: start/stop recording, the recordings list with download and report
// links, replay controls (pause, resume, step, seek, back to live). A replay is a session of
// its own (/api/replays); the views follow its websocket while the live flight goes on.
import { $, S } from "./state.js";
import { control, getJSON, onControl } from "./api.js";
import { watch } from "./live.js";

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

const session = (op) => `/api/replays/${S.replay.id}${op ? "/" + op : ""}`;
const onSession = (op, body) => { if (S.replay) control(session(op), body); };
const endSession = () => { if (S.replay) control(session(), undefined, "DELETE"); };

export function renderReplay(st) {
  if (!st) return;
  const r = S.replay && (st.replays || []).find((x) => x.id === S.replay.id);
  $("replay-state").textContent = r ? `${r.recording}: ${r.position_s.toFixed(1)} / ${r.duration_s.toFixed(1)} s ×${r.speed}${r.paused ? " paused" : ""}${r.finished ? " (end)" : ""}` : "";
  if (r && document.activeElement !== $("seek")) $("seek").value = r.duration_s ? (100 * r.position_s) / r.duration_s : 0;
}

export function initReplay() {
  onControl(listRecordings);
  $("rec-list").onchange = updateLinks;
  $("rec-start").onclick = () => control("/api/recordings/start");
  $("rec-stop").onclick = () => control("/api/recordings/stop");
  $("replay").onclick = async () => {
    const doc = await control("/api/replays", { recording: $("rec-list").value, speed: Number($("speed").value) });
    if (doc) { endSession(); watch({ id: doc.id, ws: doc.ws }); }
  };
  $("pause").onclick = () => onSession("pause");
  $("resume").onclick = () => onSession("resume");
  $("step").onclick = () => onSession("step", { n: 1 });
  $("live").onclick = () => { endSession(); watch(null); };
  $("seek").onchange = () => {
    const r = S.replay && S.status && (S.status.replays || []).find((x) => x.id === S.replay.id);
    if (r) onSession("seek", { position_s: (Number($("seek").value) / 100) * r.duration_s });
  };
  listRecordings();
  setInterval(listRecordings, 5000);
}
