"""REST, websocket resume, control with token, recordings, replay sessions and calibration on
a live service."""

from __future__ import annotations

import asyncio
import json
import os
import subprocess
import sys
import time
import urllib.error
import urllib.request
from itertools import pairwise

import pytest
import websockets

from radar_io.benchmarks.service_load import ServeProcess
from radar_io.recording.rdrlog import RecordingReader

from .test_live_pty import wait_for

TOKEN = "s3cret-token"


@pytest.fixture(scope="module")
def svc(tmp_path_factory):
    d = tmp_path_factory.mktemp("svc")
    s = ServeProcess("sim://?go_delay_s=0.5&sync_every_s=1", d / "data",
                     env={"RADAR_IO_TOKEN": TOKEN})
    s.data = d / "data"
    with s:  # stopped even when it never becomes ready
        yield s


def msg(doc) -> str:
    """The reasons of an error body (a list of {loc, msg, type}), joined."""
    assert isinstance(doc["detail"], list) and all({"loc", "msg", "type"} <= set(d) for d in doc["detail"])
    return "; ".join(d["msg"] for d in doc["detail"])


def call(svc, method: str, path: str, body=None, token: str | None = TOKEN) -> tuple[int, dict]:
    headers = {"Content-Type": "application/json"}
    if token is not None:
        headers["Authorization"] = f"Bearer {token}"
    data = json.dumps(body).encode() if body is not None else None
    req = urllib.request.Request(svc.base + path, method=method, data=data, headers=headers)
    try:
        with urllib.request.urlopen(req, timeout=10) as r:
            return r.status, json.loads(r.read() or b"null")
    except urllib.error.HTTPError as e:
        return e.code, json.loads(e.read() or b"null")


def test_status_has_every_field(svc):
    st = wait_for(lambda: (s := svc.get("/api/status"))["rate_hz"] > 900 and s, what="rate")
    for k in ("source", "connected", "frames", "crc_errors", "bytes_discarded", "seq_gaps", "rate_hz",
              "go", "rx_good", "last_frame_age_s", "recording", "ws_clients", "ws_dropped"):
        assert k in st, k
    assert st["source"].startswith("sim://") and st["connected"] and st["last_frame_age_s"] < 0.5


@pytest.mark.parametrize("method,path,body", [
    ("POST", "/api/recordings/start", None), ("POST", "/api/recordings/stop", None),
    ("POST", "/api/replays", {"recording": "x", "speed": 1}), ("POST", "/api/replays/0a/pause", None),
    ("DELETE", "/api/replays/0a", None),
    ("PUT", "/api/calibration", {"biases": {"dsr_m": 1}}),
])
def test_control_needs_the_token(svc, method, path, body):
    code, doc = call(svc, method, path, body, token=None)
    assert code == 401 and "Bearer" in msg(doc)
    code, doc = call(svc, method, path, body, token="wrong")
    assert code == 403 and msg(doc) == "wrong token"


def test_control_disabled_without_a_configured_token(tmp_path):
    s = ServeProcess("sim://", tmp_path / "d", env={"RADAR_IO_TOKEN": ""})
    try:
        s.wait_ready()
        req = urllib.request.Request(s.base + "/api/recordings/start", method="POST",
                                     headers={"Authorization": "Bearer anything"})
        with pytest.raises(urllib.error.HTTPError) as e:
            urllib.request.urlopen(req, timeout=5)
        assert e.value.code == 403 and "control is disabled" in msg(json.loads(e.value.read()))
        assert s.get("/api/status")["control_enabled"] is False
    finally:
        s.stop()


def test_track_since_and_limit(svc):
    doc = svc.get("/api/track?limit=50")
    msgs = doc["messages"]
    assert len(msgs) == 50
    seqs = [m["msg_seq"] for m in msgs]
    assert seqs == list(range(seqs[0], seqs[0] + 50))
    later = wait_for(lambda: len(m := svc.get(f"/api/track?since={seqs[-1]}&limit=10")["messages"])
                     == 10 and m, what="10 newer messages")
    assert [m["msg_seq"] for m in later] == list(range(seqs[-1] + 1, seqs[-1] + 11))
    assert {"sr_m", "x_m", "lat_deg", "xr_m", "t_ns"} <= set(msgs[0])


