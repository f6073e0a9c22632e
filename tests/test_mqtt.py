"""MQTT publishing through a real Mosquitto broker to a real QoS 1 subscriber.

The acquisition pipeline is the service's own (sim:// at 1 kHz → framer → decoder →
history → publish). ``RADAR_IO_MQTT_RUN_S`` sets the steady run's length (default 5 s;
60 for the figure in docs/interchange.md); run with ``-s`` to see the figures.
"""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import paho.mqtt.client as paho
import pytest
from conftest import ROOT

from radar_io.benchmarks.service_load import end_process
from radar_io.coordinates.transforms import load_site
from radar_io.errors import ConfigError
from radar_io.recording.recorder import Recorder
from radar_io.service.history import History
from radar_io.service.pipeline import Pipeline as ServicePipeline
from radar_io.sinks import open_sink
from radar_io.sinks.mqtt import MqttPublisher, parse_mqtt_url
from radar_io.wirespec.frame import load_spec

MOSQUITTO = shutil.which("mosquitto") or ("/usr/sbin/mosquitto"
                                          if os.path.exists("/usr/sbin/mosquitto") else None)
pytestmark = pytest.mark.skipif(MOSQUITTO is None,
                                reason="mosquitto (Debian package mosquitto) is not installed")


def wait_for(cond, timeout_s: float, step_s: float = 0.02) -> bool:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(step_s)
    return bool(cond())


class Broker:
    """A Mosquitto broker on 127.0.0.1 and a free port; restartable on the same port."""

    def __init__(self, tmp: Path, extra: str = "allow_anonymous true\n") -> None:
        self.tmp, self.extra = tmp, extra
        self.port = 0
        self.proc: subprocess.Popen | None = None

    def start(self, port: int | None = None) -> None:
        for _ in range(5):  # another process may grab the free port first: retry
            if port is None:
                with socket.socket() as s:
                    s.bind(("127.0.0.1", 0))
                    self.port = s.getsockname()[1]
            conf = self.tmp / "mosquitto.conf"
            conf.write_text(f"listener {self.port} 127.0.0.1\n{self.extra}persistence false\n")
            with open(self.tmp / "mosquitto.log", "ab") as log:
                self.proc = subprocess.Popen([MOSQUITTO, "-c", str(conf)], stdout=log,
                                             stderr=subprocess.STDOUT)
            if wait_for(self._listening, 10):
                return
            self.stop()
            if port is not None:
                time.sleep(0.2)
        raise RuntimeError(f"mosquitto did not start: {(self.tmp / 'mosquitto.log').read_text()}")

    def _listening(self) -> bool:
        if self.proc is None or self.proc.poll() is not None:
            return False
        try:
            socket.create_connection(("127.0.0.1", self.port), 0.2).close()
            return True
        except OSError:
            return False

    def stop(self) -> None:
        if self.proc is not None:
            end_process(self.proc, 5.0)
            self.proc = None


@pytest.fixture
def broker(tmp_path):
    b = Broker(tmp_path)
    b.start()
    try:
        yield b
    finally:
        b.stop()


class Subscriber:
    """A paho QoS 1 subscriber to PREFIX/#; reconnects and resubscribes by itself."""

    def __init__(self, port: int, prefix: str) -> None:
        self.track: list[dict] = []
        self.status: list[dict] = []
        self.sync: list[dict] = []
        self.lock = threading.Lock()
        self.prefix = prefix
        c = paho.Client(paho.CallbackAPIVersion.VERSION2, clean_session=True)
        c.reconnect_delay_set(0.1, 0.5)
        c.on_connect = lambda cl, *_: cl.subscribe(f"{prefix}/#", qos=1)
        c.on_message = self._on_message
        c.connect("127.0.0.1", port, keepalive=10)
        c.loop_start()
        self.client = c

    def _on_message(self, _c, _u, msg) -> None:
        doc = json.loads(msg.payload)
        with self.lock:
            if msg.topic == f"{self.prefix}/track":
                assert isinstance(doc, list)
                self.track.extend(doc)
            elif msg.topic == f"{self.prefix}/status":
                self.status.append(doc)
            elif msg.topic == f"{self.prefix}/sync":
                self.sync.append(doc)

    def seqs(self) -> list[int]:
        with self.lock:
            return [m["msg_seq"] for m in self.track]

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()


def _noop(items) -> None:
    return None


