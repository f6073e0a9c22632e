"""The look-back view in real headless Chromium against the real service (series index,
events, replay sessions), while the service's simulator keeps the live flight going: whole-
recording charts with min / max bands, drag to zoom, double-click back, one cursor for the
charts, plan and profile, markers, the view in the URL, replay through a session, the live
strip, and "Live"."""

from __future__ import annotations

import bisect
import json
import urllib.parse
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from radar_io.benchmarks.outputs import make_recording

from .cdp import Chrome
from .liveserver import TOKEN, LiveServer, browser, live_server, service_config  # noqa: F401
from .test_live_pty import ARTIFACTS, wait_for

REC = "20261125T120000Z"


@pytest.fixture
def lookback_server(tmp_path: Path) -> Iterator[LiveServer]:
    """The service on its simulator, with a 2-min 1-kHz recording in its data directory."""
    cfg = service_config(tmp_path / "svc")
    rec_dir = Path(cfg.data_dir) / "recordings"
    rec_dir.mkdir(parents=True)
    make_recording(rec_dir / f"{REC}.rdrlog", 120 / 3600)
    with live_server(cfg) as srv:
        srv.wait_connected()
        yield srv


def over_box(chrome: Chrome, column: str) -> tuple[float, float, float, float]:
    """CSS box (left, top, width, height) of a look-back chart's plot area."""
    return tuple(chrome.eval(f"(() => {{ const b = radarLookback.charts['{column}'].u.over"
                             ".getBoundingClientRect(); return [b.left, b.top, b.width, b.height]; })()"))


def frames_shown(chrome: Chrome) -> int:
    """The live strip's frame counter."""
    text = chrome.eval("document.getElementById('ls-frames').textContent")
    return int(text.split()[0]) if text.split()[0].isdigit() else -1


def shown_text(v: float | None) -> str:
    return "—" if v is None else f"{v:.1f}" if abs(v) >= 1000 else f"{v:.4f}"


def shown(doc: dict[str, Any]) -> dict[str, Any]:
    """What the page draws of a series answer: every frame, or the buckets that hold frames
    (``seq`` is never null in a frame, so a null ``seq`` is an empty bucket)."""
    if not doc["decimated"]:
        return doc
    keep = [i for i, v in enumerate(doc["columns"]["seq"]["min"]) if v is not None]
    return {**doc, "t_s": [doc["t_s"][i] for i in keep],
            "columns": {c: {k: [v[k][i] for i in keep] for k in ("min", "max")}
                        for c, v in doc["columns"].items()}}


def check_answer(chrome: Chrome, srv: LiveServer) -> dict[str, Any]:
    """The page's last series answer is the service's for the same query, it asked for no
    more buckets than the charts have pixels, and its charts hold exactly the bands of the
    buckets that have frames. Returns the answer."""
    url = chrome.eval("radarLookback.url")
    doc = srv.get(url)
    assert chrome.eval("radarLookback.doc") == doc
    points = int(urllib.parse.parse_qs(urllib.parse.urlparse(url).query)["points"][0])
    assert len(doc["t_s"]) <= points
    drawn = shown(doc)
    for col in chrome.eval("radarLookback.columns"):
        width, data = chrome.eval(f"(c => [c.plotWidth, c.u.data])(radarLookback.charts['{col}'])")
        assert points <= width
        assert data == [drawn["t_s"], drawn["columns"][col]["min"], drawn["columns"][col]["max"]]
    return doc