def test_websocket_resume_backfills_every_message(svc):
    async def main() -> list[int]:
        url = f"ws://127.0.0.1:{svc.port}/ws/live"
        async with websockets.connect(url) as ws:
            first = [json.loads(await ws.recv())["msg_seq"] for _ in range(200)]
        await asyncio.sleep(0.8)  # ~800 messages go by while we are away
        async with websockets.connect(f"{url}?from={first[-1]}") as ws:
            again = [json.loads(await ws.recv())["msg_seq"] for _ in range(3000)]
        return first + again

    seqs = asyncio.run(main())
    assert seqs == list(range(seqs[0], seqs[0] + 3200))


def test_decimated_stream(svc):
    async def main() -> list[float]:
        async with websockets.connect(f"ws://127.0.0.1:{svc.port}/ws/live?max_hz=20") as ws:
            t = []
            while len(t) < 21:
                await ws.recv()
                t.append(time.monotonic())
            return t

    t = asyncio.run(main())
    assert 0.8 < t[-1] - t[0] < 1.6  # ~20 messages per second, not 1000


def test_validation_errors_are_422_with_a_reason(svc):
    code, doc = call(svc, "POST", "/api/replays", {"recording": "x", "speed": -4})
    assert code == 422 and "speed" in json.dumps(doc)
    code, doc = call(svc, "PUT", "/api/calibration", {"biases": {"dsr_m": "a lot"}})
    assert code == 422 and doc["detail"][0]["loc"] == ["body", "biases", "dsr_m"] and msg(doc)
    code, _ = call(svc, "GET", "/api/track?limit=0")
    assert code == 422


def test_recordings_list_download_404_and_traversal(svc):
    rec = wait_for(lambda: svc.get("/api/status")["recording"], what="GO-edge recording")
    wait_for(lambda: sum(e["recording"] == rec for e in svc.get("/api/sync-events")) >= 2,
             what="two shutter events in the recording")
    code, doc = call(svc, "POST", "/api/recordings/stop")
    assert code == 200 and doc["closed"] == rec
    lst = svc.get("/api/recordings")
    assert rec in [r["id"] for r in lst]
    with urllib.request.urlopen(f"{svc.base}/api/recordings/{rec}", timeout=10) as r:
        body = r.read()
    assert body == (svc.data / "recordings" / f"{rec}.rdrlog").read_bytes()
    # the download's limiter slot is back once it was sent (freed when the server's last send
    # returns, which may be just after the client has read the body)
    wait_for(lambda: svc.get("/api/status")["expensive"]["downloads"] == {
        "running": 0, "limit": 4, "refused": 0}, what="the download's limiter slot back")
    assert call(svc, "GET", "/api/recordings/nope")[0] == 404
    for bad in ("..%2F..%2Fetc%2Fpasswd", "a..b", "%2Fetc%2Fpasswd"):
        code, _ = call(svc, "GET", f"/api/recordings/{bad}")
        assert code in (404, 422), bad  # a bad id is a validation error (422)
    events = svc.get(f"/api/sync-events?recording={rec}", 60)  # the first starts a worker
    assert events and all(e["recording"] == rec for e in events)
    assert all(b["tod_s"] - a["tod_s"] == pytest.approx(1.0, abs=0.002)
               for a, b in pairwise(events))


def test_manual_recording_and_replay_controls(svc):
    code, doc = call(svc, "POST", "/api/recordings/start")
    assert code == 200
    rec = doc["recording"]
    time.sleep(1.5)
    assert call(svc, "POST", "/api/recordings/stop")[1]["closed"] == rec
    with RecordingReader(svc.data / "recordings" / f"{rec}.rdrlog") as r:
        n_rec = sum(len(c.data) for c in r) // 24
    live0 = svc.get("/api/status")
    code, st = call(svc, "POST", "/api/replays", {"recording": rec, "speed": 1.0})
    assert code == 201 and st["recording"] == rec and st["ws"] == f"/ws/replays/{st['id']}"
    sid = st["id"]
    base = f"/api/replays/{sid}"
    code, st = call(svc, "POST", base + "/pause")
    assert code == 200 and st["paused"]
    time.sleep(0.3)
    f0 = svc.get(base)["frames"]
    time.sleep(0.4)
    assert svc.get(base)["frames"] == f0  # paused: nothing flows
    call(svc, "POST", base + "/step", {"n": 3})
    wait_for(lambda: svc.get(base)["chunk"] >= 3 and svc.get(base)["frames"] > f0, what="step")
    code, st = call(svc, "POST", base + "/seek", {"position_s": 0.0})
    assert code == 200 and st["position_s"] == 0.0
    call(svc, "POST", base + "/speed", {"speed": 0})
    call(svc, "POST", base + "/resume")
    st = wait_for(lambda: (s := svc.get(base))["finished"] and s, what="end")
    assert st["frames"] >= n_rec and st["seq_gaps"] == 0
    assert [r["id"] for r in svc.get("/api/replays")] == [sid]
    live = svc.get("/api/status")  # the live pipeline never noticed
    assert live["mode"] == "live" and live["connected"] and live["source"] == live0["source"]
    assert live["reconnects"] == live0["reconnects"] and live["frames"] > live0["frames"]
    assert [r["id"] for r in live["replays"]] == [sid]
    code, doc = call(svc, "DELETE", base)
    assert code == 200 and doc["id"] == sid
    assert call(svc, "GET", base)[0] == 404 and svc.get("/api/replays") == []
    code, doc = call(svc, "POST", "/api/replay", {"recording": rec, "speed": 1.0})
    assert code == 410 and "POST /api/replays" in msg(doc)


