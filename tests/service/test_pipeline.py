"""The pipeline's edge cases: recorder edges, failures, sync attribution, replay sessions."""

from __future__ import annotations

import errno
import json
import os
import time

import independent

from radar_io.recording.rdrlog import RecordingReader, RecordingWriter
from radar_io.recording.recorder import Recorder
from radar_io.service.history import History
from radar_io.service.pipeline import Pipeline, RecordedClock
from radar_io.sources.replay import ReplaySource

from .test_live_pty import wait_for

GO, GO_SYNC, IDLE, SYNC = 0x0005, 0x8005, 0x0004, 0x8004


def pipeline(tmp_path, spec, preroll_s: float = 2.0, source: str = "loop://"):
    rec = Recorder(tmp_path / "data", spec, None, source, auto="go", preroll_s=preroll_s)
    published: list = []
    acq = Pipeline(source, spec, History(8 << 20), published.extend, recorder=rec)
    return acq, rec, published


def frames(sts: list[int], seq0: int = 0) -> list[bytes]:
    return [independent.frame(seq=seq0 + i, sr=1000 + seq0 + i, sts=s) for i, s in enumerate(sts)]


def recorded(rec: Recorder, rec_id: str) -> bytes:
    with RecordingReader(rec.dir / f"{rec_id}.rdrlog") as r:
        return b"".join(c.data for c in r)


def test_go_falling_and_rising_within_one_read(tmp_path, spec):
    acq, rec, _ = pipeline(tmp_path, spec)
    fr = frames([IDLE, GO, GO, IDLE, GO, GO])
    acq._process(b"".join(fr[:3]), 1)
    first = rec.current
    acq._process(b"".join(fr[3:]), 2)  # GO falls and rises again in this one chunk
    second = rec.current
    rec.stop()
    assert first and second and first != second
    assert fr[1] + fr[2] in recorded(rec, first)
    data = recorded(rec, second)
    assert fr[4] + fr[5] in data  # the new GO period is whole


def test_preroll_zero_keeps_the_frame_split_across_reads(tmp_path, spec):
    acq, rec, _ = pipeline(tmp_path, spec, preroll_s=0.0)
    f = frames([IDLE, GO, GO])
    acq._process(f[0] + f[1][:10], 1)
    acq._process(f[1][10:] + f[2], 2_000_000_000)  # 2 s later: beyond any pre-roll
    rid = rec.stop()
    assert f[1] + f[2] in recorded(rec, rid)


def test_sync_edge_on_the_go_falling_frame_belongs_to_the_closing_recording(tmp_path, spec):
    acq, rec, _ = pipeline(tmp_path, spec)
    acq._process(b"".join(frames([GO, GO])), 1)
    rid = rec.current
    acq._process(b"".join(frames([SYNC, IDLE], seq0=2)), 2)  # GO falls as SYNC rises
    assert rec.current is None
    assert rec.sync_events[-1].recording == rid
    rec.close()  # the writer thread has written the sync index and the events
    assert (rec.dir / f"{rid}.sync.jsonl").read_text().count("\n") == 1
    lines = (rec.dir / f"{rid}.events.jsonl").read_text().splitlines()
    kinds = [json.loads(x)["kind"] for x in lines]
    assert kinds == ["go", "go", "sync"]  # rise, fall, then the edge on the falling frame


def test_a_failing_disk_never_stops_decoding(tmp_path, spec, monkeypatch):
    acq, rec, published = pipeline(tmp_path, spec)
    acq._process(b"".join(frames([GO, GO])), 1)
    rid = rec.current
    wait_for(lambda: rec.committed_bytes(rid), what="the recording open")
    real_write = os.write

    def write(fd, data):  # the disk goes away under the open recording
        if str(rec.dir) in os.readlink(f"/proc/self/fd/{fd}"):
            raise OSError(errno.EIO, os.strerror(errno.EIO))
        return real_write(fd, data)

    monkeypatch.setattr(os, "write", write)
    acq._process(b"".join(frames([GO, GO, GO], seq0=2)), 2)
    assert len(published) == 5  # every frame still decoded and published
    wait_for(lambda: acq.status()["recording_error"], what="the write error reported")
    assert rec.current == rid  # kept: its chunks wait in memory for the disk
    acq._process(b"".join(frames([GO], seq0=5)), 3)
    assert len(published) == 6
    assert rec.buffer_status()["pending_bytes"] == 4 * spec.length
    rec.close(timeout_s=0.5)