class Pipeline:
    """The service's acquisition (sim:// at 1 kHz) publishing into an MqttPublisher."""

    def __init__(self, tmp: Path, url: str) -> None:
        spec = load_spec()
        site = load_site(ROOT / "firmware_specs" / "sites" / "demo.toml")
        self.history = History(512 << 20)   # bytes: all of a 60 s run
        self.recorder = Recorder(tmp / "data", spec, site, "sim://", auto="manual")
        self.submit_max_s = self.noop_max_s = self.submit_total_s = 0.0
        self.submits = 0
        self.pub = MqttPublisher(url, status=self.status,
                                 sync_events=lambda: self.recorder.sync_events)
        self.acq = ServicePipeline("sim://?rate_hz=1000&sync_every_s=1&seed=3", spec,
                                   self.history, self.publish, recorder=self.recorder, site=site)

    def publish(self, items) -> None:      # what Service wires: hub + MQTT
        t0 = time.perf_counter()
        _noop(items)                       # baseline: the same call doing nothing
        t1 = time.perf_counter()
        self.pub.submit(items)
        t2 = time.perf_counter()
        self.noop_max_s = max(self.noop_max_s, t1 - t0)
        self.submit_max_s = max(self.submit_max_s, t2 - t1)
        self.submit_total_s += t2 - t1
        self.submits += 1

    def figures(self) -> str:
        return (f"submit mean {self.submit_total_s / max(self.submits, 1) * 1e6:.1f} us, "
                f"max {self.submit_max_s * 1e3:.3f} ms (a no-op call in the same place: max "
                f"{self.noop_max_s * 1e3:.3f} ms)")

    def status(self) -> dict:
        return {**self.acq.status(), "publish": {"mqtt": self.pub.stats()}}

    def start(self) -> None:
        sys.setswitchinterval(0.0005)   # as create_app() does for the live service
        self.pub.start()
        self.acq.start()

    def stop(self) -> None:
        self.acq.stop()
        self.pub.close()
        self.recorder.close()
        sys.setswitchinterval(0.005)


def test_url_options_and_credentials_never_in_the_url(monkeypatch):
    t = parse_mqtt_url("mqtt://broker.range:1884/site-a/radar1?qos=0")
    assert (t.host, t.port, t.prefix, t.qos, t.tls) == ("broker.range", 1884, "site-a/radar1", 0, False)
    assert parse_mqtt_url("mqtts://b/x").port == 8883 and parse_mqtt_url("mqtt://b/x").qos == 1
    for bad, what in (("mqtt://u:secret@b:1883/x", "not in the URL"), ("mqtt://b/x?qos=2", "qos"),
                      ("mqtt://b/a/#", "must not hold"), ("mqtt://b/x?retain=1", "unknown option"),
                      ("http://b/x", "expected mqtt")):
        with pytest.raises(ConfigError, match=what) as ei:
            parse_mqtt_url(bad)
        assert "secret" not in str(ei.value)
    monkeypatch.setenv("RADAR_IO_MQTT_USER", "radar")
    monkeypatch.setenv("RADAR_IO_MQTT_PASSWORD", "s3cret-pw")
    pub = MqttPublisher("mqtt://127.0.0.1:1/p")
    assert "s3cret-pw" not in json.dumps(pub.stats()) and "s3cret-pw" not in repr(pub.url)


def test_one_khz_through_the_broker_every_msg_seq_once(broker, tmp_path):
    run_s = float(os.environ.get("RADAR_IO_MQTT_RUN_S", "5"))
    sub = Subscriber(broker.port, "site-a")
    pipe = Pipeline(tmp_path, f"mqtt://127.0.0.1:{broker.port}/site-a?qos=1")
    try:
        pipe.start()
        assert wait_for(lambda: pipe.pub.connected, 10)
        time.sleep(run_s)
        pipe.acq.stop()
        last = pipe.history.last_seq
        assert wait_for(lambda: len(sub.seqs()) >= last, 20)
        pipe.stop()
        late = Subscriber(broker.port, "site-a")   # retained status: the last word is offline
        assert wait_for(lambda: late.status, 5)
        late.close()
    finally:
        pipe.stop()
        sub.close()
    seqs = sub.seqs()
    assert seqs == list(range(1, last + 1))       # every msg_seq exactly once, in order
    assert last >= 0.5 * 1000 * run_s             # the source really ran near 1 kHz
    hist = {seq: json.loads(text) for seq, text in pipe.history.since(0)}
    for m in sub.track:                           # values match /api/track (the history)
        assert m == hist[m["msg_seq"]]
    st = pipe.pub.stats()
    assert st["dropped"] == 0 and st["published"] == last and st["reconnects"] == 0
    assert late.status[-1] == {"online": False}
    online = [s for s in sub.status if s.get("online")]
    assert len(online) >= run_s - 1 and online[-1]["frames"] > 0
    assert "mqtt" in online[-1]["publish"]
    edges = [e.msg_seq for e in pipe.recorder.sync_events]
    assert len(edges) >= run_s - 2 and [e["msg_seq"] for e in sub.sync] == edges
    print(f"\nMQTT steady: {run_s:.0f} s, {last} msgs ({last / run_s:.0f}/s), "
          f"received {len(seqs)} once each, dropped 0, status {len(online)}, sync {len(edges)}, "
          + pipe.figures())


