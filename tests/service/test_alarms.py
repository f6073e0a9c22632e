"""Limit alarms: the pure engine fed messages with times, the config checks, and a real
``radar-io serve`` (REST, websocket push, acknowledge with the token, event log)."""

from __future__ import annotations

import asyncio
import json
import math
import time
import urllib.error
import urllib.request

import pytest

from radar_io.errors import ConfigError, NotFoundError
from radar_io.service.alarms import AlarmEngine, LimitRule, alarm_message, parse_alarm_config, read_events

T0 = 1_800_000_000.0


def _msgs(values, t0=T0, dt=0.1, column="h_m", seq0=100):
    return [{column: v, "t_ns": int((t0 + k * dt) * 1e9), "seq": seq0 + k}
            for k, v in enumerate(values)]


def _engine(**kw):
    changes, events = [], []
    e = AlarmEngine(on_change=changes.append, on_event=events.append, **kw)
    return e, changes, events


def test_limit_raises_after_for_s_and_clears_when_back_inside():
    e, changes, events = _engine(rules=[LimitRule("hi", "too high", "h_m", None, 100.0, 0.5)],
                                 builtin={})
    # out for 0.4 s (5 samples at 0.1 s), then back: never raised
    e.feed(_msgs([150, 150, 150, 150, 150, 90]))
    assert e.active() == [] and events == []
    # out from t=1.0 s: raised at the sample 0.5 s later (seq 100 + 15)
    e.feed(_msgs([150] * 8, t0=T0 + 1.0, seq0=110))
    (a,) = e.active()
    assert (a["id"], a["column"], a["limit"], a["acknowledged"]) == ("hi", "h_m", 100.0, False)
    assert a["since"] == pytest.approx(T0 + 1.5) and a["value"] == 150
    assert events[-1]["action"] == "raise" and events[-1]["seq"] == 115
    assert events[-1]["t_s"] == pytest.approx(T0 + 1.5)
    # NaN / None (NG) samples neither clear nor restart it
    e.feed(_msgs([math.nan, None], t0=T0 + 2.0, seq0=120))
    assert len(e.active()) == 1
    e.feed(_msgs([160, 99.5], t0=T0 + 2.2, seq0=122))
    assert e.active() == []
    assert [ev["action"] for ev in events] == ["raise", "clear"]
    assert events[-1]["seq"] == 123 and events[-1]["duration_s"] == pytest.approx(0.8, abs=1e-6)
    assert [len(c) for c in changes] == [1, 0]


def test_min_limit_and_immediate_raise():
    e, _, events = _engine(rules=[LimitRule("lo", "low", "sr_m", 500.0, None, 0.0)], builtin={})
    e.feed(_msgs([600, 499.9], column="sr_m"))
    assert e.active()[0]["limit"] == 500.0 and events[0]["seq"] == 101


def test_acknowledge_keeps_the_alarm_until_it_clears():
    e, changes, events = _engine(rules=[LimitRule("hi", "high", "h_m", None, 1.0)], builtin={})
    e.feed(_msgs([2.0]))
    assert e.acknowledge("hi")["acknowledged"] is True
    assert e.active()[0]["acknowledged"] is True and events[-1]["action"] == "ack"
    assert changes[-1][0]["acknowledged"] is True
    e.acknowledge("hi")  # twice: no second event
    assert [ev["action"] for ev in events] == ["raise", "ack"]
    with pytest.raises(NotFoundError):
        e.acknowledge("nope")
    e.feed(_msgs([0.5], t0=T0 + 1))
    assert e.active() == []
    e.feed(_msgs([3.0], t0=T0 + 2))  # a new crossing is a new, unacknowledged alarm
    assert e.active()[0]["acknowledged"] is False


