// Shared dashboard state and tiny DOM helpers. window.radarState is the same object, for
// debugging and for the browser tests.

export const MAX_POINTS = 20000; // track points kept for the plan and profile views
export const STALE_S = 1.0;      // no message for this long → STALE banner

export const S = (window.radarState = {
  points: [],            // {x, y, h, g, sync, s}: rx-good positions in the radar frame (m)
  lastMsgSeq: null,      // resume point for ws ?from=
  instance: null,        // server instance: a change means the server restarted
  lastMsgAt: 0,          // performance.now() of the last message
  last: null,            // last measurement message
  status: null,
  site: null,
  path: null,            // reference path polyline in the radar frame {x_m, y_m, h_m}
  ref: null,             // runway reference course in the radar frame (from the API)
  air: [],               // air data samples (SI) with the radar ground range at arrival
  airSeq: 0,
  ws: null,
  connected: false,
  reconnects: 0,
  received: 0,
  stale: false,
  dirty: true,
});

export const $ = (id) => document.getElementById(id);

/** A number with d decimals, or an em dash for missing values. */
export const fmt = (v, d) =>
  v === null || v === undefined || Number.isNaN(v) ? "—" : Number(v).toFixed(d);

/** Listeners for every live measurement message (strip charts, …). */
export const onMessage = [];