def test_broker_restart_resumes_and_counts_the_gap(broker, tmp_path):
    sub = Subscriber(broker.port, "site-b")
    pipe = Pipeline(tmp_path, f"mqtt://127.0.0.1:{broker.port}/site-b?qos=1")
    try:
        pipe.start()
        assert wait_for(lambda: pipe.pub.connected and len(sub.seqs()) > 500, 15)
        seq_down = pipe.history.last_seq
        frames_down = pipe.acq.status()["frames"]
        broker.stop()
        time.sleep(3.0)
        frames_outage = pipe.acq.status()["frames"] - frames_down
        seq_up = pipe.history.last_seq
        t_up = time.monotonic()
        broker.start(broker.port)
        assert wait_for(lambda: max(sub.seqs(), default=0) > seq_up, 15)
        resumed_s = time.monotonic() - t_up
        time.sleep(1.0)
        pipe.acq.stop()
        last = pipe.history.last_seq
        assert wait_for(lambda: max(sub.seqs(), default=0) >= last, 15)
    finally:
        pipe.stop()
        sub.close()
    st = pipe.pub.stats()
    assert st["reconnects"] >= 1 and st["dropped"] > 0 and st["connected"] is False
    assert st["last_error"] in ("cannot connect to the broker",) or "lost" in st["last_error"]
    assert frames_outage > 0 and pipe.acq.processing_errors == 0   # acquisition went on
    got = sub.seqs()
    first_after = min(s for s in got if s > seq_up)
    # outside the outage window every msg_seq arrives exactly once
    before = [s for s in got if s <= seq_down - 1000]
    after = [s for s in got if s >= first_after]
    assert before == list(range(1, seq_down - 999))
    assert after == list(range(first_after, last + 1))
    missing = last - len(set(got))
    assert 0 < missing <= st["dropped"] + 1000     # the gap is counted as dropped
    print(f"\nMQTT restart: broker down 3.0 s, publishing resumed {resumed_s:.2f} s after the "
          f"broker restarted, dropped {st['dropped']} msgs, missing {missing}, acquisition "
          f"frames during the outage {frames_outage}, " + pipe.figures())


def test_registry_sink_publishes_rows(broker):
    import numpy as np

    from radar_io.decoding.measurement import MeasurementBatch

    sub = Subscriber(broker.port, "reg")
    sink = open_sink("mqtt", f"mqtt://127.0.0.1:{broker.port}/reg?qos=0")
    try:
        assert wait_for(lambda: sink.stats()["connected"], 10)
        sink.write({"msg_seq": np.array([7, 8]), "sr_m": np.array([1000.0, np.nan])})
        # a decoded batch (what decode_bytes returns) is columns too, though not a Mapping
        assert sink.write(MeasurementBatch({"msg_seq": np.array([9]),
                                            "sr_m": np.array([1200.0])})) == 1
        assert wait_for(lambda: len(sub.track) == 3, 10)
    finally:
        sink.close()
        sub.close()
    assert sub.track == [{"msg_seq": 7, "sr_m": 1000.0}, {"msg_seq": 8, "sr_m": None},
                         {"msg_seq": 9, "sr_m": 1200.0}]