def test_builtin_alarms_from_the_status():
    e, _, events = _engine()
    ok = {"mode": "live", "connected": True, "last_frame_age_s": 0.01, "crc_errors": 0,
          "recording_error": None, "uplink": {"tlm": {"connected": True}},
          "disk_free_bytes": 50e9}
    e.check_status(ok, T0)
    assert e.active() == []
    bad = {**ok, "last_frame_age_s": 3.0, "crc_errors": 50, "recording_error": "disk full",
           "uplink": {"tlm": {"connected": False}}, "disk_free_bytes": 1e8}
    e.check_status(bad, T0 + 10)
    got = {a["id"]: a for a in e.active()}
    assert set(got) == {"source_stale", "crc_rate", "recording_error", "uplink", "low_disk"}
    assert got["crc_rate"]["value"] == pytest.approx(5.0) and got["crc_rate"]["limit"] == 1.0
    assert got["source_stale"]["value"] == 3.0
    assert got["recording_error"]["value"] == "disk full"
    assert got["uplink"]["value"] == "tlm not connected"
    assert got["low_disk"]["limit"] == 1e9
    # back to normal except the source: only "source stale" stays
    e.check_status({**ok, "connected": False, "last_frame_age_s": 20.0, "crc_errors": 50}, T0 + 30)
    assert [a["id"] for a in e.active()] == ["source_stale"]
    assert {ev["id"] for ev in events if ev["action"] == "clear"} == {
        "crc_rate", "recording_error", "uplink", "low_disk"}


def test_source_stale_before_the_first_frame_waits_stale_s():
    e, _, _ = _engine()
    e.check_status({"last_frame_age_s": None}, T0)
    e.check_status({"last_frame_age_s": None}, T0 + 0.5)
    assert e.active() == []
    e.check_status({"last_frame_age_s": None}, T0 + 1.25)
    assert e.active()[0]["id"] == "source_stale" and e.active()[0]["value"] == 1.25


def test_builtin_limits_from_config_and_switched_off():
    rules, builtin = parse_alarm_config([
        {"builtin": "crc_rate", "max": 10.0}, {"builtin": "low_disk", "enabled": False},
        {"column": "dz_m", "min": -30, "max": 30, "for_s": 0.5, "name": "glide path"}])
    assert builtin["crc_rate"] == 10.0 and builtin["low_disk"] is None
    assert rules == [LimitRule("limit:dz_m", "glide path", "dz_m", -30.0, 30.0, 0.5)]
    e, _, _ = _engine(rules=rules, builtin=builtin)
    e.check_status({"crc_errors": 0, "disk_free_bytes": 0}, T0)
    e.check_status({"crc_errors": 50, "disk_free_bytes": 0}, T0 + 10)  # 5/s < 10/s; disk off
    assert e.active() == []


@pytest.mark.parametrize("entry, needle", [
    ({"column": "h_m"}, "alarms[0]: give min, max or both"),
    ({"column": "h_m", "max": "high"}, "alarms[0]: max must be a finite number"),
    ({"column": "h_m", "min": 5, "max": 1}, "alarms[0]: min 5.0 is above max 1.0"),
    ({"max": 1}, "alarms[0]: column (a decoded column name) is required"),
    ({"column": "h_m", "max": 1, "colour": "red"}, "alarms[0]: unknown key(s) colour"),
    ({"column": "hh_m", "max": 1}, "alarms[0]: column 'hh_m' is not a decoded column"),
    ({"builtin": "coffee"}, "alarms[0]: builtin 'coffee' is not one of"),
    ({"column": "h_m", "max": 1, "for_s": -1}, "alarms[0]: for_s must be >= 0"),
])
def test_bad_config_names_the_entry_and_the_field(entry, needle):
    with pytest.raises(ConfigError) as exc:
        parse_alarm_config([entry], "cfg.toml", columns=("h_m", "sr_m"))
    assert str(exc.value).startswith("cfg.toml: ") and needle in str(exc.value)


def test_websocket_message_has_no_nan():
    doc = json.loads(alarm_message([{"id": "source_stale", "value": math.inf, "limit": 1.0}]))
    assert doc == {"type": "alarm", "alarms": [{"id": "source_stale", "value": None,
                                                "limit": 1.0}]}


# ------------------------------------------------------------------------ real server
TOKEN = "alarm-token"


@pytest.fixture(scope="module")
def svc(tmp_path_factory):
    from radar_io.benchmarks.service_load import ServeProcess

    d = tmp_path_factory.mktemp("alarms")
    cfg = d / "service.toml"
    # the simulated flight is at 600 m: "h_m above 100 m" raises at once; RX GOOD = 1 raises
    # on good samples and clears on the NG dropouts (many per minute)
    cfg.write_text('''
[[alarms]]
column = "h_m"
max = 100.0
for_s = 0.2
name = "height above 100 m"

[[alarms]]
id = "good"
column = "rx_good"
max = 0.5
name = "receiver good"
''')
    s = ServeProcess("sim://?go_delay_s=0.3&ng_per_min=120&sync_every_s=1", d / "data",
                     extra=("--config", str(cfg), "--auto-record", "always"),
                     env={"RADAR_IO_TOKEN": TOKEN})
    s.data = d / "data"
    with s:  # stopped even when it never becomes ready
        yield s


