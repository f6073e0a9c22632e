"""``GET /api/recordings/{id}/series`` and ``/events`` on a real service (uvicorn on port 0):
answers equal numpy over ``decode_bytes``; the recording being written is queryable and
grows; a recording that closes gets its index from the service's worker; bad requests
answer 404 / 422 in the one error shape."""

from __future__ import annotations

import json
import time
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np
from test_series_index import (
    PATH_FILE,
    check,
    expected,
    reference,
    simulated_chunks,
    write_recording,
)

from radar_io.analysis.series import SeriesOptions, index_dir
from radar_io.coordinates.reference_path import load_path
from radar_io.coordinates.transforms import load_site
from radar_io.decoding.biases import Calibration

from .liveserver import TOKEN, LiveServer, live_server, service_config


def get(base: str, path: str) -> tuple[int, dict]:
    try:
        with urllib.request.urlopen(base + path, timeout=60) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as exc:
        return exc.code, json.loads(exc.read())


def test_series_and_events_of_a_recording(tmp_path, spec):
    cfg = service_config(tmp_path / "svc", auto_record="manual", path=str(PATH_FILE))
    recs = Path(cfg.data_dir) / "recordings"
    recs.mkdir(parents=True)
    chunks = simulated_chunks(spec, 20.0, seed=11)
    write_recording(recs / "flight.rdrlog", spec, chunks).close()
    options = SeriesOptions(spec, Calibration(), load_site("demo"), load_path(PATH_FILE))
    t, cols = reference(spec, chunks, options)
    with live_server(cfg) as srv:
        names = ["h_m", "dy_m", "lat_deg", "seq", "rx_good"]
        for q, (s, e, p) in {"": (None, None, 1000),
                             "&start_s=2.5&end_s=17&points=333": (2.5, 17.0, 333),
                             "&start_s=4&end_s=4.1&points=1000": (4.0, 4.1, 1000),
                             "&start_s=0&end_s=1e9&points=10000": (0.0, 1e9, 10000)}.items():
            status, body = get(srv.base, f"/api/recordings/flight/series?columns={','.join(names)}{q}")
            assert status == 200, body
            check(body, expected(t, cols, names, s, e, p), p)
        assert body["decimated"] is True and len(body["t_s"]) == 10000
        status, body = get(srv.base, "/api/recordings/flight/series?columns=h_m&start_s=4&end_s=4.1")
        assert body["decimated"] is False and body["frames"] == len(body["t_s"]) > 50

        with open(index_dir(recs / "flight.rdrlog") / "h_m.1.npy", "r+b") as f:
            f.truncate(100)  # a damaged index file: rebuilt, answered as before
        status, again = get(srv.base, "/api/recordings/flight/series?columns=h_m&points=77")
        assert status == 200
        check(again, expected(t, cols, ["h_m"], None, None, 77), 77)

        status, body = get(srv.base, "/api/recordings/flight/events")
        assert status == 200
        kinds = [e["kind"] for e in body["events"]]
        assert kinds.count("go") == 1 and kinds.count("sync") >= 30
        assert body["events"][kinds.index("go")]["edge"] == "rise"
        assert all(set(e) >= {"kind", "t_s", "t_ns", "seq", "tod_s"} for e in body["events"])

        for path, code, words in [
                ("/api/recordings/nope/series?columns=h_m", 404, "nope"),
                ("/api/recordings/nope/events", 404, "nope"),
                ("/api/recordings/flight/series?columns=h_m,wind_mps", 422, "wind_mps"),
                ("/api/recordings/flight/series?columns=h_m&start_s=9&end_s=3", 422, "after"),
                ("/api/recordings/flight/series?columns=h_m&points=0", 422, ""),
                ("/api/recordings/flight/series?columns=h_m&points=10001", 422, ""),
                ("/api/recordings/flight/series?columns=h_m&start_s=nan", 422, ""),
                ("/api/recordings/flight/series?columns=h_m;x", 422, ""),
                ("/api/recordings/flight/series", 422, "")]:
            status, body = get(srv.base, path)
            assert status == code, (path, body)
            assert words in body["detail"][0]["msg"]


def test_the_recording_being_written_grows_and_is_indexed_when_it_closes(tmp_path):
    cfg = service_config(tmp_path / "svc", source="sim://?sync_every_s=0.5",
                         auto_record="manual")
    srv = LiveServer(cfg)
    srv.app.state.lookback.refresh_s = 0.2
    try:
        srv.start()
        srv.wait_connected()
        status, body = srv.request("POST", "/api/recordings/start", token=TOKEN)
        assert status == 200
        rec = body["recording"]
        path = Path(cfg.data_dir) / "recordings" / f"{rec}.rdrlog"
        man = index_dir(path) / "manifest.json"
        deadline = time.monotonic() + 30
        while not (man.exists() and json.loads(man.read_text())["rows"] > 500):
            assert time.monotonic() < deadline, "the open recording was not indexed"
            time.sleep(0.1)  # no query yet: the service's worker keeps the index current
        frames = []
        for _ in range(3):
            time.sleep(1.0)
            status, body = get(srv.base, f"/api/recordings/{rec}/series?columns=h_m,sync&points=50")
            assert status == 200, body
            frames.append(body["frames"])
            assert body["decimated"] is (body["frames"] > 50)
        assert 500 < frames[0] < frames[1] < frames[2]
        assert srv.request("POST", "/api/recordings/stop", token=TOKEN)[0] == 200
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:  # the service's worker indexes the closed file
            if man.exists() and json.loads(man.read_text())["recording"]["scanned_bytes"] \
                    == path.stat().st_size:
                break
            time.sleep(0.1)
        else:
            raise AssertionError("the closed recording was not indexed")
        status, body = get(srv.base, f"/api/recordings/{rec}/series?columns=h_m&points=50")
        assert body["frames"] > frames[2]
        assert np.all(np.diff(body["t_s"]) > 0)
        status, body = get(srv.base, f"/api/recordings/{rec}/events")
        marks = [(e["kind"], e.get("seq"), e["t_s"]) for e in body["events"]
                 if e["kind"] in ("go", "sync")]
        assert status == 200 and len(marks) == len(set(marks))  # each edge once
        assert sum(kind == "sync" for kind, _, _ in marks) >= 5
    finally:
        srv.stop()