def test_mqtts_with_user_and_password_from_the_environment(tmp_path, monkeypatch, caplog):
    openssl, passwd = shutil.which("openssl"), shutil.which("mosquitto_passwd")
    if not openssl or not passwd:
        pytest.skip("openssl / mosquitto_passwd (Debian packages openssl, mosquitto) missing")
    cert, key, pwfile = tmp_path / "cert.pem", tmp_path / "key.pem", tmp_path / "passwd"
    subprocess.run([openssl, "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "1",
                    "-keyout", str(key), "-out", str(cert), "-subj", "/CN=127.0.0.1",
                    "-addext", "subjectAltName=IP:127.0.0.1"], check=True, capture_output=True)
    subprocess.run([passwd, "-b", "-c", str(pwfile), "site-a", "s3cret-pw"], check=True,
                   capture_output=True)
    # started as root, mosquitto would drop to its own user, who cannot read pytest's tmp dir
    as_root = "user root\n" if os.geteuid() == 0 else ""
    b = Broker(tmp_path, f"{as_root}certfile {cert}\nkeyfile {key}\npassword_file {pwfile}\n"
                         "allow_anonymous false\n")
    b.start()
    good = bad = None
    try:
        monkeypatch.setenv("RADAR_IO_MQTT_USER", "site-a")
        monkeypatch.setenv("RADAR_IO_MQTT_PASSWORD", "s3cret-pw")
        good = MqttPublisher(f"mqtts://127.0.0.1:{b.port}/range/site-a", ca_file=str(cert),
                             status_period_s=0.2)
        good.start()
        assert wait_for(lambda: good.connected, 15)
        good.submit([(1, '{"msg_seq":1}'), (2, '{"msg_seq":2}')])
        assert wait_for(lambda: good.published == 2, 10)    # acknowledged over TLS
        monkeypatch.setenv("RADAR_IO_MQTT_PASSWORD", "wrong-pw")
        bad = MqttPublisher(f"mqtts://127.0.0.1:{b.port}/range/site-a", ca_file=str(cert))
        bad.start()
        assert wait_for(lambda: bad.last_error is not None, 15)
        assert not bad.connected and "refused" in bad.last_error
    finally:
        for p in (good, bad):
            if p is not None:
                p.close()
        b.stop()
    shown = caplog.text + json.dumps(good.stats()) + json.dumps(bad.stats()) + good.url
    assert "s3cret-pw" not in shown and "wrong-pw" not in shown


def test_service_wiring_publishes_what_api_track_serves(broker, tmp_path):
    """The live service (real uvicorn on port 0) with ``publish`` and ``asterix_out``
    configured: MQTT track == /api/track, status retained, ASTERIX datagrams."""
    import urllib.request

    import numpy as np
    import uvicorn

    from radar_io.encoding.asterix_cat048 import RHO_LSB_M, THETA_LSB_DEG, decode_records
    from radar_io.service.app import build_app
    from radar_io.service.config import ServiceConfig

    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.settimeout(10)
    cfg = ServiceConfig(source="sim://?rate_hz=1000&sync_every_s=1&go_delay_s=0.5",
                        data_dir=str(tmp_path / "data"), auto_record="manual",
                        publish=f"mqtt://127.0.0.1:{broker.port}/svc?qos=1",
                        asterix_out=f"udp://127.0.0.1:{rx.getsockname()[1]}")
    app = build_app(cfg)
    svc = app.state.service
    pub = svc.mqtt
    sub = Subscriber(broker.port, "svc")
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=0, log_level="warning"))
    thread = threading.Thread(target=server.run, daemon=True)
    grams: list[bytes] = []
    try:
        thread.start()                       # the lifespan starts the publisher
        assert wait_for(lambda: server.started, 20)
        port = server.servers[0].sockets[0].getsockname()[1]
        assert wait_for(lambda: len(sub.seqs()) >= 2500 and sub.status and sub.sync, 30)
        first = min(sub.seqs())              # what came before the broker said hello is dropped
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/track?since={first - 1}"
                                    "&limit=2000", timeout=10) as r:
            api = json.loads(r.read())["messages"]
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/status", timeout=10) as r:
            status = json.loads(r.read())
        while len(grams) < 200:              # the oldest datagrams, kept by the kernel
            grams.append(rx.recv(65535))
    finally:
        server.should_exit = True            # the lifespan closes the publisher
        thread.join(15)
        wait_for(lambda: sub.status[-1:] == [{"online": False}], 10)
        sub.close()
        rx.close()
    got = {m["msg_seq"]: m for m in sub.track}
    assert len(got) == len(sub.track)                       # each msg_seq once
    assert len(api) == 2000 and all(got[m["msg_seq"]] == m for m in api)
    online = [s for s in sub.status if s.get("online")]
    assert online and online[-1]["instance"] == status["instance"]
    assert online[-1]["publish"]["mqtt"]["connected"] is True
    assert status["publish"]["mqtt"]["published"] > 0
    assert sub.status[-1] == {"online": False} and not pub.connected   # clean close
    assert status["uplink"]["asterix"]["records"] > 0      # the worker's stats on /api/status
    assert sub.sync[0]["msg_seq"] == svc.recorder.sync_events[0].msg_seq
    recs = decode_records(b"".join(grams))
    hist = [json.loads(text) for _, text in svc.history.since(0)]
    valid = [m for m in hist if m["rx_good"] == 1 and m["go"] == 1]
    n = len(recs["sr_m"])
    assert n >= 200 and (recs["sim"] == 1).all() and (recs["sic"] == svc.site.asterix_sic).all()
    sr = np.array([m["sr_c_m"] for m in valid[:n]])
    az = np.array([m["az_c_deg"] for m in valid[:n]])
    assert np.abs(recs["sr_m"] - sr).max() <= RHO_LSB_M
    assert np.abs((recs["az_deg"] - az + 180) % 360 - 180).max() <= THETA_LSB_DEG