def _call(svc, method, path, token=TOKEN):
    headers = {"Authorization": f"Bearer {token}"} if token else {}
    req = urllib.request.Request(svc.base + path, method=method, headers=headers)
    try:
        with urllib.request.urlopen(req, timeout=30) as r:
            return r.status, r.headers.get("content-type"), r.read()
    except urllib.error.HTTPError as e:
        return e.code, e.headers.get("content-type"), e.read()


def _wait(pred, timeout_s=15.0):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        v = pred()
        if v:
            return v
        time.sleep(0.1)
    raise AssertionError("timed out")


def test_alarms_on_rest_ack_with_token_and_event_log(svc):
    def active():
        return {a["id"]: a for a in json.loads(_call(svc, "GET", "/api/alarms")[2])["alarms"]}

    got = _wait(lambda: active().get("limit:h_m"))
    assert set(got) == {"id", "name", "column", "value", "limit", "since", "since_utc",
                        "acknowledged"}
    assert got["value"] > 100.0 and got["limit"] == 100.0 and not got["acknowledged"]
    assert abs(got["since"] - time.time()) < 60
    assert _call(svc, "POST", "/api/alarms/limit:h_m/ack", token=None)[0] == 401
    assert _call(svc, "POST", "/api/alarms/limit:h_m/ack", token="wrong")[0] == 403
    assert _call(svc, "POST", "/api/alarms/nope/ack")[0] == 404
    code, _, body = _call(svc, "POST", "/api/alarms/limit:h_m/ack")
    assert code == 200 and json.loads(body)["acknowledged"] is True
    assert active()["limit:h_m"]["acknowledged"] is True
    # the recording's event log: the ack, and raises and clears of "good" with SEQ and time
    rec_dir = svc.data / "recordings"

    def log():
        evs = [e for p in rec_dir.glob("*.events.jsonl") for e in read_events(p)
               if e["kind"] == "alarm"]  # beside go / sync / clock_step events
        acts = {(e["id"], e["action"]) for e in evs}
        return evs if {("limit:h_m", "ack"), ("good", "raise"), ("good", "clear")} <= acts else None

    evs = _wait(log, 30)
    for e in evs:
        assert isinstance(e["seq"], int) and 0 <= e["seq"] < 65536, e
        assert e["time_utc"].endswith("Z") and e["recording"]
        assert isinstance(e["t_ns"], int) and isinstance(e["mono_ns"], int)
    assert any(e["action"] in ("raise", "active") and e["id"] == "limit:h_m" for e in evs)


def test_alarm_changes_are_pushed_on_the_websocket(svc):
    import websockets

    async def main():
        seen = []
        async with websockets.connect(svc.base.replace("http", "ws") + "/ws/live?max_hz=5") as ws:
            deadline = time.monotonic() + 20
            while time.monotonic() < deadline and len(seen) < 2:
                doc = json.loads(await asyncio.wait_for(ws.recv(), 20))
                if doc.get("type") == "alarm":
                    seen.append(doc)
        return seen

    seen = asyncio.run(main())
    assert len(seen) == 2  # "good" raised and cleared by NG dropouts, even on a decimated stream
    for doc in seen:
        assert all({"id", "name", "value", "limit", "since", "acknowledged"} <= set(a)
                   for a in doc["alarms"])
    assert any(a["id"] == "limit:h_m" for a in seen[0]["alarms"])


def test_report_endpoint_html_and_pdf(svc):
    recs = _wait(lambda: list(json.loads(_call(svc, "GET", "/api/recordings")[2])))
    rid = recs[0]["id"]
    time.sleep(1.0)
    code, ctype, body = _call(svc, "GET", f"/api/recordings/{rid}/report")
    assert code == 200 and ctype.startswith("text/html")
    # the flight figures (4) and the best-estimate-of-trajectory page's (3)
    assert body.count(b"data:image/png;base64,") == 7 and b"Sync events (" in body
    code, ctype, body = _call(svc, "GET", f"/api/recordings/{rid}/report?format=pdf")
    assert code == 200 and ctype == "application/pdf" and body.startswith(b"%PDF-")
    assert _call(svc, "GET", f"/api/recordings/{rid}/report?format=doc")[0] == 422
    assert _call(svc, "GET", "/api/recordings/none-such/report")[0] == 404


