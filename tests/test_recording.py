"""Recordings: append-only, crash-safe, damaged tails and middles skipped, decoded like raw bytes."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from itertools import pairwise

import independent
import numpy as np
import pytest

from radar_io.coordinates.transforms import load_site
from radar_io.decoding.decoders import decode_bytes, iter_decode
from radar_io.errors import RecordingError
from radar_io.recording.rdrlog import (
    RecordingReader,
    RecordingWriter,
    encode_chunk,
    is_recording,
    iter_payloads,
)
from radar_io.wirespec.frame import spec_dir


def payload(i: int) -> bytes:
    return (i.to_bytes(4, "big") * (1 + i % 50))[: 1 + (i * 37) % 300]


def test_round_trip_with_header(tmp_path, spec):
    site = load_site(spec_dir() / "sites" / "demo.toml")
    p = tmp_path / "a.rdrlog"
    with RecordingWriter(p, spec, site=site, source="loop://") as w:
        for i in range(100):
            w.write(payload(i), t_ns=1_000_000 * i)
    assert is_recording(p) and not is_recording(tmp_path)
    with RecordingReader(p) as r:
        assert r.header["spec_version"] == spec.spec_version == "RDR1-1.0"
        assert r.header["spec_sha256"] == spec.sha256
        assert r.header["site"]["name"] == "demo" and r.header["source"] == "loop://"
        chunks = list(r)
        assert [c.data for c in chunks] == [payload(i) for i in range(100)]
        assert [c.t_ns for c in chunks] == [1_000_000 * i for i in range(100)]
        assert r.report.torn_tail_bytes == 0 and r.report.corrupt_chunks == 0


def test_never_overwrites(tmp_path, spec):
    p = tmp_path / "a.rdrlog"
    RecordingWriter(p, spec).close()
    with pytest.raises(RecordingError, match="already exists"):
        RecordingWriter(p, spec)


WRITER = textwrap.dedent("""
    import sys
    from radar_io.recording.rdrlog import RecordingWriter
    from radar_io.wirespec.frame import load_spec
    sys.path.insert(0, {tests!r})
    from test_recording import payload
    w = RecordingWriter({path!r}, load_spec(), fsync_interval_s=0.5)
    i = 0
    while True:
        w.write(payload(i))
        i += 1
        if i % 100 == 0:
            print(i, flush=True)
