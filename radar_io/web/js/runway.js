// Runway vision panel: upload an image or a video for the automatic pose, or pick points on
// the image for the manual pose (runway-vision.md). window.runwayState for the tests.
import { $ } from "./state.js";
import { authHeader, request } from "./api.js";

const RW = (window.runwayState = { img: null, width: 0, height: 0, points: { horizon: [], left_edge: [], right_edge: [] }, lines: null, result: null, lastManual: null });
const RW_COLORS = { horizon: "#50dc50", left_edge: "#e63c3c", right_edge: "#2878e6" };

/** Picked points and the principal point are in pixel coordinates: u right, v down, 0 at
 * the centre of the first pixel (OpenCV's and the Python pipeline's convention).
 * The image centre in those coordinates:
 * ((W − 1) / 2, (H − 1) / 2), the default the Python pipeline uses. */
export const principalPoint = (w, h) => [(w - 1) / 2, (h - 1) / 2];

function rwDraw() {
  const cv = $("rw-canvas"), g = cv.getContext("2d");
  if (!RW.img) return;
  cv.width = RW.width; cv.height = RW.height;
  g.drawImage(RW.img, 0, 0);
  for (const [k, pts] of Object.entries(RW.points)) {
    g.fillStyle = RW_COLORS[k];
    for (const [u, v] of pts) { g.beginPath(); g.arc(u + 0.5, v + 0.5, 4, 0, 2 * Math.PI); g.fill(); }
  }
}

function rwShow(doc) {
  RW.result = doc;
  const f = (v, d, u) => (v === null || v === undefined ? "—" : `${Number(v).toFixed(d)}${u}`);
  $("rw-result").textContent = doc.found
    ? `bank ${f(doc.bank_deg, 2, "°")}  pitch ${f(doc.pitch_deg, 2, "°")}  yaw ${f(doc.yaw_deg, 2, "°")}  height ${f(doc.height_m, 1, " m")}  lateral ${f(doc.lateral_m, 1, " m")}  quality ${f(doc.quality, 2, "")}`
    : `no runway found: ${doc.reason || "?"}`;
}

function rwLoadImage(src, w, h) {
  return new Promise((resolve) => {
    const im = new Image();
    im.onload = () => { RW.img = im; RW.width = w || im.naturalWidth; RW.height = h || im.naturalHeight; rwDraw(); resolve(); };
    im.src = src;
  });
}

async function estimate() {
  const file = $("rw-file").files[0];
  if (!file) { $("rw-result").textContent = "choose an image or a video first"; return; }
  $("rw-result").textContent = "…";
  const q = `focal_px=${$("rw-f").value}&half_width_m=${$("rw-d").value}`;
  let doc;
  try {
    doc = await request(`/api/runway?${q}`, { method: "POST", body: file, raw: true, headers: { "Content-Type": file.type || "application/octet-stream", ...authHeader() } });
    if (doc.job && doc.status_url) { // a video: a job on the server (202), polled until it ends
      for (;;) {
        await new Promise((ok) => setTimeout(ok, 500));
        const job = await request(doc.status_url);
        $("rw-result").textContent = `${job.state}: ${job.frames_done} / ${job.frames_total ?? "?"} frames`;
        if (job.state === "done") { doc = job.result; break; }
        if (job.state === "failed" || job.state === "cancelled") { $("rw-result").textContent = `${job.state}: ${job.error || ""}`; return; }
      }
    }
  } catch (e) { $("rw-result").textContent = e.message; return; }
  if (doc.frames) { RW.result = doc; $("rw-result").textContent = doc.frames.map((r) => `#${r.frame} ` + (r.found ? `bank ${r.bank_deg} pitch ${r.pitch_deg} yaw ${r.yaw_deg} h ${r.height_m} lat ${r.lateral_m} q ${r.quality}` : `not found: ${r.reason}`)).join("\n"); return; }
  if (doc.overlay_png_base64) await rwLoadImage("data:image/png;base64," + doc.overlay_png_base64, doc.image.width, doc.image.height);
  rwShow(doc);
}

async function manual() {
  if (!RW.img) { $("rw-result").textContent = "load an image first"; return; }
  const body = { points: RW.points, focal_px: Number($("rw-f").value), half_width_m: Number($("rw-d").value), principal_point: principalPoint(RW.width, RW.height) };
  RW.lastManual = body;
  try { rwShow(await request("/api/runway/manual", { method: "POST", body, headers: authHeader() })); } catch (e) { $("rw-result").textContent = e.message; }
}

export function initRunway() {
  $("rw-file").onchange = async () => {
    const file = $("rw-file").files[0];
    if (file && file.type.startsWith("image/")) {
      RW.points = { horizon: [], left_edge: [], right_edge: [] };
      await rwLoadImage(URL.createObjectURL(file));
    }
  };
  $("rw-go").onclick = estimate;
  $("rw-canvas").onclick = (ev) => {
    if (!RW.img) return;
    const cv = $("rw-canvas"), r = cv.getBoundingClientRect();
    // position in the canvas's content box (inside its border; 0 at the image's left edge)
    // → pixel coordinates (0 at the first pixel's centre)
    const x = ev.clientX - r.left - cv.clientLeft, y = ev.clientY - r.top - cv.clientTop;
    const u = (x * cv.width) / cv.clientWidth - 0.5, v = (y * cv.height) / cv.clientHeight - 0.5;
    RW.points[$("rw-line").value].push([u, v]);
    rwDraw();
  };
  $("rw-clear").onclick = () => { RW.points = { horizon: [], left_edge: [], right_edge: [] }; rwDraw(); };
  $("rw-manual").onclick = manual;
}
