"""The live flight is untouchable (issue 19 items 1 and 2): a real ``radar-io serve`` reading
a pty at 1 kHz with GO high and a GO recording open.

* Every route of ``/openapi.json`` is called with plausible arguments (replay sessions,
  calibration apply, a runway image, …; ``POST /api/recordings/stop|start`` last): the
  recording keeps growing with no SEQ gap, the source stays connected and the same, and only
  the recording routes change the recorder.
* The figure (``-m slow``, ``-s`` prints it): with TLM1 to a file, ASTERIX to UDP and MQTT to
  Mosquitto, two replay sessions of an earlier, distinguishable flight (speed 4; speed 1
  paused, seeked, stepped) run for 20 s beside the live stream; no live output carries a
  replayed message and each replay websocket gets the recorded frames with their recorded
  ``t_ns``.
"""

from __future__ import annotations

import asyncio
import json
import socket
import threading
import time
import urllib.error
import urllib.request
from pathlib import Path
from typing import Any

import independent
import numpy as np
import pytest
import websockets
from conftest import require_program

from radar_io.benchmarks.service_load import Pty, ServeProcess
from radar_io.decoding.decoders import decode_bytes
from radar_io.recording.rdrlog import RecordingReader
from radar_io.wirespec.frame import spec_dir

from .test_live_pty import wait_for
from .test_replay_sessions import recorded_t_ns, write_flight

TOKEN = "walk-token"
LIVE_SR, REPLAY_SR = 4000, 15000       #: slant ranges (m) of the live and the replayed flight
REPLAY_SEQ0, REPLAY_FRAMES = 40000, 24000  #: the replayed flight's SEQ range: 40000 … 63999
EL, AZ = 0x0100, 0x2000                #: raw words: 1.4° elevation, 45° azimuth
DEMO_SITE = spec_dir() / "sites" / "demo.toml"


def _sts(i: int) -> int:
    return 0x8005 if i % 100 == 1 else 0x0005  # GO and RX good; SYNC high one frame in 100


class Feeder(threading.Thread):
    """RDR1 frames into a pty at ``rate_hz``, ``per_write`` frames per write, paced on the
    monotonic clock: SEQ from 0, GO high, SYNC every 100 frames, SR ``LIVE_SR``."""

    def __init__(self, pty: Pty, rate_hz: float = 1000.0, per_write: int = 10) -> None:
        super().__init__(daemon=True, name="pty-feeder")
        self.pty, self.rate_hz, self.per_write = pty, rate_hz, per_write
        self.sent = 0
        self.halt = threading.Event()

    def run(self) -> None:
        t0 = time.monotonic()
        while not self.halt.is_set():
            wait = t0 + self.sent / self.rate_hz - time.monotonic()
            if wait > 0:
                time.sleep(wait)
            k = self.sent
            self.pty.write(b"".join(independent.frame(seq=i & 0xFFFF, tod=10 * i, sr=LIVE_SR,
                                                      el=EL, az=AZ, sts=_sts(i))
                                    for i in range(k, k + self.per_write)))
            self.sent = k + self.per_write

    def stop(self) -> int:
        self.halt.set()
        self.join(10)
        return self.sent


class StatusWatch(threading.Thread):
    """Polls /api/status every ``period_s``: (connected, source, reconnects, recording)."""

    def __init__(self, svc: ServeProcess, period_s: float = 0.25) -> None:
        super().__init__(daemon=True, name="status-watch")
        self.svc, self.period_s = svc, period_s
        self.seen: list[tuple[bool, str, int, str | None]] = []
        self.halt = threading.Event()

    def run(self) -> None:
        while not self.halt.wait(self.period_s):
            try:
                st = self.svc.get("/api/status")
            except OSError:
                self.seen.append((False, "(no answer)", -1, None))
                continue
            self.seen.append((st["connected"], st["source"], st["reconnects"], st["recording"]))

    def stop(self) -> list[tuple[bool, str, int, str | None]]:
        self.halt.set()
        self.join(10)
        return self.seen


