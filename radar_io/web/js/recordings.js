// Recordings: start/stop recording, the recordings list with the report links and the
// "Look back" button that opens the selected recording in the look-back view.
import { $ } from "./state.js";
import { control, getJSON, onControl } from "./api.js";

/** The report of a recording (built by the service: GET /api/recordings/{id}/report). */
export const reportUrl = (id) => `/api/recordings/${encodeURIComponent(id)}/report`;

function updateLinks() {
  const id = $("rec-list").value, rep = $("rec-report"), pdf = $("rec-report-pdf");
  rep.hidden = pdf.hidden = !id;
  $("rec-open").disabled = !id;
  if (id) { rep.href = reportUrl(id); pdf.href = reportUrl(id) + "?format=pdf"; }
}

/** Fill a <select> with the recordings (newest first; ● = being written); keeps the choice. */
export async function fillRecordings(sel) {
  const list = await getJSON("/api/recordings"), keep = sel.value;
  sel.replaceChildren(...list.map((r) => {
    const o = document.createElement("option");
    o.value = r.id; o.textContent = `${r.id} (${(r.size_bytes / 1e6).toFixed(1)} MB)${r.open ? " ●" : ""}`;
    return o;
  }));
  if (keep && list.some((r) => r.id === keep)) sel.value = keep;
  return list;
}

export async function listRecordings() {
  try { await fillRecordings($("rec-list")); } catch (e) { /* offline */ }
  updateLinks();
}

/** open(recordingId): what "Look back" does with the selected recording. */
export function initRecordings(open) {
  onControl(listRecordings);
  $("rec-list").onchange = updateLinks;
  $("rec-start").onclick = () => control("/api/recordings/start");
  $("rec-stop").onclick = () => control("/api/recordings/stop");
  $("rec-open").onclick = () => { if ($("rec-list").value) open($("rec-list").value); };
  listRecordings();
  setInterval(listRecordings, 5000);
}