def test_serve_refuses_a_bad_alarm_entry_in_one_line(tmp_path):
    from conftest import run_cli

    cfg = tmp_path / "bad.toml"
    cfg.write_text('[[alarms]]\ncolumn = "height_m"\nmax = 100.0\n')
    r = run_cli("serve", "--config", str(cfg), "--port", "0", "--data-dir", str(tmp_path / "d"),
                timeout=60)
    err = r.stderr.decode().strip()
    assert r.returncode == 2 and len(err.splitlines()) == 1, err
    assert "alarms[0]: column 'height_m' is not a decoded column" in err


def test_a_flapping_limit_leaves_one_alarm_state_waiting_per_client(tmp_path):
    """A range limit flapping at its threshold for 3 s (a frame each ms over a pty, about
    1000 alarm changes/s): a ``max_hz=25`` client that reads and one that never reads each
    hold at most one alarm state waiting, the reader gets alarms at about its own rate, and
    the last alarm message it receives is the current state."""
    import threading

    import independent
    import websockets

    from radar_io.benchmarks.service_load import Pty, _stalled

    from .liveserver import live_server, service_config

    pty = Pty()
    cfg = service_config(tmp_path, source=pty.path, auto_record="manual",
                         alarms=[{"column": "sr_m", "max": 5000.0, "name": "range"},
                                 {"builtin": "source_stale", "enabled": False},
                                 {"builtin": "low_disk", "enabled": False}])
    flap_s = 3.0
    with live_server(cfg) as srv:
        hub = srv.app.state.service.hub
        waiting: list[int] = []
        stop_sampling = threading.Event()

        def sample() -> None:  # the most alarm states any client has waiting, every 5 ms
            while not stop_sampling.wait(0.005):
                waiting.append(max((len(c.events) for c in list(hub.clients)), default=0))

        def flap() -> None:  # 4990 / 5010 m alternately for flap_s, then 5010 m (raised)
            t0 = time.monotonic()
            k = 0
            while (elapsed := time.monotonic() - t0) < flap_s + 0.3:
                sr = 5010 if elapsed >= flap_s or k % 2 else 4990
                pty.write(independent.frame(seq=k, tod=k * 10, sr=sr, sts=0x0004))
                k += 1
                time.sleep(0.001)

        async def main() -> list[dict]:
            url = srv.base.replace("http", "ws") + "/ws/live?max_hz=25"
            done, ready = asyncio.Event(), asyncio.Event()
            stall = asyncio.create_task(_stalled(url, done, ready, [0, 1]))
            await ready.wait()
            got: list[dict] = []
            async with websockets.connect(url) as ws:
                writer = asyncio.create_task(asyncio.to_thread(flap))
                t_end = time.monotonic() + 30.0
                while time.monotonic() < t_end:
                    try:
                        doc = json.loads(await asyncio.wait_for(ws.recv(), 0.2))
                    except TimeoutError:
                        continue
                    if doc.get("type") == "alarm":
                        got.append(doc)
                    if writer.done() and t_end - time.monotonic() > 1.0:
                        t_end = time.monotonic() + 1.0  # what is still on its way
                await writer
            done.set()
            await stall
            return got

        sampler = threading.Thread(target=sample)
        sampler.start()
        try:
            got = asyncio.run(main())
        finally:
            stop_sampling.set()
            sampler.join()
            pty.close()
        current = srv.get("/api/alarms")["alarms"]
    changes = [e for e in srv.app.state.service.alarms.events if e["action"] in ("raise", "clear")]
    assert len(changes) > 500, len(changes)  # it did flap, hundreds of times a second
    assert max(waiting) <= 1
    assert 10 <= len(got) <= 25 * (flap_s + 1.5), len(got)  # about max_hz, not 1000/s
    assert [a["id"] for a in current] == ["limit:sr_m"]
    last = got[-1]["alarms"]
    assert [(a["id"], a["since"]) for a in last] == [(a["id"], a["since"]) for a in current]
