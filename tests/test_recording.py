"""Recordings: append-only, crash-safe, damaged tails and middles skipped, decoded like raw bytes."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

import independent
from radar_io.decoding.decoders import decode_bytes, iter_decode
from radar_io.errors import RecordingError
from radar_io.coordinates.transforms import load_site
from radar_io.recording.rdrlog import (RecordingReader, RecordingWriter, encode_chunk, is_recording,
                                iter_payloads)
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
    with pytest.raises(RecordingError, match="not an .rdrlog"):
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
    with pytest.raises(StorageError, match="fsync failed.*Input/output error"):
        w.write(b"after")
    with pytest.raises(StorageError, match="fsync failed"):
        w.close()
    assert w.closed


def test_recorder_on_a_full_disk_never_raises_and_retries(tmp_path, spec, monkeypatch):
    budget = [0]
    disk_full_after(monkeypatch, "recordings", budget)
    rec = Recorder(tmp_path, spec, None, "test", auto="go", retry_s=0.2)
    frame = independent.frame(seq=1, sts=5)
    rec.on_chunk(frame, 1)
    rec.on_go_edge(True)  # GO rises: the start fails, reported, not raised
    assert rec.current is None and "No space left" in rec.last_error
    assert list(rec.dir.iterdir()) == []
    rec.on_chunk(frame, 2)  # before retry_s: no new attempt
    assert rec.storage()["errors"] == 1
    budget[0] = 1 << 30  # space is back
    time.sleep(0.25)
    rec.on_chunk(frame, 3)  # retried on the next chunk
    assert rec.current is not None and rec.last_error is None
    st = rec.storage()
    assert "No space left" in st["last_error"] and st["free_bytes"] > 0
    rec.stop()


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
             for a, b in zip(chunks, chunks[1:])]
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
