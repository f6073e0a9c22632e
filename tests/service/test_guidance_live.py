"""The live service with a reference path, TLM1 and D/A sinks and the aircraft on CAN.

python-can's ``virtual`` bus lives inside one process, so this test runs the real
uvicorn server in-process (on 127.0.0.1) with the aircraft simulator on the same bus.
"""

from __future__ import annotations

import binascii
import json
import struct
import threading
import time
import urllib.request
import uuid

import numpy as np
import pytest
import uvicorn
from conftest import fly_on_virtual_bus

from radar_io.service.app import create_app
from radar_io.service.config import ServiceConfig
from radar_io.wirespec.frame import spec_dir

from .cdp import Chrome
from .test_live_pty import ARTIFACTS, wait_for


@pytest.fixture()
def live(tmp_path):
    channel = f"air-{uuid.uuid4().hex[:12]}"
    cfg = ServiceConfig(source="sim://?go_delay_s=0.2&ng_per_min=0", port=0,
                        data_dir=str(tmp_path / "data"),
                        path=str(spec_dir() / "paths" / "demo_track_radar.toml"),
                        tlm_out=str(tmp_path / "uplink.tlm"), tlm_cycle_s=0.02,
                        da_out=str(tmp_path / "da.bin"), can=f"virtual:{channel}")
    app = create_app(cfg)
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=0, log_level="warning",
                                           ws_per_message_deflate=False))
    th = threading.Thread(target=server.run, daemon=True)
    th.start()
    stop = threading.Event()
    ac: threading.Thread | None = None
    try:  # the server is stopped even when its start fails
        wait_for(lambda: server.started, what="uvicorn")
        port = server.servers[0].sockets[0].getsockname()[1]  # port 0: the one the kernel gave

        # the aircraft's recorder traffic on the bus, in real time
        ac = threading.Thread(target=fly_on_virtual_bus, args=(channel, stop), daemon=True)
        ac.start()
        base = f"http://127.0.0.1:{port}"

        def get(path: str):
            with urllib.request.urlopen(base + path, timeout=5) as r:
                return json.loads(r.read())

        yield base, get, tmp_path
    finally:
        stop.set()
        server.should_exit = True
        th.join(10)
        if ac is not None:
            ac.join(5)


def test_deviation_uplink_and_air_data_live(live):
    _, get, tmp = live
    st = wait_for(lambda: (s := get("/api/status"))["uplink"]["tlm"]["records"] > 50
                  and s["airdata"]["samples_received"] > 10 and s, what="uplink and air data")
    assert st["path"].endswith("demo_track_radar.toml")
    msgs = [m for m in get("/api/track?limit=500")["messages"] if m["rx_good"]]
    assert msgs and all(abs(m["dy_m"]) < 30 and abs(m["dz_m"]) < 30 and m["leg"] == 0
                        for m in msgs)  # the simulator flies this path
    path = get("/api/path")
    assert len(path["x_m"]) > 100 and path["x_m"][0] == pytest.approx(-14834.7)
    air = get("/api/airdata")
    s = air["samples"][-1]
    assert s["ias_mps"] == pytest.approx(70.0, abs=3.0)  # the script's 70 m/s
    # pressure altitude = height above the antenna + antenna MSL + QNH effect: ~100 m above
    diff = [a["pressure_altitude_m"] - a["radar_h_m"] for a in air["samples"] if a["radar_h_m"]]
    assert 80 < float(np.median(diff)) < 130
    # the uplink file holds whole, CRC-valid TLM1 frames at the 20 ms cycle
    time.sleep(0.5)
    data = (tmp / "uplink.tlm").read_bytes()
    n = len(data) // 26
    assert n >= 50 and len(data) % 26 == 0
    secs = []
    for k in range(n):
        fr = data[26 * k:26 * (k + 1)]
        sync, seq, *ch = struct.unpack(">HH10h", fr[:24])
        assert sync == 0x1ACF and binascii.crc_hqx(fr[:24], 0xFFFF) == struct.unpack(">H", fr[24:])[0]
        assert seq == k
        secs.append(ch)
    assert n < 2 * (st["frames"] / 1000 / 0.02) + 100  # one frame per cycle, not per sample
    da = (tmp / "da.bin").read_bytes()
    assert len(da) % 16 == 0 and len(da) > 0


def test_dashboard_shows_needles_path_and_air_data(live):
    base, get, tmp = live
    wait_for(lambda: get("/api/status")["airdata"]["samples_received"] > 5, what="air data")
    chrome = Chrome(tmp / "chrome")
    try:
        chrome.navigate(base + "/")
        chrome.wait_for("!document.getElementById('needles').hidden && radarState.needles "
                        "&& radarState.needles.ok")
        chrome.wait_for("!document.getElementById('air').hidden && "
                        "document.getElementById('a-ias').textContent.includes('m/s')")
        chrome.wait_for("radarState.path && radarState.path.x_m.length > 100")
        chrome.wait_for("radarState.air.length > 5")
        # the needles sit near the centre: the simulator flies the path
        assert abs(chrome.eval("radarState.needles.dx")) < 0.1
        assert abs(chrome.eval("radarState.needles.dz")) < 0.2
        chrome.screenshot(ARTIFACTS / "dashboard-guidance.png")
    finally:
        chrome.close()