def test_serve_refuses_a_bad_publish_url_in_one_line(tmp_path):
    from conftest import run_cli

    res = run_cli("serve", "--port", "0", "--data-dir", str(tmp_path),
                  "--publish", "mqtt://radar:pw@127.0.0.1:1883/x", timeout=60)
    err = res.stderr.decode().strip()
    assert res.returncode == 2 and "\n" not in err and "not in the URL" in err and "pw" not in err


def test_ground_replay_outputs_say_the_data_is_not_live(broker, tmp_path):
    """``serve --source replay://FILE`` drives the outputs from a recording: MQTT track
    messages carry ``"replay": true``, ASTERIX I048/020 SIM = 1 (read by tshark), and
    /api/status says ``source_kind: "replay"``."""
    import urllib.request

    import uvicorn
    from conftest import require_program
    from test_asterix import tshark_fields, write_pcap

    from radar_io.encoding.asterix_cat048 import decode_records
    from radar_io.recording.rdrlog import RecordingWriter
    from radar_io.service.app import build_app
    from radar_io.service.config import ServiceConfig
    from radar_io.simulation.radar import FlightScript, RadarSimulator, SimConfig

    require_program("tshark")
    data, _ = RadarSimulator(FlightScript(), SimConfig(seed=4, go_delay_s=0.0,
                                                       ng_per_min=0)).generate(4000)
    rec = tmp_path / "flight.rdrlog"
    with RecordingWriter(rec, load_spec()) as w:
        for k in range(0, len(data), 480):   # 20 frames per chunk, 20 ms apart
            w.write(data[k:k + 480], 1_700_000_000_000_000_000 + k * 41_667, k * 41_667)
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.settimeout(10)
    cfg = ServiceConfig(source=f"replay://{rec}?speed=2", data_dir=str(tmp_path / "data"),
                        site=str(ROOT / "firmware_specs" / "sites" / "demo.toml"),
                        auto_record="manual", publish=f"mqtt://127.0.0.1:{broker.port}/gr",
                        asterix_out=f"udp://127.0.0.1:{rx.getsockname()[1]}")
    app = build_app(cfg)
    sub = Subscriber(broker.port, "gr")
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=0, log_level="warning"))
    thread = threading.Thread(target=server.run, daemon=True)
    grams: list[bytes] = []
    try:
        thread.start()
        assert wait_for(lambda: server.started, 20)
        port = server.servers[0].sockets[0].getsockname()[1]
        assert wait_for(lambda: len(sub.seqs()) >= 1000, 30)
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/status", timeout=10) as r:
            status = json.loads(r.read())
        while len(grams) < 50:
            grams.append(rx.recv(65535))
    finally:
        server.should_exit = True
        thread.join(15)
        sub.close()
        rx.close()
    assert status["source_kind"] == "replay" and status["mode"] == "replay"
    with sub.lock:
        track = list(sub.track)
    assert len(track) >= 1000 and all(m["replay"] is True for m in track)
    pcap = tmp_path / "ground.pcap"
    write_pcap(pcap, grams)
    got = tshark_fields(pcap)
    n = len(got["asterix.048_020_SIM"])
    assert n > 100 and (got["asterix.048_020_SIM"] == 1).all()
    assert n == len(decode_records(b"".join(grams))["sim"])   # tshark read every record
