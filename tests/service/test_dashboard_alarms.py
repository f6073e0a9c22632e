"""Alarm banner and report link in headless Chromium.

The alarm engine belongs to another branch; here a small peer implements its HTTP contract
(GET /api/alarms → list of {id, name, column, value, limit, since, acknowledged};
POST /api/alarms/{id}/ack with the control token) and the websocket message
{"type": "alarm", "alarms": [...]}, so the dashboard side is tested against real HTTP and a
real websocket."""

from __future__ import annotations

import json
import time
import urllib.request
from typing import Any

from fastapi import APIRouter, Header, HTTPException

from .liveserver import TOKEN, browser, live_server, service_config, sim_server  # noqa: F401
from .test_live_pty import ARTIFACTS


class AlarmPeer:
    """The alarm endpoints' contract, with alarms raised and cleared by the test."""

    def __init__(self) -> None:
        self.alarms: dict[str, dict[str, Any]] = {}
        self.acks: list[str] = []
        self.router = APIRouter()

        @self.router.get("/api/alarms", operation_id="peer_alarms")
        def alarms() -> list[dict[str, Any]]:
            return list(self.alarms.values())

        @self.router.post("/api/alarms/{alarm_id}/ack", operation_id="peer_alarm_ack")
        def ack(alarm_id: str, authorization: str | None = Header(None)) -> dict[str, Any]:
            if authorization != f"Bearer {TOKEN}":
                raise HTTPException(403, "wrong token")
            if alarm_id not in self.alarms:
                raise HTTPException(404, f"no active alarm {alarm_id!r}")
            self.acks.append(alarm_id)
            self.alarms[alarm_id]["acknowledged"] = True
            return self.alarms[alarm_id]

    def raise_(self, alarm_id: str, **kw: Any) -> None:
        self.alarms[alarm_id] = {"id": alarm_id, "acknowledged": False, "since": time.time(), **kw}


BANNER = "document.getElementById('alarms')"


def test_banner_shows_acknowledges_and_clears(tmp_path, browser):  # noqa: F811
    peer = AlarmPeer()
    with live_server(service_config(tmp_path / "svc"), routers=(peer.router,)) as srv:
        browser.navigate(srv.base + "/")
        browser.wait_for("radarAlarms.endpoint === true", 10)
        assert browser.eval(f"{BANNER}.hidden")

        peer.raise_("sr-max", name="SR above limit", column="sr_m", value=15210.5, limit=15000.0)
        browser.wait_for(f"!{BANNER}.hidden", 5)
        text = browser.eval(f"{BANNER}.textContent")
        assert "SR above limit" in text and "sr_m = 15210.5" in text and "limit 15000.0" in text
        browser.screenshot(ARTIFACTS / "dashboard-alarm.png")

        # a wrong token: refused, the banner stays
        browser.eval("document.getElementById('token').value = 'nope', true")
        browser.eval(f"{BANNER}.querySelector('button').click(), true")
        browser.wait_for("document.getElementById('msg').textContent === '403: wrong token'", 5)
        browser.wait_for(f"{BANNER}.textContent.includes('acknowledge failed: 403: wrong token')", 5)
        assert peer.acks == [] and not browser.eval(f"{BANNER}.hidden")

        # the control token: acknowledged, the banner goes, the header keeps a quiet note
        browser.eval(f"document.getElementById('token').value = {json.dumps(TOKEN)}, true")
        browser.eval(f"{BANNER}.querySelector('button').click(), true")
        browser.wait_for(f"{BANNER}.hidden", 5)
        assert peer.acks == ["sr-max"]
        assert "SR above limit" in browser.eval("document.getElementById('alarms-acked').textContent")

        # the alarm clears on the server: nothing left on the page
        del peer.alarms["sr-max"]
        browser.wait_for("document.getElementById('alarms-acked').hidden", 5)


def test_alarm_messages_on_the_websocket(tmp_path, browser):  # noqa: F811
    """No /api/alarms route here (a router without routes replaces it): no polling, alarms
    come only from the websocket."""
    no_alarms = APIRouter()

    @no_alarms.get("/api/alarms", include_in_schema=False)
    def gone() -> None:
        raise HTTPException(404, "no alarm engine")

    with live_server(service_config(tmp_path / "svc"), routers=(no_alarms,)) as srv:
        websocket_alarms(srv, browser)


def websocket_alarms(sim_server, browser) -> None:  # noqa: F811
    browser.navigate(sim_server.base + "/")
    browser.wait_for("radarState.connected && radarAlarms.endpoint === false", 10)
    svc = sim_server.app.state.service

    def push(alarms: list[dict[str, Any]]) -> None:  # the way the alarm engine does
        svc.hub.publish_event_threadsafe(json.dumps({"type": "alarm", "alarms": alarms}))

    crc = {"id": "crc", "name": "CRC error rate", "column": None, "value": 0.12, "limit": 0.01,
           "since": time.time(), "acknowledged": False}
    for k in range(300):  # flapping: the states coalesce, the newest one is shown
        push([crc] if k % 2 else [])
    browser.wait_for(f"!{BANNER}.hidden && {BANNER}.textContent.includes('CRC error rate')", 5)
    n = browser.eval("radarState.received")
    browser.wait_for(f"radarState.received > {n + 5}", 5)  # measurements still flow
    push([])
    browser.wait_for(f"{BANNER}.hidden", 5)


def test_report_link_follows_the_selected_recording(sim_server, browser):  # noqa: F811
    for _ in range(2):
        code, doc = sim_server.request("POST", "/api/recordings/start", token=TOKEN)
        assert code == 200, doc
        time.sleep(1.1)  # recording ids are UTC seconds
        sim_server.request("POST", "/api/recordings/stop", token=TOKEN)
    ids = [r["id"] for r in sim_server.get("/api/recordings")]
    assert len(ids) >= 2
    browser.navigate(sim_server.base + "/")
    browser.wait_for("document.getElementById('rec-list').options.length >= 2", 10)
    assert browser.eval("document.getElementById('rec-report').href") == \
        f"{sim_server.base}/api/recordings/{ids[0]}/report"
    browser.eval(f"(s => (s.value = {ids[1]!r}, s.dispatchEvent(new Event('change'))))"
                 "(document.getElementById('rec-list')), true")
    assert browser.eval("document.getElementById('rec-report').href") == \
        f"{sim_server.base}/api/recordings/{ids[1]}/report"
    assert not browser.eval("document.getElementById('rec-report').hidden")
    assert browser.eval("document.getElementById('rec-report-pdf').href") == \
        f"{sim_server.base}/api/recordings/{ids[1]}/report?format=pdf"
    if "/api/recordings/{rec_id}/report" in sim_server.get("/openapi.json")["paths"]:
        # the report service is there: the link gives a page
        href = browser.eval("document.getElementById('rec-report').href")
        with urllib.request.urlopen(href, timeout=120) as r:
            assert r.headers["Content-Type"].startswith("text/html")
            assert b"<html" in r.read(4096).lower()