""")


def test_kill_9_mid_write_loses_no_complete_chunk(tmp_path):
    p = tmp_path / "crash.rdrlog"
    code = WRITER.format(tests=os.path.dirname(__file__), path=str(p))
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    reported = 0
    deadline = time.monotonic() + 60
    while reported < 3000 and time.monotonic() < deadline:
        reported = int(proc.stdout.readline() or reported)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert reported >= 3000
    with RecordingReader(p) as r:
        chunks = [c.data for c in r]
    assert len(chunks) >= reported
    assert chunks == [payload(i) for i in range(len(chunks))]
    # the crash may also have cut a chunk in half: emulate it explicitly
    full = p.read_bytes()
    torn = encode_chunk(payload(len(chunks)), 123)
    p.write_bytes(full + torn[: len(torn) // 2])
    with RecordingReader(p) as r:
        again = [c.data for c in r]
        assert again == chunks
        assert r.report.torn_tail_bytes == len(torn) // 2
        assert "torn tail" in r.report.problems[0]


@pytest.mark.parametrize("cut", [1, 5, 19, 20, 21])
def test_torn_tail_at_any_point_is_skipped(tmp_path, spec, cut):
    p = tmp_path / "t.rdrlog"
    with RecordingWriter(p, spec) as w:
        for i in range(5):
            w.write(payload(i + 10))
    size = p.stat().st_size
    with open(p, "r+b") as f:
        f.truncate(size - cut)
    with RecordingReader(p) as r:
        assert [c.data for c in r] == [payload(i + 10) for i in range(4)]
        assert r.report.torn_tail_bytes > 0


def test_damaged_middle_chunk_is_counted_and_skipped(tmp_path, spec):
    p = tmp_path / "d.rdrlog"
    with RecordingWriter(p, spec) as w:
        for i in range(20):
            w.write(payload(i))
    with RecordingReader(p) as r:
        offs = [c.offset for c in r]
    raw = bytearray(p.read_bytes())
    raw[offs[7] + 25] ^= 0xFF  # inside chunk 7's payload
    raw[offs[12] + 2] ^= 0xFF  # chunk 12's magic
    p.write_bytes(bytes(raw))
    with RecordingReader(p) as r:
        got = [c.data for c in r]
        assert got == [payload(i) for i in range(20) if i not in (7, 12)]
        assert r.report.corrupt_chunks == 2 and r.report.torn_tail_bytes == 0


def test_chunks_from_an_offset_up_to_a_limit(tmp_path, spec):
    """``chunks(start, end)``: from a chunk boundary, never past ``end`` (the committed bytes
    of a recording being written: a chunk written in part after it is not read)."""
    p = tmp_path / "c.rdrlog"
    w = RecordingWriter(p, spec)
    for i in range(12):
        w.write(payload(i))
    committed = w.committed_bytes
    with open(p, "ab") as f:  # the next chunk, half written
        f.write(encode_chunk(payload(99), 1)[:20])
    with RecordingReader(p) as r:
        offs = [c.offset for c in r]
        assert r.report.torn_tail_bytes == 20
        got = list(r.chunks(offs[5], committed))
        assert [c.data for c in got] == [payload(i) for i in range(5, 12)]
        assert r.report.torn_tail_bytes == 0 and r.report.problems == []
        assert [c.data for c in r.chunks(offs[3], offs[6])] == [payload(i) for i in (3, 4, 5)]
        assert [c.data for c in r.chunks(offs[3], offs[6] - 1)] == [payload(3), payload(4)]
        assert r.report.torn_tail_bytes > 0  # a limit inside a chunk: the rest is torn
        assert list(r.chunks(committed, committed)) == []
    w.close()


def test_not_a_recording(tmp_path):
    p = tmp_path / "x.rdrlog"
    p.write_bytes(b"hello world")
    with pytest.raises(RecordingError, match=r"not an \.rdrlog"):
        RecordingReader(p)
    with pytest.raises(RecordingError, match="not found"):
        RecordingReader(tmp_path / "missing.rdrlog")


def test_recording_decodes_through_the_same_framer_as_raw_bytes(tmp_path, spec):
    frames = b"".join(independent.frame(seq=i, sr=i, sts=5) for i in range(3000))
    data = frames[:5000] + b"\x00junk\xeb" + frames[5000:]
    p = tmp_path / "r.rdrlog"
    with RecordingWriter(p, spec) as w:
        for k in range(0, len(data), 777):  # serial-read-sized chunks, frames split across them
            w.write(data[k:k + 777])
    batches = list(iter_decode(iter_payloads(p, chunk_bytes=10_000)))
    want = decode_bytes(data)
    assert batches[-1].stats == want.stats
    assert np.array_equal(np.concatenate([b["sr_m"] for b in batches]), want["sr_m"])


# -- storage faults (issue 10 item 3) ------------------------------------------------------
import errno  # noqa: E402

from radar_io.errors import StorageError  # noqa: E402
from radar_io.recording.recorder import Recorder  # noqa: E402


def open_fds() -> set[str]:
    return set(os.listdir("/proc/self/fd"))


def disk_full_after(monkeypatch, path_part: str, budget: list[int]) -> None:
    """os.write to files whose name contains ``path_part`` fails with ENOSPC once
    ``budget[0]`` bytes are used up (the last write is cut short, as on a real disk)."""
    real = os.write

    def write(fd, data):
        try:
            ours = path_part in os.readlink(f"/proc/self/fd/{fd}")
        except OSError:
            ours = False
        if not ours:
            return real(fd, data)
        if budget[0] <= 0:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        n = real(fd, bytes(memoryview(data)[:budget[0]]))
        budget[0] -= n
        return n

    monkeypatch.setattr(os, "write", write)


def test_full_disk_at_creation_leaves_no_file_and_no_fd(tmp_path, spec, monkeypatch):
    disk_full_after(monkeypatch, "full.rdrlog", [10])  # not even the header fits
    before = open_fds()
    for _ in range(5):
        with pytest.raises(StorageError, match="No space left") as e:
            RecordingWriter(tmp_path / "full.rdrlog", spec)
        assert e.value.errno == errno.ENOSPC
    assert not (tmp_path / "full.rdrlog").exists()
    assert open_fds() == before
    assert Recorder.http_status(e.value) == 507
    assert Recorder.http_status(StorageError("x", errno=errno.EIO)) == 503


def test_disk_filling_mid_chunk_keeps_whole_chunks(tmp_path, spec, monkeypatch):
    budget = [10_000]
    disk_full_after(monkeypatch, "mid.rdrlog", budget)
    w = RecordingWriter(tmp_path / "mid.rdrlog", spec)
    n = 0
    with pytest.raises(StorageError, match="cannot write recording"):
        while True:
            w.write(payload(n))
            n += 1
    assert budget[0] == 0  # the last chunk was cut short by the full disk …
    size = (tmp_path / "mid.rdrlog").stat().st_size
    assert size == w.committed_bytes  # … and cut off again: the file ends on a whole chunk
    w.close()
    with RecordingReader(tmp_path / "mid.rdrlog") as r:
        assert [c.data for c in r] == [payload(i) for i in range(n)]
        assert r.report.torn_tail_bytes == 0


def test_fsync_error_is_raised_not_swallowed(tmp_path, spec, monkeypatch):
    w = RecordingWriter(tmp_path / "s.rdrlog", spec, fsync_interval_s=0.05)
    w.write(b"before")
    real = os.fsync

    def fsync(fd):
        if fd == w._fd:
            raise OSError(errno.EIO, os.strerror(errno.EIO))
        return real(fd)

    monkeypatch.setattr(os, "fsync", fsync)
    deadline = time.monotonic() + 10
    while w.fsync_error is None and time.monotonic() < deadline:
        time.sleep(0.01)
    with pytest.raises(StorageError, match=r"fsync failed.*Input/output error"):
        w.write(b"after")
    with pytest.raises(StorageError, match="fsync failed"):
        w.close()
    assert w.closed


def wait_until(cond, timeout_s: float = 10.0):
    deadline = time.monotonic() + timeout_s
    while not (got := cond()):
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.01)
    return got


def frames_in(path) -> list[bytes]:
    with RecordingReader(path) as r:
        return [c.data for c in r]


def test_recorder_on_a_full_disk_buffers_and_loses_nothing(tmp_path, spec, monkeypatch):
    """GO rises on a full disk: the recording is started at that point of the stream (its
    file cannot be created yet); the chunks wait in memory and are all written, pre-roll
    first, when space comes back — by the writer thread, never by on_chunk."""
    budget = [0]
    disk_full_after(monkeypatch, "recordings", budget)
    rec = Recorder(tmp_path, spec, None, "test", auto="go", retry_s=0.1)
    frames = [independent.frame(seq=i, sts=5) for i in range(40)]
    rec.on_chunk(frames[0], 10**18, 1)
    rec.on_go_edge(True)  # GO rises: returns at once, the writer meets the full disk
    wait_until(lambda: rec.last_error and "No space left" in rec.last_error)
    rid = rec.current
    assert rid is not None and list(rec.dir.glob("*.rdrlog")) == []
    for i in range(1, 30):
        rec.on_chunk(frames[i], 10**18 + i, 1 + i)
    time.sleep(0.35)
    st = rec.storage()
    assert st["errors"] >= 3 and st["buffer"]["pending_bytes"] == 30 * len(frames[1])  # pre-roll too
    budget[0] = 1 << 30  # space is back
    wait_until(lambda: rec.last_error is None and rec.buffer_status()["pending_bytes"] == 0)
    rec.on_go_edge(False)
    rec.close()
    assert frames_in(rec.dir / f"{rid}.rdrlog") == frames[:30]
    st = rec.storage()
    assert "No space left" in st["last_error"] and st["buffer"]["overflow_chunks"] == 0


def test_recorder_buffer_overflow_is_counted(tmp_path, spec, monkeypatch):
    budget = [0]
    disk_full_after(monkeypatch, "recordings", budget)
    frame = independent.frame(seq=1, sts=5)
    rec = Recorder(tmp_path, spec, None, "test", auto="always", retry_s=0.1,
                   buffer_bytes=10 * len(frame))
    for i in range(25):
        rec.on_chunk(frame, 10**18 + i, i)
    st = rec.buffer_status()
    assert st["pending_bytes"] == 10 * len(frame)
    assert (st["overflow_chunks"], st["overflow_bytes"]) == (15, 15 * len(frame))
    budget[0] = 1 << 30
    wait_until(lambda: rec.buffer_status()["pending_bytes"] == 0)
    rid = rec.current
    rec.close()
    assert len(frames_in(rec.dir / f"{rid}.rdrlog")) == 10


def test_manual_start_on_a_full_disk_is_refused(tmp_path, spec, monkeypatch):
    budget = [0]
    disk_full_after(monkeypatch, "recordings", budget)
    rec = Recorder(tmp_path, spec, None, "test", auto="manual", retry_s=0.1)
    rec.on_chunk(b"x" * 24, 10**18, 1)
    with pytest.raises(StorageError, match="No space left"):
        rec.start()
    assert rec.current is None and rec.buffer_status()["pending_bytes"] == 0
    assert list(rec.dir.iterdir()) == []
    budget[0] = 1 << 30
    rid = rec.start()
    rec.on_chunk(b"y" * 24, 10**18 + 1, 2)
    wait_until(lambda: rec.buffer_status()["pending_bytes"] == 0)
    budget[0] = 0  # full again while the manual recording runs: it is retried, not dropped
    for i in range(5):
        rec.on_chunk(bytes([i]) * 24, 10**18 + 2 + i, 3 + i)
    wait_until(lambda: rec.last_error and "No space left" in rec.last_error)
    assert rec.current == rid
    budget[0] = 1 << 30
    assert rec.stop() == rid
    assert frames_in(rec.dir / f"{rid}.rdrlog") == [b"x" * 24, b"y" * 24] + [
        bytes([i]) * 24 for i in range(5)]
    rec.close()


class SlowDisk:
    """os.fsync / os.write on the recordings take ``delay_s``; records which threads call."""

    def __init__(self, monkeypatch, delay_s: float) -> None:
        import threading

        self.delay_s, self.threads = delay_s, set()
        real_fsync, real_write = os.fsync, os.write

        def ours(fd):
            try:
                return "recordings" in os.readlink(f"/proc/self/fd/{fd}")
            except OSError:
                return False

        def fsync(fd):
            if ours(fd):
                self.threads.add(threading.current_thread().name)
                time.sleep(delay_s)
            return real_fsync(fd)

        def write(fd, data):
            if ours(fd):
                self.threads.add(threading.current_thread().name)
            return real_write(fd, data)

        monkeypatch.setattr(os, "fsync", fsync)
        monkeypatch.setattr(os, "write", write)


def test_on_chunk_never_waits_for_a_slow_disk(tmp_path, spec, monkeypatch):
    """fsync takes 0.5 s: GO edges, sync events, manual stop and events from other threads
    cost the caller of on_chunk nothing; every chunk is in the file, events beside it."""
    from radar_io.recording.recorder import SyncEvent

    disk = SlowDisk(monkeypatch, 0.5)
    rec = Recorder(tmp_path, spec, None, "test", auto="go", fsync_interval_s=0.2)
    worst, sent, ids = 0.0, [], []
    for i in range(300):
        data = i.to_bytes(4, "big") * 6
        t0 = time.perf_counter()
        rec.on_chunk(data, 10**18 + i * 10**6, i * 10**6)
        if i % 100 == 10:
            rec.on_go_edge(True)
            ids.append(rec.current)
            rec.on_sync(SyncEvent(seq=i, tod_s=i / 1000, t_ns=10**18 + i * 10**6, msg_seq=i,
                                  recording=rec.current))
        if i % 100 == 90:
            rec.on_go_edge(False)
        worst = max(worst, time.perf_counter() - t0)
        if ids and i % 100 >= 10 and i % 100 <= 90:
            sent.append(data)
        time.sleep(0.002)
    rec.close()
    assert worst < 0.05, worst
    assert "rdrlog-writer" in disk.threads <= {"rdrlog-writer", "rdrlog-fsync"}  # not ours
    got = [d for rid in ids for d in frames_in(rec.dir / f"{rid}.rdrlog")]
    assert [d for d in sent if d in got] == sent  # every chunk while GO was high
    for rid in ids:
        events = [json.loads(line) for line in (rec.dir / f"{rid}.events.jsonl").open()]
        assert [e["kind"] for e in events] == ["go", "sync", "go"]
        assert [e.get("edge") for e in events] == ["rise", None, "fall"]
        assert all(isinstance(e["t_ns"], int) and isinstance(e["mono_ns"], int) for e in events)
        assert (rec.dir / f"{rid}.sync.jsonl").read_text().count("\n") == 1


def test_clock_steps_are_events_and_status(tmp_path, spec):
    rec = Recorder(tmp_path, spec, None, "test", auto="always")
    t, mono = 10**18, 5 * 10**9
    for i in range(10):
        jump = {4: 3600 * 10**9, 7: -int(0.7e9)}.get(i, 0)
        t += 10**6 + jump
        mono += 10**6
        if i == 2:
            t += int(0.4e9)  # below the threshold: not a step
        rec.on_chunk(b"z" * 24, t, mono)
    rid = rec.current
    rec.close()
    st = rec.clock_status()
    assert st["steps"] == 2 and st["last_step"]["step_s"] == pytest.approx(-0.7)
    assert st["last_step"]["count"] == 2
    events = [json.loads(line) for line in (rec.dir / f"{rid}.events.jsonl").open()]
    assert [(e["kind"], e["step_s"]) for e in events] == [("clock_step", 3600.0),
                                                          ("clock_step", -0.7)]


FSIZE_WRITER = textwrap.dedent("""
    import resource, signal, sys
    from radar_io.errors import StorageError
    from radar_io.recording.rdrlog import RecordingWriter
    from radar_io.wirespec.frame import load_spec
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (50_000, 50_000))
    w = RecordingWriter({path!r}, load_spec())
    n = 0
    try:
        while True:
            w.write(bytes(range(256)) * 2)
            n += 1
    except StorageError as exc:
        print(n, exc.errno, exc, flush=True)