def test_put_calibration_applies_live(svc):
    before = svc.get("/api/track?limit=20")["messages"]
    code, doc = call(svc, "PUT", "/api/calibration",
                     {"format": "radar_io-calibration/1", "id": "test-cal",
                      "biases": {"dsr_m": 100.0, "del_deg": 0.0, "daz_deg": 0.0}})
    assert code == 200 and doc["id"] == "test-cal"
    assert svc.get("/api/status")["calibration"] == "test-cal"
    time.sleep(0.2)
    after = svc.get("/api/track?limit=200")["messages"]
    good = [m for m in after if m["rx_good"]]
    assert good and all(m["sr_c_m"] == pytest.approx(m["sr_m"] + m["dsr_m"] + 100.0) for m in good[-50:])
    assert (svc.data / "calibrations" / "active.json").exists()
    call(svc, "PUT", "/api/calibration", {"id": "zero", "biases": {}})
    assert all(m["sr_c_m"] == pytest.approx(m["sr_m"] + m["dsr_m"]) for m in before if m["rx_good"])


def test_openapi_docs(svc):
    with urllib.request.urlopen(svc.base + "/docs", timeout=5) as r:
        assert b"swagger" in r.read().lower()
    api = svc.get("/openapi.json")
    assert "/api/status" in api["paths"] and "/api/replays/{sid}/seek" in api["paths"]
    gone = api["paths"]["/api/replay/seek"]["post"]["responses"]
    assert "410" in gone and not any(code.startswith("2") for code in gone)


def test_serve_defaults_and_port_0_prints_the_real_port(tmp_path):
    """The README's ``radar-io serve`` with only ``--port 0``: the simulator, the demo site,
    ./radar-data, on 127.0.0.1 at the port it prints."""
    env = {k: v for k, v in os.environ.items() if k != "RADAR_IO_TOKEN"}
    p = subprocess.Popen([sys.executable, "-m", "radar_io.cli", "serve", "--port", "0"],
                         cwd=tmp_path, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                         text=True)
    try:
        port = None
        for line in p.stderr:
            if "listening on http://" in line:
                host_port = line.split("listening on http://", 1)[1].split("/", 1)[0]
                assert host_port.startswith("127.0.0.1:")
                port = int(host_port.rsplit(":", 1)[1])
                break
        assert port and port != 0, "serve printed no port"
        base = f"http://127.0.0.1:{port}"

        def status():
            try:
                with urllib.request.urlopen(base + "/api/status", timeout=2) as r:
                    return json.loads(r.read())
            except OSError:
                assert p.poll() is None
                return None

        st = wait_for(lambda: (s := status()) and s["frames"] > 0 and s, timeout_s=30,
                      what="serve on the printed port")
        assert st["source"] == "sim://" and st["site"] == "demo"
        with urllib.request.urlopen(base + "/", timeout=5) as r:
            assert b"radar_io" in r.read()
        assert (tmp_path / "radar-data" / "recordings").is_dir()
    finally:
        p.terminate()
        p.wait(10)


