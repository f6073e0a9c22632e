"""Replay sessions beside the live pipeline: /api/replays, /ws/replays/{id}, limits, idle end,
the recording being written, and the 410 of the removed /api/replay* routes."""

from __future__ import annotations

import asyncio
import json
import time
import urllib.request
from pathlib import Path

import independent
import pytest
import websockets

from radar_io.recording.rdrlog import RecordingReader, RecordingWriter
from radar_io.wirespec.frame import load_spec

from .liveserver import TOKEN, browser, live_server, service_config  # noqa: F401 - fixture
from .test_live_pty import wait_for

GO, GO_SYNC = 0x0005, 0x8005
T0_NS = 1_767_225_600_000_000_000  # 2026-01-01T00:00:00Z: the recorded flight's wall clock
MONO0_NS = 123_000_000_000


def write_flight(path: Path, n: int, *, seq0: int, sr: int, chunk_frames: int = 10,
                 sync_every: int = 100) -> list[tuple[int, int]]:
    """A recording of ``n`` GO frames (SEQ from ``seq0``, SR ``sr`` m, SYNC high on one frame
    every ``sync_every``), ``chunk_frames`` whole frames per chunk received 1 ms per frame
    apart; the ``(t_ns, mono_ns)`` of each chunk."""
    times = []
    with RecordingWriter(path, load_spec(), source="test") as w:
        for k in range(0, n, chunk_frames):
            data = b"".join(independent.frame(seq=seq0 + i, tod=10 * i, sr=sr,
                                              sts=GO_SYNC if i % sync_every == 1 else GO)
                            for i in range(k, min(n, k + chunk_frames)))
            t = (T0_NS + k * 1_000_000, MONO0_NS + k * 1_000_000)
            w.write(data, *t)
            times.append(t)
    return times