""")


def test_file_size_limit_in_a_subprocess(tmp_path):
    p = tmp_path / "lim.rdrlog"
    out = subprocess.run([sys.executable, "-c", FSIZE_WRITER.format(path=str(p))],
                         capture_output=True, text=True, timeout=60)
    n, err_no, msg = out.stdout.split(" ", 2)
    assert int(err_no) == errno.EFBIG and "size limit" in msg
    assert p.stat().st_size <= 50_000
    with RecordingReader(p) as r:
        assert len(list(r)) == int(n) and r.report.torn_tail_bytes == 0


def test_version_2_keeps_both_clocks_and_version_1_still_reads(tmp_path, spec):
    """v2 chunks carry the monotonic receive time beside the wall clock; a v1 file (no
    monotonic time) reads with mono_ns = t_ns; a damaged v1 chunk is skipped like a v2 one."""
    import json
    import struct
    import zlib

    from radar_io.recording import rdrlog

    p2 = tmp_path / "v2.rdrlog"
    with RecordingWriter(p2, spec) as w:
        for i in range(5):  # the wall clock steps back an hour after chunk 2
            w.write(payload(i), t_ns=10**18 + i * 10**6 - (3600 * 10**9 if i > 2 else 0),
                    mono_ns=5 * 10**9 + i * 10**6)
    with RecordingReader(p2) as r:
        assert r.version == 2 and r.header["format"] == "rdrlog/2"
        chunks = list(r)
    assert [c.mono_ns for c in chunks] == [5 * 10**9 + i * 10**6 for i in range(5)]
    steps = [rdrlog.clock_step_s(a.t_ns, a.mono_ns, b.t_ns, b.mono_ns)
             for a, b in pairwise(chunks)]
    assert steps == [0.0, 0.0, -3600.0, 0.0]

    p1 = tmp_path / "v1.rdrlog"
    hdr = json.dumps({"format": "rdrlog/1"}).encode()
    body = [rdrlog.encode_chunk_v1(payload(i), 1000 * i) for i in range(4)]
    damaged = bytearray(body[1])
    damaged[-1] ^= 0xFF
    body[1] = bytes(damaged)
    p1.write_bytes(rdrlog.FILE_MAGIC_V1 + struct.pack(">I", len(hdr)) + hdr
                   + struct.pack(">I", zlib.crc32(hdr)) + b"".join(body))
    assert is_recording(p1)
    with RecordingReader(p1) as r:
        got = list(r)
        assert r.version == 1 and r.report.corrupt_chunks == 1
    assert [c.data for c in got] == [payload(0), payload(2), payload(3)]
    assert [c.mono_ns for c in got] == [c.t_ns for c in got] == [0, 2000, 3000]
    with open(p1, "rb") as f:  # the payload sits right after the v1 chunk header
        f.seek(got[1].offset + got[1].head_size)
        assert f.read(len(payload(2))) == payload(2)