class WsCollector(threading.Thread):
    """All messages of one websocket (``batch=1`` arrays flattened) until stopped."""

    def __init__(self, url: str) -> None:
        super().__init__(daemon=True, name=f"ws:{url.rsplit('/', 1)[-1]}")
        self.url = url
        self.msgs: list[dict[str, Any]] = []
        self.halt = threading.Event()
        self.ready = threading.Event()

    def run(self) -> None:
        asyncio.run(self._main())

    async def _main(self) -> None:
        async with websockets.connect(self.url, max_size=None) as ws:
            self.ready.set()
            while not self.halt.is_set():
                try:
                    doc = json.loads(await asyncio.wait_for(ws.recv(), 0.2))
                except TimeoutError:
                    continue
                except websockets.ConnectionClosed:
                    return
                self.msgs.extend(doc if isinstance(doc, list) else [doc])

    def stop(self) -> list[dict[str, Any]]:
        self.halt.set()
        self.join(10)
        return self.msgs


def call(base: str, method: str, path: str, body: Any = None, *, raw: bytes | None = None,
         content_type: str = "application/json", token: str | None = TOKEN) -> tuple[int, Any]:
    data = raw if raw is not None else (json.dumps(body).encode() if body is not None else None)
    req = urllib.request.Request(base + path, method=method, data=data)
    req.add_header("Content-Type", content_type)
    if token:
        req.add_header("Authorization", f"Bearer {token}")
    try:
        with urllib.request.urlopen(req, timeout=60) as r:
            payload = r.read()
            code = r.status
    except urllib.error.HTTPError as exc:
        payload, code = exc.read(), exc.code
    try:
        return code, json.loads(payload or b"null")
    except ValueError:
        return code, payload  # a download, a report, a picture


def recording_seqs(path: Path) -> np.ndarray:
    """SEQ of every frame in a recording (read as far as it is written)."""
    with RecordingReader(path) as r:
        data = b"".join(c.data for c in r)
    return np.asarray(decode_bytes(data)["seq"], dtype=np.int64)


def seq_gaps(seqs: np.ndarray) -> int:
    return int(np.count_nonzero(np.diff(seqs) % 65536 != 1))


def serve(tmp: Path, pty: Pty, extra_toml: str = "") -> ServeProcess:
    cfg = tmp / "serve.toml"
    cfg.write_text(f'auto_record = "go"\nsite = "{DEMO_SITE}"\n{extra_toml}')
    return ServeProcess(pty.path, tmp / "data", extra=("--config", str(cfg)),
                        env={"RADAR_IO_TOKEN": TOKEN})


# -- the OpenAPI walk ------------------------------------------------------------------------
def _png() -> bytes:
    import cv2

    img = np.full((240, 320), 90, np.uint8)
    ok, buf = cv2.imencode(".png", img)
    assert ok
    return bytes(buf)