def recorded_t_ns(seq: int, seq0: int, times: list[tuple[int, int]], chunk_frames: int = 10) -> int:
    """The recorded receive time of the chunk that completed frame ``seq``."""
    return times[(seq - seq0) // chunk_frames][0]


async def collect(url: str, until, timeout_s: float = 30.0) -> list[dict]:
    """Messages of a websocket (arrays flattened) until ``until(msgs)`` or the server closes."""
    msgs: list[dict] = []
    async with websockets.connect(url, max_size=None) as ws:
        deadline = time.monotonic() + timeout_s
        while not until(msgs) and time.monotonic() < deadline:
            try:
                doc = json.loads(await asyncio.wait_for(ws.recv(), 1.0))
            except TimeoutError:
                continue
            except websockets.ConnectionClosed:
                break
            msgs.extend(doc if isinstance(doc, list) else [doc])
    return msgs


@pytest.fixture
def server(tmp_path):
    cfg = service_config(tmp_path / "svc", "sim://?rate_hz=1000&sync_every_s=0.5&go_delay_s=0.2",
                         auto_record="manual", max_replays=2, replay_idle_s=1.0)
    with live_server(cfg) as srv:
        srv.wait_connected()
        srv.rec_dir = Path(cfg.data_dir) / "recordings"
        yield srv


def test_a_session_streams_the_recorded_frames_with_their_recorded_t_ns(server):
    times = write_flight(server.rec_dir / "earlier.rdrlog", 3000, seq0=40000, sr=15000)
    live0 = server.get("/api/status")
    code, st = server.request("POST", "/api/replays", {"recording": "earlier", "speed": 0},
                              TOKEN)
    assert code == 201 and st["ws"] == f"/ws/replays/{st['id']}" and st["chunks"] == 300
    sid = st["id"]
    wait_for(lambda: server.get(f"/api/replays/{sid}")["finished"], what="the replay")
    msgs = asyncio.run(collect(f"ws://127.0.0.1:{server.port}{st['ws']}?from=0&batch=1",
                               lambda m: len(m) >= 3000))
    assert [m["seq"] for m in msgs] == list(range(40000, 43000))  # all, in order
    assert [m["t_ns"] for m in msgs] == [recorded_t_ns(m["seq"], 40000, times) for m in msgs]
    assert all(m["replay"] == sid and m["sr_m"] == 15000.0 for m in msgs)
    assert [m["msg_seq"] for m in msgs] == list(range(1, 3001))  # the session's own numbering
    # the live pipeline saw none of it
    live = server.get("/api/status")
    assert live["source"] == live0["source"] and live["reconnects"] == live0["reconnects"]
    assert live["recording"] is None and live["mode"] == "live" and live["source_kind"] == "sim"
    assert not any(40000 <= e["seq"] < 43000 for e in server.get("/api/sync-events"))
    assert not any("replay" in m for m in server.get("/api/track?limit=5000")["messages"])
    assert [r["id"] for r in live["replays"]] == [sid]


def test_step_delivers_n_recorded_chunks_and_seek_lands_on_the_chunk(server):
    write_flight(server.rec_dir / "steps.rdrlog", 5000, seq0=100, sr=9000)
    code, st = server.request("POST", "/api/replays",
                              {"recording": "steps", "speed": 1.0, "start_s": 2.0}, TOKEN)
    assert code == 201
    base = f"/api/replays/{st['id']}"
    st = server.request("POST", base + "/pause", None, TOKEN)[1]
    c0 = st["chunk"]
    assert 200 <= c0 < 260  # 2 s in (200 chunks of 10 ms), a few chunks played since
    time.sleep(0.3)
    frames0 = server.get(base)["frames"]
    assert server.get(base)["chunk"] == c0  # paused
    server.request("POST", base + "/step", {"n": 7}, TOKEN)
    st = wait_for(lambda: (s := server.get(base))["chunk"] == c0 + 7 and s, what="7 steps")
    wait_for(lambda: server.get(base)["frames"] == frames0 + 70, what="70 frames")
    st = server.request("POST", base + "/seek", {"position_s": 4.5}, TOKEN)[1]
    assert st["chunk"] == 450 and st["position_s"] == pytest.approx(4.5) and st["paused"]
    st = server.request("POST", base + "/speed", {"speed": 0}, TOKEN)[1]
    assert st["speed"] == 0
    server.request("POST", base + "/resume", None, TOKEN)
    st = wait_for(lambda: (s := server.get(base))["finished"] and s, what="the end")
    assert st["seq_gaps"] == 0 and st["crc_errors"] == 0
    assert st["frames"] == frames0 + 70 + (5000 - 4500)


def test_the_recording_being_written_replays_up_to_what_is_on_disk(server):
    rec = server.request("POST", "/api/recordings/start", None, TOKEN)[1]["recording"]
    time.sleep(1.0)
    code, st = server.request("POST", "/api/replays", {"recording": rec, "speed": 0}, TOKEN)
    assert code == 201 and st["chunks"] > 0
    base = f"/api/replays/{st['id']}"
    done = wait_for(lambda: (s := server.get(base))["finished"] and s, what="the replay")
    time.sleep(0.5)
    assert server.get("/api/status")["recording"] == rec  # still being written
    with RecordingReader(server.rec_dir / f"{rec}.rdrlog") as r:
        chunks_now = sum(1 for _ in r)
    assert chunks_now > done["chunks"]  # it grew after the session was made
    assert done["chunk"] == done["chunks"] and done["seq_gaps"] == 0 and done["crc_errors"] == 0
    assert done["frames"] > 500
    assert server.request("POST", "/api/recordings/stop", None, TOKEN)[1]["closed"] == rec


def test_max_replays_unknown_ids_and_sessions_nobody_watches_end(server):
    write_flight(server.rec_dir / "a.rdrlog", 2000, seq0=0, sr=8000)
    ids = [server.request("POST", "/api/replays", {"recording": "a"}, TOKEN)[1]["id"]
           for _ in range(2)]
    req = urllib.request.Request(server.base + "/api/replays", method="POST",
                                 data=json.dumps({"recording": "a"}).encode(),
                                 headers={"Authorization": f"Bearer {TOKEN}",
                                          "Content-Type": "application/json"})
    with pytest.raises(urllib.error.HTTPError) as e:
        urllib.request.urlopen(req, timeout=10)
    assert e.value.code == 429 and e.value.headers["Retry-After"]
    assert "max_replays" in e.value.read().decode()
    assert server.request("GET", "/api/replays/ffff")[0] == 404
    assert server.request("POST", "/api/replays/ffff/pause", None, TOKEN)[0] == 404
    assert server.request("POST", "/api/replays", {"recording": "nope"}, TOKEN)[0] == 404

    async def unknown() -> int | None:
        async with websockets.connect(f"ws://127.0.0.1:{server.port}/ws/replays/ffff") as ws:
            with pytest.raises(websockets.ConnectionClosed) as closed:
                await ws.recv()
        return closed.value.rcvd.code if closed.value.rcvd else None

    assert asyncio.run(unknown()) == 4404

    async def watch(sid: str, seconds: float) -> None:
        async with websockets.connect(f"ws://127.0.0.1:{server.port}/ws/replays/{sid}") as ws:
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                try:
                    await asyncio.wait_for(ws.recv(), 0.2)
                except TimeoutError:
                    pass

    t0 = time.monotonic()
    asyncio.run(watch(ids[0], 2.5))  # watched: outlives replay_idle_s = 1 s
    assert server.request("GET", f"/api/replays/{ids[0]}")[0] == 200
    wait_for(lambda: server.get("/api/replays") == [], timeout_s=10, what="idle sessions end")
    assert time.monotonic() - t0 >= 2.5
    code, _ = server.request("POST", "/api/replays", {"recording": "a"}, TOKEN)
    assert code == 201  # room again


@pytest.mark.parametrize("method,path,new", [
    ("POST", "/api/replay", "POST /api/replays"), ("GET", "/api/replay", "GET /api/replays"),
    ("POST", "/api/replay/pause", "/api/replays/{id}/pause"),
    ("POST", "/api/replay/seek", "/api/replays/{id}/seek"),
    ("POST", "/api/replay/stop", "DELETE /api/replays/{id}"),
])
def test_the_old_replay_routes_are_gone_and_say_where_to(server, method, path, new):
    code, doc = server.request(method, path, {"recording": "x"} if method == "POST" else None,
                               TOKEN)
    assert code == 410 and new in doc["detail"][0]["msg"] and doc["detail"][0]["type"] == "gone"


def test_dashboard_replays_in_the_look_back_view_while_live_goes_on(server, browser):  # noqa: F811
    """Headless Chromium: "Look back" on a recording, Play opens a session whose
    /ws/replays/{id} feeds the look-back view while the live view keeps /ws/live; "Live"
    deletes the session. (The look-back view itself: test_dashboard_lookback.py.)"""
    write_flight(server.rec_dir / "panel.rdrlog", 20000, seq0=40000, sr=15000)
    browser.navigate(server.base + "/")
    browser.wait_for("window.radarReady && radarState.received > 10")
    browser.eval(f"document.getElementById('token').value = {json.dumps(TOKEN)}, true")
    browser.wait_for("[...document.getElementById('rec-list').options].some(o => o.value === 'panel')")
    browser.eval("document.getElementById('rec-list').value = 'panel', "
                 "document.getElementById('rec-open').click(), true")
    browser.wait_for("radarLookback.active && radarLookback.loads > 0", 30)
    browser.eval("document.getElementById('lb-play').click(), true")
    browser.wait_for("radarReplay.last && radarReplay.last.replay", 20)
    sid = browser.eval("radarReplay.id")
    assert [r["id"] for r in server.get("/api/replays")] == [sid]
    assert browser.eval("radarReplay.last.replay") == sid and browser.eval("radarReplay.last.seq") >= 40000
    # the live stream was never swapped: the page's live messages are the simulator's
    n = browser.eval("radarState.received")
    browser.wait_for(f"radarState.received > {n + 10} && !('replay' in radarState.last)")
    browser.wait_for(f"document.getElementById('lb-replay').textContent.startsWith('session {sid}:')")
    browser.eval("document.getElementById('lb-pause').click(), true")
    wait_for(lambda: server.get(f"/api/replays/{sid}")["paused"], what="paused from the view")
    browser.eval("document.getElementById('to-live').click(), true")
    wait_for(lambda: server.get("/api/replays") == [], what="the session deleted")
    n = browser.eval("radarState.received")
    browser.wait_for(f"!document.getElementById('live-view').hidden && radarState.received > {n + 10}"
                     " && !('replay' in radarState.last)", 20)
    assert server.get("/api/status")["connected"]
