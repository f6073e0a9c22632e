"""Figures for docs/dashboard.md (not a test): dashboard load in headless Chromium, strip
chart redraw cost, and POST /api/coordinates/runway-to-radar at its largest body.

    PYTHONPATH=. python -m tests.service.measure_dashboard
"""

from __future__ import annotations

import json
import statistics
import tempfile
import time
from pathlib import Path

from .liveserver import chrome_browser, live_server, service_config


def main() -> None:
    tmp = Path(tempfile.mkdtemp(prefix="measure-dashboard-"))
    with live_server(service_config(tmp / "svc")) as srv, chrome_browser(tmp / "chrome") as ch:
        loads = []
        for _ in range(5):
            ch.navigate(srv.base + "/")
            loads.append(ch.eval("radarReadyAt"))
        res = ch.eval("""performance.getEntriesByType('resource').filter(e => e.name.includes('/static/'))
            .map(e => [e.name.split('/static/')[1], e.encodedBodySize])""")
        ch.wait_for("radarStrip.messages.length > 50", 15)
        per_draw = ch.eval("""(async () => {
            const m = radarStrip.messages; while (m.length < 3000) m.push(...m.slice(0, 3000 - m.length));
            const s = await import('/static/js/stripchart.js');
            for (const c of ['sr_m', 'el_deg', 'az_deg']) s.addColumn(c);
            const t0 = performance.now(), n = 40;
            for (let i = 0; i < n; i++) {  // uPlot draws in a microtask after setData: await it
              for (const c of radarStrip.columns) radarStrip.charts[c].setData(s.seriesOf(c));
              await Promise.resolve();
            }
            for (const c of [...radarStrip.columns]) s.removeColumn(c);
            return (performance.now() - t0) / n; })()""")
        body = json.dumps({"xr_m": [float(i) for i in range(10_000)], "yr_m": [1.0] * 10_000,
                           "hr_m": [2.0] * 10_000}).encode()
        import urllib.request

        times = []
        for _ in range(5):
            req = urllib.request.Request(srv.base + "/api/coordinates/runway-to-radar", data=body,
                                         headers={"Content-Type": "application/json"})
            t0 = time.perf_counter()
            with urllib.request.urlopen(req, timeout=60) as r:
                r.read()
            times.append(time.perf_counter() - t0)
    raise_to_screen = alarm_latency(tmp)
    print(f"page ready (navigation → main.js done), median of 5: {statistics.median(loads):.0f} ms")
    js = [(n, b) for n, b in res if n.startswith("js/")]
    vendor = [(n, b) for n, b in res if n.startswith("vendor/")]
    print(f"modules: {len(js)} files, {sum(b for _, b in js) / 1024:.1f} KiB; vendored: "
          f"{', '.join(f'{n} {b / 1024:.1f} KiB' for n, b in vendor)}")
    print(f"strip charts: 3 charts × 3000 points redrawn in {per_draw:.1f} ms")
    print(f"runway-to-radar, 10000 points (JSON both ways), median of 5: "
          f"{statistics.median(times) * 1000:.0f} ms")

    if raise_to_screen is not None:
        print(f"alarm raised (engine's since) → banner shown, 5 alarms: "
              f"median {statistics.median(raise_to_screen):.0f} ms, max {max(raise_to_screen):.0f} ms")


def alarm_latency(tmp: Path) -> list[float] | None:
    """Raise → banner on screen [ms] for limit alarms on the simulator's SR (needs the alarm
    engine; None without it). Each alarm is raised 3 s after its service starts, so the
    page is loaded and watching the banner (MutationObserver) before it happens."""
    import dataclasses

    from radar_io.service.config import ServiceConfig

    if "alarms" not in {f.name for f in dataclasses.fields(ServiceConfig)}:
        return None
    out = []
    with chrome_browser(tmp / "chrome-alarm") as ch:
        for k in range(5):
            cfg = service_config(tmp / f"alarm{k}", alarms=[
                {"column": "sr_m", "max": 1000.0, "for_s": 3.0, "name": "SR limit"}])
            with live_server(cfg) as srv:
                ch.navigate(srv.base + "/")
                ch.eval("""window.shownAt = null; new MutationObserver(() => {
                    if (!window.shownAt && !document.getElementById('alarms').hidden)
                        window.shownAt = performance.timeOrigin + performance.now(); })
                    .observe(document.getElementById('alarms'), {attributes: true}), true""")
                ch.wait_for("window.shownAt !== null", 15)
                since = srv.get("/api/alarms")["alarms"][0]["since"]
                out.append(ch.eval("window.shownAt") - since * 1000)
    return out


if __name__ == "__main__":
    main()