def _arguments(method: str, path: str, op: dict[str, Any], ctx: dict[str, str]
               ) -> tuple[str, Any, bytes | None, str]:
    """(path with query, JSON body, raw body, content type): plausible arguments for one
    operation; an operation not listed here gets its path parameters from ``ctx`` and its
    required query parameters and body from their schema."""
    rec, earlier, sid = ctx["live"], ctx["earlier"], ctx.get("sid", "0")
    known: dict[tuple[str, str], tuple[str, Any]] = {
        ("GET", "/api/track"): ("/api/track?since=0&limit=100", None),
        ("GET", "/api/airdata"): ("/api/airdata?since=0&limit=10", None),
        ("GET", "/api/recordings/{rec_id}"): (f"/api/recordings/{rec}", None),
        ("GET", "/api/recordings/{rec_id}/report"):
            (f"/api/recordings/{earlier}/report?format=html", None),
        ("GET", "/api/sync-events"): (f"/api/sync-events?recording={earlier}", None),
        ("GET", "/api/recordings/{rec_id}/series"):  # the recording being written
            (f"/api/recordings/{rec}/series?columns=h_m,sync,seq&points=100", None),
        ("GET", "/api/recordings/{rec_id}/events"): (f"/api/recordings/{rec}/events", None),
        ("POST", "/api/replays"): ("/api/replays", {"recording": earlier, "speed": 4.0}),
        ("POST", "/api/replays/{sid}/seek"): (f"/api/replays/{sid}/seek", {"position_s": 1.0}),
        ("POST", "/api/replays/{sid}/step"): (f"/api/replays/{sid}/step", {"n": 3}),
        ("POST", "/api/replays/{sid}/speed"): (f"/api/replays/{sid}/speed", {"speed": 2.0}),
        ("POST", "/api/replay"): ("/api/replay", {"recording": earlier, "speed": 1.0}),
        ("POST", "/api/replay/seek"): ("/api/replay/seek", {"position_s": 1.0}),
        ("POST", "/api/replay/step"): ("/api/replay/step", {"n": 1}),
        ("POST", "/api/replay/speed"): ("/api/replay/speed", {"speed": 1.0}),
        ("PUT", "/api/calibration"): ("/api/calibration", {
            "format": "radar_io-calibration/1", "id": "walk",
            "biases": {"dsr_m": 0.0, "del_deg": 0.0, "daz_deg": 0.0}}),
        ("POST", "/api/calibration/bias"): ("/api/calibration/bias", {"id": "walk-bias", "observations": [
            {"group": "f1", "recording": earlier, "sync_index": k, "photo_sr_m": REPLAY_SR + 3.0,
             "photo_el_deg": 1.4, "photo_az_deg": 45.0} for k in (0, 1, 2)]}),
        ("POST", "/api/coordinates/runway-to-radar"): ("/api/coordinates/runway-to-radar",
                                                       {"xr_m": [0.0, 500.0], "yr_m": [0.0, 10.0],
                                                        "hr_m": [0.0, 30.0]}),
        ("POST", "/api/alarms/{alarm_id}/ack"): (f"/api/alarms/{ctx.get('alarm', 'none')}/ack", None),
        ("POST", "/api/runway/manual"): ("/api/runway/manual", {
            "points": {"horizon": [[0, 100], [320, 100]], "left_edge": [[120, 240], [155, 110]],
                       "right_edge": [[200, 240], [165, 110]]},
            "focal_px": 400.0, "half_width_m": 22.5, "principal_point": [160.0, 120.0]}),
    }
    if (method, path) == ("POST", "/api/runway"):
        return "/api/runway?focal_px=400&half_width_m=22.5", None, _png(), "image/png"
    if (method, path) in known:
        url, body = known[(method, path)]
        return url, body, None, "application/json"
    url = path
    for p in op.get("parameters", []):
        if p["in"] == "path":
            value = {"sid": sid, "rec_id": earlier, "recording": earlier}.get(p["name"], "0")
            url = url.replace("{" + p["name"] + "}", value)
    query = []
    for p in op.get("parameters", []):
        if p["in"] == "query" and p.get("required"):
            kind = p.get("schema", {}).get("type", "string")
            query.append(f"{p['name']}={1 if kind in ('integer', 'number') else earlier}")
    if query:
        url += "?" + "&".join(query)
    body = {} if "application/json" in op.get("requestBody", {}).get("content", {}) else None
    return url, body, None, "application/json"