def test_manual_start_during_a_go_recording_survives_the_go_fall(tmp_path, spec):
    acq, rec, _ = pipeline(tmp_path, spec)
    acq._process(b"".join(frames([GO, GO])), 1)
    rid = rec.start("manual")
    acq._process(b"".join(frames([IDLE, IDLE], seq0=2)), 2)
    assert rec.current == rid  # manual: the GO fall does not end it
    assert rec.stop() == rid


def test_a_replay_pipeline_survives_a_vanished_recording(tmp_path, spec):
    p = tmp_path / "r.rdrlog"
    with RecordingWriter(p, spec) as w:
        w.write(b"".join(frames([GO] * 10)), 1)
    ctl = ReplaySource(p, 0)
    p.unlink()  # gone before the reader opens it
    published: list = []
    pipe = Pipeline(ctl, spec, History(1 << 20), published.extend, clock=RecordedClock(ctl),
                    replay="s1")
    pipe.start()
    try:
        st = wait_for(lambda: (s := pipe.status())["last_error"] and s,
                      what="replay failure reported")
        assert pipe._thread.is_alive() and not st["connected"] and st["mode"] == "replay"
        assert "r.rdrlog" in st["last_error"] and not published
    finally:
        pipe.stop()


def test_a_replay_pipeline_stamps_recorded_times_and_touches_no_recorder(tmp_path, spec):
    """Replay: each message carries the recorded t_ns of the chunk that completed its frame
    and the session id; no recorder exists, so no recording and no sync index."""
    p = tmp_path / "r.rdrlog"
    fr = frames([GO, GO_SYNC, GO, IDLE, SYNC, GO], seq0=40)
    t0, m0 = 1_700_000_000_000_000_000, 5_000_000_000
    with RecordingWriter(p, spec) as w:
        w.write(fr[0] + fr[1][:7], t0, m0)                     # frame 40 completes here
        w.write(fr[1][7:] + fr[2] + fr[3][:3], t0 + 10, m0 + 1_000)  # 41, 42
        w.write(fr[3][3:] + fr[4] + fr[5], t0 + 20, m0 + 2_000)      # 43, 44, 45
    src = ReplaySource(p, 0)
    published: list = []
    pipe = Pipeline(src, spec, History(1 << 20), published.extend, clock=RecordedClock(src),
                    replay="abc")
    pipe.start()
    try:
        wait_for(lambda: len(published) == 6, what="six replayed messages")
    finally:
        pipe.stop()
    import json

    msgs = [json.loads(t) for _, t in published]
    assert [m["seq"] for m in msgs] == list(range(40, 46))
    assert [m["t_ns"] for m in msgs] == [t0, t0 + 10, t0 + 10, t0 + 20, t0 + 20, t0 + 20]
    assert all(m["replay"] == "abc" for m in msgs) and pipe.recorder is None
    assert not (tmp_path / "data").exists()  # nothing recorded anywhere


def test_a_damaged_chunk_length_skips_one_chunk_not_the_rest(tmp_path, spec):
    p = tmp_path / "d.rdrlog"
    with RecordingWriter(p, spec) as w:
        for i in range(30):
            w.write(bytes([i]) * 100, i)
    with RecordingReader(p) as r:
        off = [c.offset for c in r][10]
    raw = bytearray(p.read_bytes())
    raw[off + 13] ^= 0x40  # chunk 10 now claims 4 MiB more than the file holds
    p.write_bytes(bytes(raw))
    with RecordingReader(p) as r:
        got = [c.data[0] for c in r]
        assert got == [i for i in range(30) if i != 10]
        assert r.report.corrupt_chunks == 1 and r.report.torn_tail_bytes == 0


def test_status_rate_is_safe_to_read_while_frames_arrive(tmp_path, spec):
    import threading

    acq, rec, _ = pipeline(tmp_path, spec)
    stop = threading.Event()
    errors: list = []

    def reader() -> None:
        while not stop.is_set():
            try:
                acq.status()
            except Exception as exc:  # noqa: BLE001
                errors.append(exc)

    th = threading.Thread(target=reader)
    th.start()
    t_end = time.monotonic() + 1.0
    k = 0
    while time.monotonic() < t_end:
        acq._process(independent.frame(seq=k & 0xFFFF, sts=GO), time.time_ns())
        k += 1
    stop.set()
    th.join()
    rec.close()
    assert not errors and acq.rate_hz() > 0


def test_azimuth_never_reads_360(spec):
    from radar_io.coordinates.transforms import radar_sea

    assert float(radar_sea(1.0, -1e-20, 0.0)[2]) == 0.0
    assert 0.0 <= float(radar_sea(1.0, -1e-14, 0.0)[2]) < 360.0
    assert float(radar_sea(-1.0, 0.0, 0.0)[2]) == 180.0
