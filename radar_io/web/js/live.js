// Live data: the websocket stream (decimated, resumable with ?from=) and the status poll.
import { MAX_POINTS, S, onMessage } from "./state.js";
import { getJSON } from "./api.js";
import { setAlarms } from "./alarms.js";
import { loadReferenceCourse } from "./plan.js";

let backoff = 500;

export async function connect() {
  try {
    const st = await getJSON("/api/status");
    if (S.instance !== null && st.instance !== S.instance) S.lastMsgSeq = null; // new server run
    S.instance = st.instance;
  } catch (e) {
    return retry();
  }
  const proto = location.protocol === "https:" ? "wss" : "ws";
  let url = `${proto}://${location.host}/ws/live?max_hz=25`;
  if (S.lastMsgSeq !== null) url += `&from=${S.lastMsgSeq}`;
  const ws = new WebSocket(url);
  S.ws = ws;
  ws.onopen = () => { S.connected = true; backoff = 500; S.dirty = true; };
  ws.onmessage = (ev) => {
    const m = JSON.parse(ev.data);
    if (m.type === "alarm") { setAlarms(m.alarms); return; }
    if (S.lastMsgSeq !== null && m.msg_seq <= S.lastMsgSeq) return; // duplicate after resume
    S.lastMsgSeq = m.msg_seq;
    S.lastMsgAt = performance.now();
    S.received++;
    S.last = m;
    if (m.rx_good && m.x_m !== null) {
      S.points.push({ x: m.x_m, y: m.y_m, h: m.h_m, g: Math.hypot(m.x_m, m.y_m), sync: m.sync, s: m.msg_seq });
      if (S.points.length > MAX_POINTS) S.points.splice(0, S.points.length - MAX_POINTS);
    }
    for (const fn of onMessage) fn(m);
    S.dirty = true;
  };
  ws.onclose = () => {
    if (S.ws === ws) { S.connected = false; S.dirty = true; S.reconnects++; retry(); }
  };
  ws.onerror = () => ws.close();
}

function retry() {
  setTimeout(connect, backoff);
  backoff = Math.min(backoff * 2, 5000);
}

/** Status, site, reference path and air data; every 0.5 s. */
export async function poll() {
  try {
    const st = await getJSON("/api/status");
    S.status = st;
    if (S.instance !== null && st.instance !== S.instance && S.ws) S.ws.close(); // restarted
    if (!S.site && st.site) {
      S.site = await getJSON("/api/site");
      S.ref = await loadReferenceCourse();
    }
    if (!S.path && st.path) S.path = await getJSON("/api/path");
    if (st.airdata) {
      const doc = await getJSON(`/api/airdata?since=${S.airSeq}`);
      for (const a of doc.samples) { S.air.push(a); S.airSeq = a.air_seq; }
      if (S.air.length > 8 * 600) S.air.splice(0, S.air.length - 8 * 600);
    }
  } catch (e) {
    S.status = null;
  }
  S.dirty = true;
}
