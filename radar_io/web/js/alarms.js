// Limit alarms: a red banner with the active, unacknowledged alarms and an ACK button each
// (POST /api/alarms/{id}/ack with the control token); acknowledged alarms that are still
// active stay listed quietly in the header until they clear. Fed by {"type": "alarm"}
// websocket messages and by polling GET /api/alarms every second (no such route in
// /openapi.json, or a 404 → no alarm engine: no polling). window.radarAlarms for the tests.
import { $ } from "./state.js";
import { control } from "./api.js";

export const POLL_S = 1.0;
const A = (window.radarAlarms = { list: [], endpoint: null, acks: 0, error: "", shown: null });

const fmtValue = (v) => (typeof v === "number" ? (Math.abs(v) >= 100 ? v.toFixed(1) : v.toPrecision(4)) : String(v ?? "—"));
const fmtSince = (s) => (typeof s === "number" ? new Date(s * 1000).toISOString().slice(11, 19) + "Z" : String(s ?? ""));

function row(a) {
  const div = document.createElement("div");
  div.className = "alarm";
  div.dataset.id = a.id;
  const name = document.createElement("b");
  name.textContent = a.name || a.id;
  const what = document.createElement("span");
  const col = a.column ? `${a.column} = ${fmtValue(a.value)}` : fmtValue(a.value);
  what.textContent = ` ${col} (limit ${fmtValue(a.limit)}) since ${fmtSince(a.since)} `;
  const ack = document.createElement("button");
  ack.textContent = "ACK";
  ack.onclick = () => acknowledge(a.id);
  div.append(name, what, ack);
  return div;
}

/** Show this list of active alarms (replaces the previous one; the DOM is rebuilt only
 * when something changed, so an ACK button is not replaced under the operator's click). */
export function setAlarms(list) {
  A.list = Array.isArray(list) ? list : [];
  const key = JSON.stringify([A.list, A.error]);
  if (key === A.shown) return;
  A.shown = key;
  const open = A.list.filter((a) => !a.acknowledged), acked = A.list.filter((a) => a.acknowledged);
  const banner = $("alarms"), rows = open.map(row);
  if (open.length && A.error) {
    const err = document.createElement("div");
    err.className = "alarm-error";
    err.textContent = `acknowledge failed: ${A.error}`;
    rows.push(err);
  }
  banner.replaceChildren(...rows);
  banner.hidden = open.length === 0;
  const quiet = $("alarms-acked");
  quiet.textContent = acked.length ? `acknowledged: ${acked.map((a) => a.name || a.id).join(", ")}` : "";
  quiet.hidden = acked.length === 0;
  const count = $("ls-alarms"); // the live strip
  count.textContent = `${open.length} alarm${open.length === 1 ? "" : "s"}`;
  count.className = "tag " + (open.length ? "bad" : "off");
}

export async function acknowledge(id) {
  const doc = await control(`/api/alarms/${encodeURIComponent(id)}/ack`);
  if (doc !== null) A.acks++;
  A.error = doc === null ? $("msg").textContent : ""; // e.g. "401: control needs …" (no token)
  if (A.endpoint) await pollAlarms();
  else setAlarms(A.list);
}

export async function pollAlarms() {
  if (A.endpoint === false) return;
  try {
    const res = await fetch("/api/alarms", { cache: "no-store" });
    if (res.status === 404) { A.endpoint = false; setAlarms([]); return; }
    if (!res.ok) return;
    A.endpoint = true;
    const doc = await res.json();
    setAlarms(Array.isArray(doc) ? doc : doc.alarms);
  } catch (e) { /* offline: the status line says so */ }
}

/** Whether this service has an alarm engine: asked once from its OpenAPI document, so that a
 * service without one is not polled (and the console shows no 404 every second). */
async function hasAlarmEndpoint() {
  try {
    const doc = await (await fetch("/openapi.json")).json();
    return "/api/alarms" in (doc.paths || {});
  } catch (e) { return true; } // cannot tell: poll, a 404 stops it
}

export async function initAlarms() {
  if (!(await hasAlarmEndpoint())) { A.endpoint = false; return; }
  pollAlarms();
  setInterval(pollAlarms, POLL_S * 1000);
}
