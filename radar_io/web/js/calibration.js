// Calibration panel: photo positions at sync events → proposed ΔSR/ΔEL/ΔAZ, then apply.
import { $ } from "./state.js";
import { control } from "./api.js";

let proposed = null;

/** A CSV table (header line, comma-separated) → observation objects for /api/calibration/bias. */
export function parseObservations(text) {
  const lines = text.trim().split(/\r?\n/).filter((l) => l.trim());
  const head = lines.shift().split(",").map((h) => h.trim());
  return lines.map((l, n) => {
    const v = l.split(","), o = {};
    if (v.length !== head.length) throw new Error(`line ${n + 2}: ${v.length} fields, the header has ${head.length}`);
    head.forEach((h, i) => { o[h] = ["group", "recording"].includes(h) ? v[i].trim() : Number(v[i]); });
    return o;
  });
}

export function initCalibration() {
  $("estimate").onclick = async () => {
    let observations;
    try { observations = parseObservations($("obs").value); } catch (e) { $("cal-result").textContent = "cannot read the table: " + e.message; return; }
    const doc = await control("/api/calibration/bias", { id: $("cal-id").value || "photo", observations });
    if (!doc || !doc.statistics) { $("cal-result").textContent = $("msg").textContent; $("apply").disabled = true; return; }
    proposed = doc.calibration;
    const f = (s) => `${s.mean.toFixed(4)} ± ${s.std.toFixed(4)}`, lines = [];
    for (const [g, s] of [...Object.entries(doc.statistics.groups), ["combined", doc.statistics.combined]])
      lines.push(`${g.padEnd(10)} n=${String(s.n).padEnd(3)} ΔSR ${f(s.dsr_m)} m  ΔEL ${f(s.del_deg)}°  ΔAZ ${f(s.daz_deg)}°`);
    $("cal-result").textContent = lines.join("\n");
    $("apply").disabled = false;
  };
  $("apply").onclick = async () => {
    if (!proposed) return;
    await control("/api/calibration", proposed, "PUT");
    $("apply").disabled = true;
  };
}
