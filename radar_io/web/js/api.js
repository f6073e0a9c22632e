// HTTP helpers: one error formatter, JSON requests, control requests with the bearer token.
import { $ } from "./state.js";

// {loc: ["body", "xr_m", 0], msg} → "xr_m.0: msg"; {loc: [], msg} → "msg"
const item = (e) => {
  if (!e || e.msg === undefined) return JSON.stringify(e);
  const loc = (e.loc || []).filter((p, i) => !(i === 0 && ["body", "query", "path", "header"].includes(p)));
  return loc.length ? `${loc.join(".")}: ${e.msg}` : e.msg;
};

/** One line for a failed response: "<status>: <detail>" (FastAPI's detail may be a list). */
export function errorText(status, doc) {
  const d = doc && doc.detail !== undefined ? doc.detail : doc;
  let text;
  if (typeof d === "string") text = d;
  else if (Array.isArray(d)) text = d.map(item).join("; ");
  else text = JSON.stringify(d);
  return `${status}: ${text}`;
}

export class ApiError extends Error {
  constructor(status, doc) { super(errorText(status, doc)); this.status = status; this.doc = doc; }
}

/** fetch + JSON; throws ApiError (with the formatted message) when the status is not 2xx. */
export async function request(path, { method = "GET", body, headers = {}, raw = false, signal } = {}) {
  const init = { method, headers: { ...headers }, cache: "no-store", signal };
  if (body !== undefined) {
    if (raw) init.body = body;
    else { init.body = JSON.stringify(body); init.headers["Content-Type"] = "application/json"; }
  }
  const res = await fetch(path, init);
  const doc = await res.json().catch(() => ({}));
  if (!res.ok) throw new ApiError(res.status, doc);
  return doc;
}

export const getJSON = (path) => request(path);
export const postJSON = (path, body) => request(path, { method: "POST", body });

// ---------------------------------------------------------------- control token
const token = $("token");
token.value = localStorage.getItem("radar_io_token") || "";
token.onchange = () => localStorage.setItem("radar_io_token", token.value);

export const authHeader = () => ({ Authorization: `Bearer ${token.value}` });

const afterControl = [];
/** Run after every control request (status poll, recordings list refresh). */
export const onControl = (fn) => afterControl.push(fn);

/** A control request with the token; errors go to the message line out (default #msg).
 * Returns the document or null. */
export async function control(path, body, method = "POST", out = $("msg")) {
  let doc = null;
  try {
    doc = await request(path, { method, body, headers: authHeader() });
    out.textContent = "";
  } catch (e) {
    out.textContent = e.message;
  }
  for (const fn of afterControl) fn();
  return doc;
}

/** Runway frame → radar frame via POST /api/coordinates/runway-to-radar (arrays in metres). */
export const runwayToRadar = (xr_m, yr_m, hr_m) =>
  postJSON("/api/coordinates/runway-to-radar", { xr_m, yr_m, hr_m });
