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