#: must succeed with the arguments above (the others may answer a documented 4xx)
MUST_SUCCEED = {("GET", "/api/status"), ("GET", "/api/track"), ("GET", "/api/recordings"),
                ("GET", "/api/recordings/{rec_id}"), ("GET", "/api/sync-events"),
                ("GET", "/api/replays"), ("POST", "/api/replays"), ("GET", "/api/replays/{sid}"),
                ("DELETE", "/api/replays/{sid}"), ("POST", "/api/replays/{sid}/pause"),
                ("POST", "/api/replays/{sid}/resume"), ("POST", "/api/replays/{sid}/seek"),
                ("POST", "/api/replays/{sid}/step"), ("POST", "/api/replays/{sid}/speed"),
                ("GET", "/api/calibration"), ("PUT", "/api/calibration"),
                ("POST", "/api/coordinates/runway-to-radar"), ("GET", "/api/alarms"),
                ("GET", "/api/recordings/{rec_id}/report"), ("POST", "/api/calibration/bias"),
                ("GET", "/api/recordings/{rec_id}/series"), ("GET", "/api/recordings/{rec_id}/events")}
RECORDING_ROUTES = [("POST", "/api/recordings/stop"), ("POST", "/api/recordings/start")]


def _order(item: tuple[str, str]) -> tuple[int, str, str]:
    method, path = item
    if item == ("POST", "/api/replays"):
        return (0, path, method)  # the session the /api/replays/{sid}… routes work on
    if item == ("DELETE", "/api/replays/{sid}"):
        return (2, path, method)
    return (1, path, method)


def test_every_route_during_a_go_recording_leaves_the_recording_and_the_source_alone(tmp_path):
    rec_dir = tmp_path / "data" / "recordings"
    rec_dir.mkdir(parents=True)
    write_flight(rec_dir / "earlier.rdrlog", 3000, seq0=REPLAY_SEQ0, sr=REPLAY_SR)
    pty = Pty()
    feeder = Feeder(pty)
    svc = serve(tmp_path, pty)
    watch = StatusWatch(svc)
    calls: list[tuple[str, str, int]] = []
    try:
        svc.wait_ready()
        feeder.start()
        rec = wait_for(lambda: svc.get("/api/status")["recording"], what="the GO recording")
        st0 = svc.get("/api/status")
        watch.start()
        ctx = {"live": rec, "earlier": "earlier"}
        api = svc.get("/openapi.json")
        ops = {(m.upper(), p): op for p, item in api["paths"].items() for m, op in item.items()}
        size0 = (rec_dir / f"{rec}.rdrlog").stat().st_size
        # a session of the recording being written, too
        code, doc = call(svc.base, "POST", "/api/replays", {"recording": rec, "speed": 1.0})
        assert code == 201, doc
        calls.append(("POST", "/api/replays (the open recording)", code))
        for method, path in sorted(set(ops) - set(RECORDING_ROUTES), key=_order):
            if (method, path) == ("POST", "/api/alarms/{alarm_id}/ack"):
                alarms = svc.get("/api/alarms")
                ctx["alarm"] = (alarms.get("alarms") or [{"id": "none"}])[0]["id"] \
                    if isinstance(alarms, dict) else "none"
            url, body, raw, ctype = _arguments(method, path, ops[(method, path)], ctx)
            code, doc = call(svc.base, method, url, body, raw=raw, content_type=ctype)
            calls.append((method, path, code))
            assert code < 500, (method, url, code, doc)
            if path.startswith("/api/replay/") or path == "/api/replay":
                assert code == 410, (method, path, code)
            elif (method, path) in MUST_SUCCEED:
                assert 200 <= code < 300, (method, url, code, doc)
            if (method, path) == ("POST", "/api/replays"):
                ctx["sid"] = doc["id"]
            st = svc.get("/api/status")  # after every call: same recording, same source
            assert st["recording"] == rec, (method, path)
            assert st["source"] == st0["source"] and st["connected"], (method, path)
        size1 = (rec_dir / f"{rec}.rdrlog").stat().st_size
        seqs = recording_seqs(rec_dir / f"{rec}.rdrlog")
        seen = watch.stop()
        # only the recording routes change the recorder, and last
        code, doc = call(svc.base, "POST", "/api/recordings/stop")
        assert code == 200 and doc["closed"] == rec
        calls.append(("POST", "/api/recordings/stop", code))
        code, doc = call(svc.base, "POST", "/api/recordings/start")
        assert code == 200 and doc["recording"] != rec
        calls.append(("POST", "/api/recordings/start", code))
        time.sleep(0.5)
        st1 = svc.get("/api/status")
    finally:
        watch.halt.set()
        feeder.stop()
        svc.stop()
        pty.close()
    walked = {(m, p) for m, p, _ in calls}
    assert set(ops) <= walked, f"not called: {sorted(set(ops) - walked)}"
    assert size1 > size0                                     # the recording kept growing
    assert seqs[0] == 0 and seq_gaps(seqs) == 0 and len(seqs) > 1000  # every frame, no gap
    assert st1["recording"] == doc["recording"] and st1["connected"]
    assert st1["source"] == st0["source"] and st1["reconnects"] == st0["reconnects"]
    assert st1["source_kind"] == "serial" and st1["seq_gaps"] == 0 and st1["crc_errors"] == 0
    assert seen and all(c and s == st0["source"] and n == st0["reconnects"] and r == rec
                        for c, s, n, r in seen)
    print(f"\nOpenAPI walk: {len(calls)} calls over {len(ops)} operations during recording "
          f"{rec}: {size0} → {size1} bytes, {len(seqs)} frames, 0 SEQ gaps; status polled "
          f"{len(seen)} times: connected, same source, reconnects {st0['reconnects']}")


