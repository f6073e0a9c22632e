"""Replay seek: the jump resets the framer and edge state, so no SEQ gap and no sync edge
is counted across it (issue 10 item 7: one backward seek used to add ~65 000 seq_gaps)."""

from __future__ import annotations

import time

import independent

from radar_io.recording.rdrlog import RecordingWriter
from radar_io.recording.recorder import Recorder
from radar_io.service.history import History
from radar_io.service.pipeline import Pipeline

N = 3000
CHUNK = 777  # serial-read-sized chunks: frames (24 bytes) split across them


def sts(i: int) -> int:
    return (1 << 15 if i % 100 < 5 else 0) | 4  # SYNC high 5 frames every 100; RX good


def wait(cond, what: str, timeout_s: float = 30.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not cond():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.01)


def test_backward_seek_adds_no_gap_and_no_edge(tmp_path, spec):
    data = b"".join(independent.frame(seq=i, tod=i, sts=sts(i)) for i in range(N))
    p = tmp_path / "r.rdrlog"
    with RecordingWriter(p, spec) as w:
        for k in range(0, len(data), CHUNK):
            w.write(data[k:k + CHUNK], t_ns=1_000_000 * (k // CHUNK))
    rec = Recorder(tmp_path / "data", spec, None, "test", auto="manual")
    rec.enabled = False  # records nothing; its sync index shows the edges
    acq = Pipeline(f"replay://{p}?speed=0", spec, History(), lambda _m: None, recorder=rec)
    src = acq.source
    src.pause()
    src.step(5)  # 5 chunks: 161 whole frames and 21 bytes of the 162nd
    acq.start()
    try:
        first = 5 * CHUNK // 24
        wait(lambda: acq.framer.stats.frames == first and src.state()["chunk"] == 5, "5 steps")
        assert acq.framer.pending == 5 * CHUNK - 24 * first
        src.seek(0.0)  # backwards, to the start (frame 0 has SYNC high)
        src.resume()
        wait(lambda: src.finished and acq.framer.stats.frames == first + N, "the replay")
        st = acq.status()
    finally:
        acq.stop()
    assert st["seq_gaps"] == 0
    assert st["crc_errors"] == 0 and st["implausible"] == 0
    assert st["bytes_discarded"] == 5 * CHUNK - 24 * first  # the cut frame before the jump
    # edges: frames 0 and 100 before the seek; after it 100, 200, … 2900 (frame 0 right
    # after the jump is not an edge: what came before it in the stream is unknown)
    assert [e.seq for e in rec.sync_events] == [0, 100, *range(100, N, 100)]