def test_bias_from_photo_observations_at_recorded_sync_events(svc):
    """Photo positions offset from the radar by known biases → those biases, then applied live."""
    import numpy as np

    from radar_io.decoding.decoders import decode_bytes

    rec = call(svc, "POST", "/api/recordings/start")[1]["recording"]
    time.sleep(3.6)  # sync every 1 s
    assert call(svc, "POST", "/api/recordings/stop")[1]["closed"] == rec
    with RecordingReader(svc.data / "recordings" / f"{rec}.rdrlog") as r:
        b = decode_bytes(b"".join(c.data for c in r))
    s = b["sync"].astype(int)
    edges = list(np.flatnonzero((s[1:] == 1) & (s[:-1] == 0)) + 1)
    if s[0] == 1:  # began before the recording: counted, never paired
        edges = [0, *edges]
    usable = [(k, i) for k, i in enumerate(edges) if b["rx_good"][i] and i > 0][:3]
    assert len(usable) >= 2
    listed = svc.get(f"/api/sync-events?recording={rec}", 60)
    assert [e["seq"] for e in listed] == [int(b["seq"][i]) for i in edges]
    obs = []
    for k, i in usable:
        obs.append({"group": "f1" if k % 2 == 0 else "f2", "recording": rec, "sync_index": k,
                    "photo_sr_m": float(b["sr_c_m"][i]) + 5.0,
                    "photo_el_deg": float(b["el_c_deg"][i]) + 0.01,
                    "photo_az_deg": float(b["az_c_deg"][i]) - 0.02})
    code, doc = call(svc, "POST", "/api/calibration/bias", {"id": "photo-1", "observations": obs})
    assert code == 200, doc
    comb = doc["statistics"]["combined"]
    assert comb["n"] == len(usable)
    assert comb["dsr_m"]["mean"] == pytest.approx(5.0, abs=1e-9)
    assert comb["del_deg"]["mean"] == pytest.approx(0.01, abs=1e-12)
    assert comb["daz_deg"]["mean"] == pytest.approx(-0.02, abs=1e-9)
    assert [p["seq"] for p in doc["pairs"]] == [int(b["seq"][i]) for _, i in usable]
    assert svc.get("/api/status")["calibration"] != "photo-1"  # proposed, not applied
    code, _ = call(svc, "PUT", "/api/calibration", doc["calibration"])
    assert code == 200 and svc.get("/api/status")["calibration"] == "photo-1"
    code, doc = call(svc, "POST", "/api/calibration/bias",
                     {"id": "x", "observations": [{**obs[0], "sync_index": 999}]})
    assert code == 422 and "no index 999" in msg(doc)
    call(svc, "PUT", "/api/calibration", {"id": "zero", "biases": {}})


def test_dashboard_calibration_panel_estimates_and_applies(svc, tmp_path):
    """In Chromium: paste photo observations, estimate, review, apply with the token."""
    from .cdp import Chrome

    rec = call(svc, "POST", "/api/recordings/start")[1]["recording"]
    time.sleep(2.6)
    call(svc, "POST", "/api/recordings/stop")
    events = [e for e in svc.get(f"/api/sync-events?recording={rec}", 60) if e["rx_good"]][:2]
    assert len(events) == 2
    rows = ["group,recording,sync_index,photo_sr_m,photo_el_deg,photo_az_deg"]
    for e in events:
        rows.append(f"f1,{rec},{e['sync_index']},{e['sr_m'] + 7.0},{e['el_deg']},{e['az_deg']}")
    chrome = Chrome(tmp_path / "chrome")
    try:
        chrome.navigate(svc.base + "/")
        chrome.eval("document.getElementById('calibration').open = true, true")
        chrome.eval(f"document.getElementById('token').value = {json.dumps(TOKEN)}, true")
        chrome.eval(f"document.getElementById('obs').value = {json.dumps(chr(10).join(rows))}, true")
        chrome.eval("document.getElementById('cal-id').value = 'panel-cal', true")
        chrome.eval("document.getElementById('estimate').click(), true")
        chrome.wait_for("document.getElementById('cal-result').textContent.includes('combined')", 20)
        text = chrome.eval("document.getElementById('cal-result').textContent")
        assert "ΔSR 7.0000" in text
        assert svc.get("/api/status")["calibration"] != "panel-cal"  # reviewed, not yet applied
        chrome.eval("document.getElementById('apply').click(), true")
        wait_for(lambda: svc.get("/api/status")["calibration"] == "panel-cal", what="applied")
        chrome.wait_for("document.getElementById('cal-active').textContent === 'panel-cal'", 5)
    finally:
        chrome.close()
        call(svc, "PUT", "/api/calibration", {"id": "zero", "biases": {}})
