// Lamps, numeric readouts, servo-error bars, air data, header tags and counters.
import { $, S, fmt } from "./state.js";

function setBar(id, v, fullScale) {
  const el = $("b-" + id), val = $("v-" + id);
  if (v === null || v === undefined) { el.style.width = "0"; val.textContent = "—"; return; }
  const f = Math.max(-1, Math.min(1, v / fullScale));
  el.style.left = f >= 0 ? "50%" : `${50 + f * 50}%`;
  el.style.width = `${Math.abs(f) * 50}%`;
  el.classList.toggle("sat", Math.abs(v) >= 0.98 * fullScale);
  val.textContent = fmt(v, id === "dsr" ? 2 : 4);
}

/** Value and "± σ" of a tracking-filter field (— without a track). */
function setKin(id, v, sigma, digits) {
  $("k-" + id).textContent = fmt(v, digits);
  $("k-" + id + "-s").textContent = v === null || v === undefined || sigma === null || sigma === undefined
    ? "" : "± " + fmt(sigma, digits);
}

/** The tracking filter's ground speed, vertical speed, flight-path angle, track and (with a
 * reference path) glide-path angle error, each ± 1σ. */
function renderKinematics(m) {
  setKin("gs", m.gs_mps, m.gs_sigma_mps, 1);
  setKin("vs", m.vs_mps, m.vs_sigma_mps, 1);
  setKin("fpa", m.fpa_deg, m.fpa_sigma_deg, 2);
  setKin("trk", m.track_deg, m.track_sigma_deg, 1);
  $("k-gpa-row").hidden = m.gpa_err_deg === undefined;
  setKin("gpa", m.gpa_err_deg, m.gpa_err_sigma_deg, 2);
}

/** The last message's lamps and values (corrected SR'/EL'/AZ' when RX GOOD). */
export function renderMessage(m, stale) {
  for (const k of ["go", "rx_good", "sync", "auto"]) $("lamp-" + k).classList.toggle("on", !!(m && m[k]) && !stale);
  if (!m) return;
  const good = m.rx_good;
  $("r-sr").textContent = fmt(good ? m.sr_c_m : m.sr_m, 1);
  $("r-el").textContent = fmt(good ? m.el_c_deg : m.el_deg, 4);
  $("r-az").textContent = fmt(good ? m.az_c_deg : m.az_deg, 4);
  $("r-x").textContent = fmt(m.x_m, 1); $("r-y").textContent = fmt(m.y_m, 1); $("r-h").textContent = fmt(m.h_m, 1);
  $("r-tod").textContent = fmt(m.tod_s, 3); $("r-seq").textContent = m.seq;
  setBar("dsr", m.dsr_m, 50); setBar("del", m.del_deg, 1); setBar("daz", m.daz_deg, 1);
  $("r-dy").textContent = fmt(m.dy_m, 1); $("r-dz").textContent = fmt(m.dz_m, 1);
  $("r-along").textContent = fmt(m.along_m, 0); $("r-leg").textContent = m.leg === undefined ? "—" : m.leg;
  renderKinematics(m);
}

/** The latest CAN air-data sample. */
export function renderAir(st) {
  $("air").hidden = !(st && st.airdata);
  const a = S.air.length ? S.air[S.air.length - 1] : null;
  if (!a) return;
  $("a-ias").textContent = fmt(a.ias_mps, 1) + " m/s"; $("a-alt").textContent = fmt(a.pressure_altitude_m, 1) + " m";
  $("a-pitch").textContent = fmt(a.pitch_deg, 2) + "°"; $("a-roll").textContent = fmt(a.roll_deg, 2) + "°";
  $("a-hdg").textContent = fmt(a.heading_deg, 1) + "°"; $("a-shut").textContent = a.shutter_count ?? "—";
  $("a-dme1").textContent = fmt(a.dme1_m, 0) + " m"; $("a-dme2").textContent = fmt(a.dme2_m, 0) + " m";
  $("air-age").textContent = st && st.airdata && st.airdata.last_sample_age_s !== null ? `${st.airdata.last_sample_age_s.toFixed(1)} s ago` : "";
}

/** The live strip (header: GO, REC, source, rate, frames, alarms; shown in every view) and
 * the counters table, from /api/status. */
export function renderStatus(st) {
  $("link").textContent = S.connected ? "ONLINE" : "OFFLINE";
  $("link").className = "tag " + (S.connected ? "ok" : "bad");
  $("c-points").textContent = S.points.length;
  if (!st) return;
  $("mode").textContent = st.mode.toUpperCase();
  $("source").textContent = st.source + (st.connected ? "" : ` (disconnected: ${st.last_error || "…"})`);
  $("calib").textContent = `cal: ${st.calibration}`;
  $("cal-active").textContent = st.calibration;
  $("rec").className = "tag " + (st.recording ? "on" : "off");
  $("rec").title = st.recording || "not recording";
  $("c-rate").textContent = fmt(st.rate_hz, 0) + " Hz"; $("c-frames").textContent = st.frames;
  $("c-crc").textContent = st.crc_errors; $("c-impl").textContent = st.implausible;
  $("c-disc").textContent = st.bytes_discarded; $("c-gaps").textContent = st.seq_gaps;
  $("c-ws").textContent = st.ws_clients; $("c-drop").textContent = st.ws_dropped;
  $("c-reconn").textContent = st.reconnects;
  $("ls-go").className = "tag " + (st.go && st.connected ? "ok" : "off");
  $("ls-rate").textContent = fmt(st.rate_hz, 0) + " Hz";
  $("ls-frames").textContent = `${st.frames} frames`;
}
