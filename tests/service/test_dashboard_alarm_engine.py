"""The alarm banner against the service's own alarm engine (radar_io.service.alarms): a limit
crossing in simulated data shows on the page, and the ACK button acknowledges it with the
control token."""

from __future__ import annotations

import json

from .liveserver import TOKEN, browser, live_server, service_config  # noqa: F401
from .test_live_pty import ARTIFACTS

BANNER = "document.getElementById('alarms')"


def test_limit_alarm_from_simulated_data_shows_and_acknowledges(tmp_path, browser):  # noqa: F811
    # the simulator flies at SR ≈ 15 km: a 1 km upper limit is crossed at once
    cfg = service_config(tmp_path / "svc", alarms=[
        {"column": "sr_m", "max": 1000.0, "for_s": 0.2, "name": "SR limit"}])
    with live_server(cfg) as srv:
        browser.navigate(srv.base + "/")
        browser.wait_for("radarAlarms.endpoint === true", 10)
        browser.wait_for(f"!{BANNER}.hidden && {BANNER}.textContent.includes('SR limit')", 10)
        text = browser.eval(f"{BANNER}.textContent")
        assert "sr_m = " in text and "limit 1000" in text
        alarm = next(a for a in srv.get("/api/alarms")["alarms"] if a["column"] == "sr_m")
        assert not alarm["acknowledged"]
        browser.screenshot(ARTIFACTS / "dashboard-alarm-engine.png")

        browser.eval(f"document.getElementById('token').value = {json.dumps(TOKEN)}, true")
        browser.eval(f"{BANNER}.querySelector('button').click(), true")
        browser.wait_for(f"{BANNER}.hidden", 10)
        assert "SR limit" in browser.eval("document.getElementById('alarms-acked').textContent")
        alarm = next(a for a in srv.get("/api/alarms")["alarms"] if a["column"] == "sr_m")
        assert alarm["acknowledged"]
