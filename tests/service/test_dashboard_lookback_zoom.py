"""Figure (issue 19): a 1-h recording (3.6 M frames at 1 kHz) in the look-back view of
headless Chromium on the real service, while the service's simulator keeps the live flight
going: from the whole hour down to 100 ms in 5 steps, a screenshot of each
(``artifacts/dashboard-zoom-<k>.png``) and the time from the request to the charts drawn,
measured in the page with performance.now() (``artifacts/dashboard-zoom.json``); the live
strip's frame counter grows between the steps.

    PYTHONPATH=. python -m pytest -q -s -m slow tests/service/test_dashboard_lookback_zoom.py
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import pytest

from radar_io.benchmarks.outputs import make_recording

from .liveserver import browser, live_server, service_config  # noqa: F401
from .test_dashboard_lookback import check_answer, frames_shown
from .test_live_pty import ARTIFACTS

pytestmark = pytest.mark.slow

REC = "20261125T100000Z"
STEPS = 5
LAST_SPAN_S = 0.1


def test_zoom_whole_hour_to_100_ms_while_live(tmp_path: Path, browser):  # noqa: F811
    cfg = service_config(tmp_path / "svc")
    rec_dir = Path(cfg.data_dir) / "recordings"
    rec_dir.mkdir(parents=True)
    simulate_s = make_recording(rec_dir / f"{REC}.rdrlog", 1.0)
    chrome = browser
    with live_server(cfg) as srv:
        srv.wait_connected()
        chrome.watch_console()
        chrome.navigate(f"{srv.base}/?recording={REC}&columns=sr_m,el_deg,h_m")
        # the first query builds the recording's look-back index
        chrome.wait_for("radarLookback.loads >= 1 && radarLookback.events.length > 0", 180)
        first = chrome.eval("radarLookback.timings[0]")
        whole = check_answer(chrome, srv)
        assert whole["decimated"] and 3599 < whole["end_s"] < 3601
        # the centre: 20 ms after a SYNC edge near the middle, so that every view has markers
        sync = next(e["t_s"] for e in chrome.eval("radarLookback.events")
                    if e["kind"] == "sync" and e["t_s"] >= 1800)
        centre = sync + 0.02
        spans = [whole["end_s"] - whole["start_s"]]
        spans += [spans[0] * (LAST_SPAN_S / spans[0]) ** (k / STEPS) for k in range(1, STEPS + 1)]
        rows = []
        for k, span in enumerate(spans):
            frames = frames_shown(chrome)
            a, b = (whole["start_s"], whole["end_s"]) if k == 0 else (centre - span / 2, centre + span / 2)
            loads = chrome.eval("radarLookback.loads")
            chrome.eval(f"import('/static/js/lookback.js').then(m => m.zoom({a}, {b})), true")
            chrome.wait_for(f"radarLookback.loads > {loads}", 60)
            chrome.eval(f"import('/static/js/lookback.js').then(m => m.setCursor({centre})), true")
            chrome.wait_for("document.getElementById('lb-cursor').textContent !== ''", 5)
            doc = check_answer(chrome, srv)  # ≤ pixels buckets, the charts hold the answer
            timing = chrome.eval("radarLookback.timings.at(-1)")
            assert doc["decimated"] == (doc["frames"] > timing["points"])
            time.sleep(0.3)  # the cursor line and values are drawn in the next animation frame
            chrome.screenshot(ARTIFACTS / f"dashboard-zoom-{k}.png")
            # the live flight went on meanwhile: the live strip's counter keeps growing
            chrome.wait_for(f"parseInt(document.getElementById('ls-frames').textContent) > {frames}", 5)
            rows.append({"step": k, "span_s": doc["end_s"] - doc["start_s"], "frames": doc["frames"],
                         "values_per_column": len(doc["t_s"]), "decimated": doc["decimated"],
                         "points": timing["points"], "fetch_ms": round(timing["fetch_ms"], 1),
                         "draw_ms": round(timing["draw_ms"], 1), "total_ms": round(timing["total_ms"], 1),
                         "live_frames": frames_shown(chrome)})
        assert rows[-1]["span_s"] == pytest.approx(LAST_SPAN_S, rel=1e-3) and not rows[-1]["decimated"]
        chrome.eval("1")
        assert chrome.errors() == []
    out = {"recording_frames": whole["frames"], "simulate_s": round(simulate_s, 1),
           "first_query_ms": round(first["total_ms"], 1), "steps": rows}
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    (ARTIFACTS / "dashboard-zoom.json").write_text(json.dumps(out, indent=1) + "\n")
    print(f"\n1-h recording ({whole['frames']} frames, simulated in {simulate_s:.0f} s); "
          f"first open (index build + draw): {first['total_ms']:.0f} ms")
    for r in rows:
        print(f"step {r['step']}: span {r['span_s']:10.4f} s  {r['frames']:8d} frames  "
              f"{r['values_per_column']:4d} values/column  request→drawn {r['total_ms']:6.1f} ms "
              f"(fetch {r['fetch_ms']:.1f}, draw {r['draw_ms']:.1f})  live frames {r['live_frames']}")