def test_lookback_zoom_cursor_url_replay_and_live(lookback_server, browser, tmp_path):  # noqa: F811
    srv, chrome = lookback_server, browser
    chrome.watch_console()
    chrome.navigate(f"{srv.base}/?recording={REC}&columns=sr_m,h_m")
    chrome.wait_for("radarLookback.loads >= 1 && radarLookback.events.length > 0", 60)
    assert chrome.eval("document.getElementById('live-view').hidden")
    assert not chrome.eval("document.getElementById('lookback').hidden")

    # the whole recording, decimated: bands (some bucket's min < max), markers from /events
    whole = check_answer(chrome, srv)
    assert whole["decimated"] and whole["start_s"] == 0 and 119 < whole["end_s"] < 121
    sr = whole["columns"]["sr_m"]
    assert any(lo is not None and lo < hi for lo, hi in zip(sr["min"], sr["max"], strict=True))
    events = srv.get(f"/api/recordings/{REC}/events")["events"]
    assert {(e["kind"], e.get("edge")) for e in events} >= {("go", "rise"), ("sync", None)}
    assert chrome.eval("radarLookback.events.length") == len([e for e in events if e["t_s"] is not None])
    chrome.wait_for("radarLookback.track.filter(p => p).length > 100", 5)  # plan / profile points

    # drag over 25 % … 50 % of the sr_m chart: the range is asked for again, the URL says so
    x, y, w, h = over_box(chrome, "sr_m")
    frames0 = frames_shown(chrome)
    chrome.drag(x + 0.25 * w, y + h / 2, x + 0.5 * w, y + h / 2)
    chrome.wait_for("radarLookback.loads >= 2", 20)
    zoomed = check_answer(chrome, srv)
    span = whole["end_s"] - whole["start_s"]
    assert abs(zoomed["start_s"] - 0.25 * span) < 0.01 * span
    assert abs(zoomed["end_s"] - 0.5 * span) < 0.01 * span
    q = urllib.parse.parse_qs(urllib.parse.urlparse(chrome.eval("location.href")).query)
    assert q["recording"] == [REC] and q["columns"] == ["sr_m,h_m"]
    assert abs(float(q["start_s"][0]) - zoomed["start_s"]) < 1e-5
    link = chrome.eval("location.href")

    # the cursor: hovering the h_m chart moves the line on every chart and shows the
    # values of the bucket under it (sr_m and h_m, and x/y/h for the plan and profile)
    x, y, w, h = over_box(chrome, "h_m")
    chrome.mouse("mouseMoved", x + 0.6 * w, y + h / 2)
    chrome.wait_for("radarLookback.cursor_s !== null", 5)
    t = chrome.eval("radarLookback.cursor_s")
    assert zoomed["start_s"] + 0.55 * (zoomed["end_s"] - zoomed["start_s"]) < t
    drawn = shown(zoomed)
    i = bisect.bisect_right(drawn["t_s"], t) - 1
    chrome.wait_for("[...document.querySelectorAll('.lb-cursor')].every(e => !e.hidden)", 5)
    for col in ("sr_m", "h_m"):
        c = drawn["columns"][col]
        want = shown_text(c["min"][i]) if c["min"][i] == c["max"][i] else \
            f"{shown_text(c['min'][i])} … {shown_text(c['max'][i])}"
        chrome.wait_for(f"radarLookback.charts['{col}'].value.textContent === {json.dumps(want)}", 5)
    values = dict(chrome.eval("[...document.querySelectorAll('#lb-values tr')]"
                              ".map(r => [r.cells[0].textContent, r.cells[1].textContent])"))
    assert set(values) == {"sr_m", "h_m", "x_m", "y_m"} and values["x_m"] != "—"
    chrome.screenshot(ARTIFACTS / "dashboard-lookback.png")

    # double-click: the whole recording again, the URL without a range
    chrome.double_click(x + 0.3 * w, y + h / 2)
    chrome.wait_for("radarLookback.loads >= 3", 20)
    assert check_answer(chrome, srv)["t_s"] == whole["t_s"]
    assert "start_s" not in chrome.eval("location.search")

    # the link reopens the same view in a fresh page; the back button the previous ones
    chrome.navigate(link)
    chrome.wait_for("radarLookback.loads >= 1", 20)
    again = check_answer(chrome, srv)
    assert (again["start_s"], again["end_s"]) == (zoomed["start_s"], zoomed["end_s"])
    assert chrome.eval("radarLookback.columns") == ["sr_m", "h_m"]

    # the live strip stayed current the whole time
    chrome.wait_for(f"parseInt(document.getElementById('ls-frames').textContent) > {frames0}", 5)
    assert chrome.eval("document.getElementById('ls-go').classList.contains('ok')")

    # replay from the cursor in a replay session: its websocket moves the cursor forward
    start = zoomed["start_s"] + 1.0
    chrome.eval(f"import('/static/js/lookback.js').then(m => m.setCursor({start})), "
                f"document.getElementById('token').value = '{TOKEN}', "
                "document.getElementById('lb-speed').value = '2', "
                "document.getElementById('lb-play').click(), true")
    chrome.wait_for("radarReplay.messages > 20", 20)
    (session,) = srv.get("/api/replays")
    assert session["recording"] == REC and session["id"] == chrome.eval("radarReplay.id")
    chrome.wait_for(f"radarLookback.cursor_s > {start + 1.0}", 10)
    # the cursor follows the recorded time: within a second of the session's own position
    st = srv.get(f"/api/replays/{session['id']}")
    assert abs(chrome.eval("radarReplay.position_s") - st["position_s"]) < 1.5
    chrome.eval("document.getElementById('lb-pause').click(), true")
    chrome.wait_for("radarReplay.state && radarReplay.state.paused", 5)
    chrome.screenshot(ARTIFACTS / "dashboard-lookback-replay.png")

    # "Live": the live view again, the session ended, the URL without a recording
    chrome.eval("document.getElementById('to-live').click(), true")
    chrome.wait_for("!document.getElementById('live-view').hidden && location.search === ''", 5)
    chrome.wait_for("radarState.points.length > 10", 10)
    wait_for(lambda: srv.get("/api/replays") == [], 5, "the session to end")
    chrome.eval("1")
    assert chrome.errors() == []
