"""The operator dashboard in real headless Chromium: track and lamps, STALE, reconnects."""

from __future__ import annotations

import threading
import time
from contextlib import ExitStack

from radar_io.benchmarks.service_load import Pty
from radar_io.simulation.radar import FlightScript, RadarSimulator, SimConfig

from .liveserver import LiveServer, browser, ink_js, service_config  # noqa: F401
from .test_live_pty import ARTIFACTS


class Writer(threading.Thread):
    """Simulated radar frames into a pty at 200 frames/s until stopped; can pause."""

    def __init__(self, pty: Pty) -> None:
        super().__init__(daemon=True)
        self.pty = pty
        # fast and close, so that a few seconds of track are many pixels long
        self.sim = RadarSimulator(FlightScript(start_x_m=-5000, start_y_m=2000, speed_mps=300),
                                  SimConfig(seed=8, rate_hz=200, go_delay_s=0, loop=True,
                                            sync_every_s=1.0))
        self.running = threading.Event()
        self.running.set()
        self.stopped = threading.Event()

    def run(self) -> None:
        t0, sent = time.monotonic(), 0
        while not self.stopped.is_set():
            due = int((time.monotonic() - t0) * 200) - sent
            if not self.running.is_set():
                sent += max(due, 0)  # paused: frames not sent are simply not sent
            elif due > 0:
                data, _ = self.sim.generate(due)
                self.pty.write(data)
                sent += due
            time.sleep(0.01)


def test_dashboard_track_lamps_stale_and_recovery(tmp_path, browser):  # noqa: F811
    """Everything started here is stopped in ``finally``, also when a start fails; the
    service binds port 0 and its restart reuses the port it got."""
    chrome = browser
    with ExitStack() as stack:
        pty = Pty()
        stack.callback(pty.close)
        writer = Writer(pty)
        writer.start()
        stack.callback(writer.join, 5)
        stack.callback(writer.stopped.set)
        cfg = service_config(tmp_path / "svc", source=pty.path)
        svc = LiveServer(cfg)
        stack.callback(lambda: svc.stop())  # whichever server runs at the end
        svc.start()
        svc.wait_connected()
        port = svc.port
        chrome.navigate(f"http://127.0.0.1:{port}/")
        # track and lamps from live data
        chrome.wait_for("radarState.points.length > 30 && radarState.connected")
        chrome.wait_for("document.getElementById('lamp-go').classList.contains('on')")
        assert chrome.eval("document.getElementById('lamp-rx_good').classList.contains('on')")
        assert chrome.eval("document.getElementById('stale').hidden")
        assert chrome.eval("document.getElementById('r-sr').textContent") not in ("—", "")
        # the tracking filter's readouts: a ground speed with its σ
        chrome.wait_for("document.getElementById('k-gs-s').textContent.startsWith('± ')")
        assert chrome.eval("document.getElementById('k-gs').textContent") not in ("—", "")
        chrome.wait_for("(r => r > 150 && r < 260)(parseFloat(document.getElementById('c-rate')"
                        ".textContent))")  # the writer's ~200 frames/s
        # something was drawn on the plan view: the canvas is not blank
        chrome.wait_for(ink_js("document.getElementById('plan')") + " > 500", 10)
        chrome.screenshot(ARTIFACTS / "dashboard.png")

        # the source stops: STALE within about a second
        writer.running.clear()
        chrome.wait_for("!document.getElementById('stale').hidden", 5)
        assert not chrome.eval("document.getElementById('lamp-go').classList.contains('on')")
        chrome.screenshot(ARTIFACTS / "dashboard-stale.png")
        writer.running.set()
        chrome.wait_for("document.getElementById('stale').hidden", 5)

        # a dropped websocket: reconnects with from= and no point is missing
        before = chrome.eval("radarState.lastMsgSeq")
        chrome.eval("radarState.ws.close(), true")
        chrome.wait_for(f"radarState.lastMsgSeq > {before + 300} && radarState.connected", 15)
        plotted = set(chrome.eval("radarState.points.map(p => p.s)"))
        # the page waits 0.5 s before its first reconnect: at 200 frames/s the first 80
        # messages after the close fall inside the outage and must all be plotted (backfill)
        track = svc.get(f"/api/track?since={before}&limit=80")["messages"]
        want = {m["msg_seq"] for m in track if m["rx_good"]}
        assert want and want <= plotted

        # the server restarts on the same port: the page recovers on its own
        instance = chrome.eval("radarState.instance")
        svc.stop()
        chrome.wait_for("!document.getElementById('stale').hidden", 5)
        chrome.wait_for("!radarState.connected", 5)
        svc = LiveServer(cfg, port=port)
        svc.start()
        svc.wait_connected()
        chrome.wait_for(f"radarState.connected && radarState.instance !== '{instance}'", 20)
        n = chrome.eval("radarState.received")
        chrome.wait_for(f"radarState.received > {n + 20}", 10)
        chrome.wait_for("document.getElementById('stale').hidden", 5)
        chrome.screenshot(ARTIFACTS / "dashboard-recovered.png")
