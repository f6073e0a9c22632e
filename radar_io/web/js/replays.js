// Replay inside the look-back view: a replay session of the service (POST /api/replays; it
// has its own pipeline and reaches no live output) and its websocket /ws/replays/{id}, whose
// recorded messages move the look-back cursor. Pause / resume / step / stop act on the
// session; leaving the view or the page ends it. window.radarReplay for the tests.
import { $ } from "./state.js";
import { authHeader, control, getJSON } from "./api.js";

const R = (window.radarReplay = { id: null, state: null, ws: null, messages: 0, last: null, position_s: null });
let poller = null;
const out = () => $("lb-msg");
const path = (id, what = "") => `/api/replays/${encodeURIComponent(id)}${what}`;

/** The position (s since the recording's start) of a replayed message: its recorded t_ns
 * against the nearest event at or before it (events carry t_s and t_ns), else the
 * session's last reported position. */
export function positionOf(m, events) {
  if (typeof m.position_s === "number") return m.position_s;
  let best = null;
  for (const e of events) if (typeof e.t_ns === "number" && e.t_ns <= m.t_ns) best = e; else if (best) break;
  if (best) return best.t_s + (m.t_ns - best.t_ns) / 1e9;
  return R.state ? R.state.position_s : null;
}

function show() {
  const s = R.state;
  $("lb-replay").textContent = !s ? "" :
    `session ${R.id}: ${s.position_s.toFixed(2)} / ${s.duration_s.toFixed(2)} s ×${s.speed}` +
    `${s.paused ? " paused" : ""}${s.finished ? " (end)" : ""}, ${R.messages} messages`;
}

async function refresh() {
  if (!R.id) return;
  try { R.state = await getJSON(path(R.id)); } catch (e) { if (e.status === 404) end(); }
  show();
}

/** Start a session of recording at start_s; onPosition(t_s) for every replayed message. */
export async function play(recording, start_s, speed, events, onPosition) {
  await stop();
  const doc = await control("/api/replays", { recording, speed, start_s }, "POST", out());
  if (!doc) return null;
  R.id = doc.id; R.state = doc; R.messages = 0; R.last = null;
  const proto = location.protocol === "https:" ? "wss" : "ws";
  const ws = (R.ws = new WebSocket(`${proto}://${location.host}${doc.ws}?max_hz=25`));
  ws.onmessage = (ev) => {
    const d = JSON.parse(ev.data);
    for (const m of Array.isArray(d) ? d : [d]) {
      if (m.type !== undefined || typeof m.t_ns !== "number") continue; // alarm / control messages
      R.messages++; R.last = m;
      const t = positionOf(m, events());
      if (t !== null) { R.position_s = t; onPosition(t); }
    }
  };
  ws.onclose = () => { if (R.ws === ws) R.ws = null; };
  poller = setInterval(refresh, 500);
  show();
  return doc;
}

const act = (what, body) => (R.id ? control(path(R.id, what), body, "POST", out()).then(refresh) : null);
export const pause = () => act("/pause");
export const resume = () => act("/resume");
export const step = () => act("/step", { n: 1 });

function end() {
  if (R.ws) { const ws = R.ws; R.ws = null; ws.close(); }
  clearInterval(poller);
  R.id = null; R.state = null;
  show();
}

/** End the session (DELETE) and close its websocket. */
export async function stop() {
  if (!R.id) return;
  const id = R.id;
  end();
  await control(path(id), undefined, "DELETE", out());
}

/** A session must not outlive the page: DELETE it on the way out (keepalive request). */
window.addEventListener("pagehide", () => {
  if (R.id) fetch(path(R.id), { method: "DELETE", headers: authHeader(), keepalive: true });
});
