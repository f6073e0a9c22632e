"""The dashboard names the signed-in actor, hides what the role cannot do, and marks an
instant with the Mark button and the "m" key (headless Chromium against a real uvicorn)."""

from __future__ import annotations

import json

from radar_io.service.auth import TokensFile
from radar_io.service.config import ServiceConfig

from .liveserver import browser, live_server  # noqa: F401 (fixture)


def _sign_in(chrome, token: str) -> None:
    chrome.eval(f"(() => {{ const t = document.getElementById('token'); t.value = {json.dumps(token)};"
                " t.dispatchEvent(new Event('change')); return true; })()")


def test_actor_role_hiding_and_marks(tmp_path, browser):  # noqa: F811
    tf = TokensFile(tmp_path / "tokens.json")
    viewer, op = tf.add("wall", "viewer"), tf.add("ops-lead", "operator")
    cfg = ServiceConfig(source="sim://", data_dir=str(tmp_path / "data"),
                        tokens_file=str(tf.path), auto_record="always")
    with live_server(cfg) as srv:
        srv.wait_connected()
        browser.navigate(srv.base + "/")
        browser.wait_for("window.radarReady && window.radarAccess", 20)
        browser.wait_for("document.getElementById('whoami').textContent === 'not signed in'", 10)
        _sign_in(browser, viewer)
        browser.wait_for("radarAccess.actor === 'wall'", 10)
        assert browser.eval("document.getElementById('whoami').textContent") == "wall (viewer)"
        hidden = browser.eval("['rec-start', 'mark', 'apply'].map(i => document.getElementById(i).hidden)")
        assert hidden == [True, True, True]
        _sign_in(browser, op)
        browser.wait_for("radarAccess.role === 'operator'", 10)
        shown = browser.eval("['rec-start', 'mark', 'apply', 'rw-go']"
                             ".map(i => document.getElementById(i).hidden)")
        assert shown == [False, False, True, True]  # calibration and runway: admin only
        browser.eval("document.getElementById('mark-kind').value = 'test_point_start';"
                     "document.getElementById('mark-label').value = 'TP7'; true")
        browser.eval("document.getElementById('mark').click(), true")
        browser.wait_for("radarAccess.marks.length === 1", 10)
        browser.eval("document.getElementById('mark-kind').value = 'marker';"
                     "document.getElementById('mark-label').value = ''; document.body.focus(); true")
        browser.eval("document.dispatchEvent(new KeyboardEvent('keydown', {key: 'm'})), true")
        browser.wait_for("radarAccess.marks.length === 2", 10)
        # a live strip chart draws the marks (its draw hook), both within its time range
        browser.wait_for("radarStrip.available.includes('sr_m')", 10)
        browser.eval("document.getElementById('strip-col').value = 'sr_m';"
                     "document.getElementById('strip-add').click(), true")
        browser.wait_for("radarStrip.charts.sr_m && radarStrip.charts.sr_m.radarMarks", 10)
        browser.wait_for("(u => radarAccess.marks.every(m => m.t_s >= u.scales.x.min && "
                         "m.t_s <= u.scales.x.max))(radarStrip.charts.sr_m)", 10)
        got = srv.get("/api/annotations")["annotations"]
        errors = browser.errors()
    assert [(a["kind"], a["label"], a["actor"]) for a in got] == [
        ("test_point_start", "TP7", "ops-lead"), ("marker", "", "ops-lead")]
    assert all(a["recording"] for a in got)  # auto_record = "always": a recording is open
    assert not errors, errors