# -- the figure ------------------------------------------------------------------------------
@pytest.mark.slow
def test_figure_two_replays_beside_a_1_khz_live_flight(tmp_path):
    """Issue 19, "What it must show", first figure (``pytest -s -m slow`` prints it)."""
    import paho.mqtt.client  # noqa: F401 - the subscriber below

    require_program("mosquitto", "/usr/sbin/mosquitto")
    require_program("tshark")
    from test_asterix import tshark_fields, write_pcap
    from test_mqtt import Broker, Subscriber

    from radar_io.coordinates.transforms import load_site
    from radar_io.encoding.asterix_cat048 import decode_records
    from radar_io.encoding.tlm1 import TelemetryDecoder

    run_s = 20.0
    rec_dir = tmp_path / "data" / "recordings"
    rec_dir.mkdir(parents=True)
    times = write_flight(rec_dir / "earlier.rdrlog", REPLAY_FRAMES, seq0=REPLAY_SEQ0,
                         sr=REPLAY_SR)
    broker = Broker(tmp_path)
    broker.start()
    udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    udp.bind(("127.0.0.1", 0))
    udp.settimeout(0.2)
    grams: list[bytes] = []
    udp_halt = threading.Event()

    def receive() -> None:
        while not udp_halt.is_set():
            try:
                grams.append(udp.recv(65535))
            except TimeoutError:
                continue

    udp_thread = threading.Thread(target=receive, daemon=True)
    udp_thread.start()
    tlm = tmp_path / "uplink.tlm"
    pty = Pty()
    feeder = Feeder(pty)
    svc = serve(tmp_path, pty, f'path = "{spec_dir() / "paths" / "demo_track_radar.toml"}"\n'
                f'tlm_out = "{tlm}"\nasterix_out = "udp://127.0.0.1:{udp.getsockname()[1]}"\n'
                f'publish = "mqtt://127.0.0.1:{broker.port}/fig"\n')
    sub = Subscriber(broker.port, "fig")
    watch = StatusWatch(svc)
    live_ws = replay_a = replay_b = None
    try:
        svc.wait_ready()
        feeder.start()
        rec = wait_for(lambda: svc.get("/api/status")["recording"], what="the GO recording")
        source = svc.get("/api/status")["source"]
        watch.start()
        ws = f"ws://127.0.0.1:{svc.port}"
        live_ws = WsCollector(f"{ws}/ws/live?batch=1")
        live_ws.start()
        t0 = time.monotonic()
        code, a = call(svc.base, "POST", "/api/replays", {"recording": "earlier", "speed": 4.0})
        assert code == 201, a
        code, b = call(svc.base, "POST", "/api/replays", {"recording": "earlier", "speed": 1.0})
        assert code == 201, b
        replay_a = WsCollector(f"{ws}{a['ws']}?from=0&batch=1")
        replay_b = WsCollector(f"{ws}{b['ws']}?from=0&batch=1")
        replay_a.start()
        replay_b.start()
        bb = f"/api/replays/{b['id']}"
        script = [(2.0, "pause", None), (3.0, "seek", {"position_s": 12.0}),
                  (4.0, "step", {"n": 20}), (5.0, "resume", None)]  # B ends ~17 s in
        for at_s, op, body in script:
            time.sleep(max(0.0, t0 + at_s - time.monotonic()))
            code, doc = call(svc.base, "POST", f"{bb}/{op}", body)
            assert code == 200, (op, doc)
        time.sleep(max(0.0, t0 + run_s - time.monotonic()))
        state_a = svc.get(f"/api/replays/{a['id']}")
        state_b = svc.get(f"/api/replays/{b['id']}")
        sent = feeder.stop()
        wait_for(lambda: svc.get("/api/status")["frames"] >= sent, timeout_s=30,
                 what="the last live frames")
        time.sleep(0.5)  # the outputs' queues drain
        seen = watch.stop()  # before the recording is stopped on purpose, just below
        code, doc = call(svc.base, "POST", "/api/recordings/stop")
        assert code == 200 and doc["closed"] == rec
        status = svc.get("/api/status")
        sync_events = svc.get("/api/sync-events?limit=100000")
        live_msgs, msgs_a, msgs_b = live_ws.stop(), replay_a.stop(), replay_b.stop()
    finally:
        watch.halt.set()
        feeder.stop()
        for c in (live_ws, replay_a, replay_b):
            if c is not None:
                c.halt.set()
        svc.stop()
        pty.close()
        udp_halt.set()
        udp_thread.join(5)
        udp.close()
        sub.close()
        broker.stop()

    def replayed(seq: int) -> bool:
        return REPLAY_SEQ0 <= seq < REPLAY_SEQ0 + REPLAY_FRAMES

    # the live recording: every frame the pty sent, by SEQ
    seqs = recording_seqs(rec_dir / f"{rec}.rdrlog")
    missing = sent - len(set(seqs.tolist()))
    # the live outputs
    with sub.lock:
        mqtt_track = list(sub.track)
        mqtt_sync = list(sub.sync)
    mqtt_replayed = sum(replayed(m["seq"]) or m["sr_m"] == REPLAY_SR or "replay" in m
                        for m in mqtt_track)
    ws_replayed = sum(replayed(m["seq"]) or "replay" in m for m in live_msgs if "seq" in m)
    site = load_site(DEMO_SITE)
    probe = decode_bytes(independent.frame(sr=LIVE_SR, el=EL, az=AZ, sts=0x0005)
                         + independent.frame(seq=1, sr=REPLAY_SR, el=EL, az=AZ, sts=0x0005),
                         site=site)
    xr_live, xr_rep = (float(v) for v in probe["xr_m"])
    assert abs(xr_live - xr_rep) > 1000
    tlm_cols = TelemetryDecoder().feed(tlm.read_bytes())
    tlm_xr = np.asarray(tlm_cols["xr_m"])
    tlm_replayed = int(np.count_nonzero(np.abs(tlm_xr - xr_rep) < np.abs(tlm_xr - xr_live)))
    ast = decode_records(b"".join(grams))
    ast_replayed = int(np.count_nonzero(np.abs(ast["sr_m"] - REPLAY_SR) < 1000))
    pcap = tmp_path / "asterix.pcap"
    write_pcap(pcap, grams)
    shark = tshark_fields(pcap)
    sync_replayed = sum(replayed(e["seq"]) for e in sync_events) + \
        sum(replayed(e["seq"]) for e in mqtt_sync)
    # the replay websockets
    seq_a = [m["seq"] for m in msgs_a]
    seq_b = [m["seq"] for m in msgs_b]
    cut = next((k for k in range(1, len(seq_b)) if seq_b[k] != seq_b[k - 1] + 1), len(seq_b))
    figures = {
        "run_s": run_s, "live_frames_sent": sent, "recording_frames": len(seqs),
        "recording_missing_by_seq": missing, "recording_seq_gaps": seq_gaps(seqs),
        "status_polls": len(seen), "status_polls_connected_same_source": sum(
            c and s == source and n == 0 for c, s, n, _ in seen),
        "tlm1_frames": len(tlm_xr), "tlm1_replayed": tlm_replayed,
        "asterix_records": len(ast["sr_m"]), "asterix_replayed": ast_replayed,
        "asterix_records_tshark": len(shark["asterix.048_020_SIM"]),
        "mqtt_track": len(mqtt_track), "mqtt_replayed": mqtt_replayed,
        "ws_live": len(live_msgs), "ws_live_replayed": ws_replayed,
        "sync_events_live": len(sync_events), "sync_events_replayed": sync_replayed,
        "replay_a_msgs": len(msgs_a), "replay_a_state": {k: state_a[k] for k in (
            "speed", "position_s", "finished")},
        "replay_b_msgs": len(msgs_b), "replay_b_segments": [
            [seq_b[0], seq_b[cut - 1]], [seq_b[cut], seq_b[-1]]] if cut < len(seq_b) else None,
        "replay_b_state": {k: state_b[k] for k in ("speed", "paused", "position_s", "finished")},
    }
    print("\nissue 19 figure 1:", json.dumps(figures, indent=1))
    assert seqs.tolist() == list(range(sent)) and missing == 0
    odd = [x for x in seen if not (x[0] and x[1] == source and x[2] == 0 and x[3] == rec)]
    assert len(seen) >= 4 * run_s * 0.5 and not odd, (rec, odd)
    assert status["seq_gaps"] == 0 and status["crc_errors"] == 0 and status["reconnects"] == 0
    assert len(tlm_xr) > 100 and tlm_replayed == 0
    assert len(ast["sr_m"]) > 1000 and ast_replayed == 0 and (ast["sim"] == 0).all()
    assert len(shark["asterix.048_020_SIM"]) == len(ast["sr_m"])
    assert (shark["asterix.048_020_SIM"] == 0).all()  # live radar data: SIM = 0
    assert len(mqtt_track) > 1000 and mqtt_replayed == 0
    assert len(live_msgs) > 1000 and ws_replayed == 0
    assert len(sync_events) > 10 and sync_replayed == 0
    # replay A (speed 4): the whole recorded flight, in order, recorded t_ns, its id
    assert seq_a == list(range(REPLAY_SEQ0, REPLAY_SEQ0 + REPLAY_FRAMES))
    assert all(m["t_ns"] == recorded_t_ns(m["seq"], REPLAY_SEQ0, times)
               and m["replay"] == a["id"] for m in msgs_a)
    # replay B (speed 1): from the start until paused, then from 12 s (seek) to the end
    assert seq_b[:cut] == list(range(REPLAY_SEQ0, seq_b[cut - 1] + 1)) and cut > 1000
    assert seq_b[cut:] == list(range(REPLAY_SEQ0 + 12000, REPLAY_SEQ0 + REPLAY_FRAMES))
    assert all(m["t_ns"] == recorded_t_ns(m["seq"], REPLAY_SEQ0, times)
               and m["replay"] == b["id"] for m in msgs_b)
