"""archive_dir: each recording the service closes is archived as Parquet by a worker thread;
the partition holds exactly the rows the batch decoder gives for that recording."""

from __future__ import annotations

import time

import pyarrow.parquet as pq

from radar_io.decoding.decoders import iter_decode
from radar_io.decoding.measurement import MeasurementBatch
from radar_io.recording.rdrlog import iter_payloads

from .liveserver import TOKEN, live_server, service_config


def _until(cond, timeout_s: float = 30.0):
    end = time.monotonic() + timeout_s
    while True:
        v = cond()
        if v:
            return v
        assert time.monotonic() < end, "timed out"
        time.sleep(0.1)


def test_a_closed_recording_is_archived_with_the_decoders_rows(tmp_path):
    archive = tmp_path / "campaign"
    cfg = service_config(tmp_path, "sim://?rate_hz=500", auto_record="manual", site="demo",
                         archive_dir=str(archive))
    with live_server(cfg) as srv:
        srv.wait_connected()
        code, doc = srv.request("POST", "/api/recordings/start", token=TOKEN)
        assert code == 200, doc
        time.sleep(1.5)
        code, doc = srv.request("POST", "/api/recordings/stop", token=TOKEN)
        assert code == 200, doc
        st = _until(lambda: (s := srv.get("/api/status"))["archive"]["archived"] == 1 and s)
        assert st["archive"]["errors"] == 0 and st["archive"]["pending"] == 0
    parts = list(archive.rglob("*.parquet"))
    assert len(parts) == 1 and "site=" in str(parts[0]) and "recording=" in str(parts[0])
    rec = next((tmp_path / "data" / "recordings").glob("*.rdrlog"))
    assert rec.stem in str(parts[0])
    from radar_io.coordinates.transforms import load_site

    want = MeasurementBatch.concat(list(iter_decode(iter_payloads(rec), site=load_site("demo"))))
    got = pq.read_table(parts[0])
    assert got.num_rows == len(want) > 300
    assert got.column("seq").to_pylist() == [int(s) for s in want["seq"]]
    assert got.column("sr_m").to_pylist() == [float(v) for v in want["sr_m"]]
