"""Table outputs (CSV, JSONL, Parquet, Arrow IPC): the decoder's rows exactly, one column
order, file metadata, atomic files (no output left after an error or a kill)."""

from __future__ import annotations

import csv
import json
import math
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from conftest import ROOT, run_cli

from radar_io.decoding.decoders import POSITION_COLUMNS, decode_bytes
from radar_io.recording.rdrlog import RecordingReader
from radar_io.sinks import TABLE_FORMATS, open_table, table_format
from radar_io.sinks.arrow_convert import batch_to_arrow, file_sha256, read_metadata

FORMATS = tuple(TABLE_FORMATS)


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    d = tmp_path_factory.mktemp("rec")
    rec = d / "approach.rdrlog"
    r = run_cli("simulate", "-o", str(rec), "--duration-s", "12", "--ng-per-min", "30",
                "--flip-rate", "1e-4", "--drop-rate", "1e-4", "-q")
    assert r.returncode == 0, r.stderr
    return rec


@pytest.fixture(scope="module")
def reference(recording):
    """What decode_bytes gives for the recording's payloads."""
    with RecordingReader(recording) as rd:
        return decode_bytes(b"".join(c.data for c in rd))


@pytest.fixture(scope="module")
def decoded(recording, tmp_path_factory):
    """The recording decoded by the CLI into every format: format → path."""
    d = tmp_path_factory.mktemp("out")
    out = {}
    for fmt in FORMATS:
        p = d / f"approach.{fmt}"
        r = run_cli("decode", str(recording), "-o", str(p), "-q")
        assert r.returncode == 0, r.stderr
        out[fmt] = p
    return out


def _rows(batch) -> list[tuple]:
    """The batch as Python rows, NaN → None."""
    cols = [batch[c].tolist() for c in batch.columns]
    return [tuple(None if isinstance(v, float) and math.isnan(v) else v for v in row)
            for row in zip(*cols, strict=True)]


# -- batch_to_arrow ---------------------------------------------------------------------
@pytest.mark.slow
def test_batch_to_arrow_shares_buffers_nulls_ng_and_names_units(reference):
    rb = batch_to_arrow(reference, {"site": "demo"})
    assert rb.schema.names == list(reference.columns)
    assert rb.num_rows == len(reference)
    ng = reference["rx_good"] == 0
    assert ng.any() and (~ng).any()
    for c in reference.columns:
        a, arr = reference[c], rb.column(c)
        assert arr.buffers()[1].address == a.ctypes.data, f"{c} was copied"
        if c in POSITION_COLUMNS:
            assert arr.null_count == int(ng.sum())
            assert np.array_equal(arr.is_null().to_numpy(zero_copy_only=False), ng)
        else:
            assert arr.null_count == 0
    units = {f.name: f.metadata[b"unit"].decode() for f in rb.schema}
    assert units["sr_m"] == "m" and units["az_c_deg"] == "deg" and units["tod_s"] == "s"
    assert units["seq"] == "count" and units["status_raw"] == "bits" and units["go"] == "1"
    assert read_metadata(rb.schema) == {"site": "demo"}


def test_table_format_from_extension_or_option():
    assert table_format("a.parquet") == "parquet" and table_format("a.ARROW") == "arrow"
    assert table_format("a.jsonl") == "jsonl" and table_format("a.txt") == "csv"
    assert table_format("a.csv", "parquet") == "parquet"
    from radar_io.errors import ValidationError

    with pytest.raises(ValidationError, match="unknown table format 'xls'"):
        table_format("a.csv", "xls")


# -- the CLI's files read back -----------------------------------------------------------
@pytest.mark.slow
def test_parquet_read_by_pyarrow_and_duckdb_gives_decode_bytes_rows(decoded, reference,
                                                                    recording):
    import duckdb
    want = _rows(reference)
    t = pq.read_table(decoded["parquet"])
    assert t.schema.names == list(reference.columns)
    got = [tuple(r.values()) for r in t.to_pylist()]
    assert got == want
    con = duckdb.connect()
    try:
        rows = con.execute("SELECT * FROM read_parquet(?)", [str(decoded["parquet"])]).fetchall()
        names = [d[0] for d in con.description]
    finally:
        con.close()
    assert names == list(reference.columns)
    assert rows == want
    f = pq.ParquetFile(decoded["parquet"])
    md = read_metadata(f.schema_arrow)
    assert md["spec_version"] == "RDR1-1.0" and md["calibration_id"] == "none"
    assert md["source_file"] == "approach.rdrlog"
    assert md["source_sha256"] == file_sha256(recording)
    assert f.metadata.row_group(0).column(0).compression == "ZSTD"
    assert all(f.metadata.row_group(i).num_rows <= 1_000_000
               for i in range(f.metadata.num_row_groups))
    assert f.schema_arrow.field("h_m").metadata[b"unit"] == b"m"


@pytest.mark.slow
def test_arrow_ipc_read_back_equals_parquet(decoded):
    with pa.memory_map(str(decoded["arrow"])) as src:
        t = pa.ipc.open_file(src).read_all()
    p = pq.read_table(decoded["parquet"])
    assert t.equals(p, check_metadata=True)


@pytest.mark.slow
def test_every_format_same_columns_same_order_same_values(decoded, reference):
    cols = list(reference.columns)
    with open(decoded["csv"], newline="") as f:
        rows = list(csv.reader(f))
    assert rows[0] == cols
    with open(decoded["jsonl"]) as f:
        objs = [json.loads(line) for line in f]
    assert all(list(o) == cols for o in objs)
    assert pq.read_schema(decoded["parquet"]).names == cols
    with pa.memory_map(str(decoded["arrow"])) as src:
        assert pa.ipc.open_file(src).schema.names == cols
    want = _rows(reference)
    assert len(rows) - 1 == len(objs) == len(want)
    # text formats give the decoder's float64 to the last bit (shortest round-trip text)
    assert [tuple(o.values()) for o in objs] == want
    parsed = [tuple(None if v == "" else (float(v) if isinstance(w, float) else int(v))
                    for v, w in zip(r, wr, strict=True)) for r, wr in zip(rows[1:], want, strict=True)]
    assert parsed == want


def test_writers_stream_in_row_groups(reference, tmp_path):
    from radar_io.sinks.table_parquet import ParquetTableWriter

    out = tmp_path / "small_groups.parquet"
    w = open_table(str(out), metadata={"site": "t"})
    assert isinstance(w, ParquetTableWriter)
    w.ROW_GROUP_ROWS = 1000
    n = len(reference)
    for s in range(0, n, 777):  # batches that straddle row groups
        sl = {c: reference[c][s:s + 777] for c in reference.columns}
        w.write(type(reference)(sl, {}, reference.columns))
    assert not out.exists()  # only under a temporary name until closed
    w.close()
    f = pq.ParquetFile(out)
    sizes = [f.metadata.row_group(i).num_rows for i in range(f.metadata.num_row_groups)]
    assert sizes[:-1] == [1000] * (len(sizes) - 1) and sum(sizes) == n
    assert [tuple(r.values()) for r in f.read().to_pylist()] == _rows(reference)
    assert [p.name for p in tmp_path.iterdir()] == ["small_groups.parquet"]


@pytest.mark.slow
def test_no_frames_gives_a_complete_empty_table_with_the_columns(tmp_path):
    garbage = tmp_path / "garbage.bin"
    garbage.write_bytes(np.random.default_rng(7).integers(0, 256, 50_000, np.uint8)
                        .tobytes().replace(b"\xeb\x90", b"\x00\x00"))
    for fmt in FORMATS:
        out, stats = tmp_path / f"g.{fmt}", tmp_path / f"g.{fmt}.json"
        r = run_cli("decode", str(garbage), "-o", str(out), "--stats", str(stats), "-q")
        assert r.returncode == 0, r.stderr
        st = json.loads(stats.read_text())
        assert st["frames"] == 0 and st["bytes_discarded"] == 50_000
        if fmt == "parquet":
            t = pq.read_table(out)
            assert t.num_rows == 0 and t.schema.names[:3] == ["seq", "tod_s", "sr_m"]
        elif fmt == "csv":
            assert out.read_text().startswith("seq,tod_s,sr_m,")


# -- errors and interruptions leave nothing that looks complete ----------------------------
def _leftovers(d, name):
    return sorted(p.name for p in d.iterdir() if name in p.name)


@pytest.mark.slow
def test_damaged_recording_header_one_line_error_and_no_output(recording, tmp_path):
    bad = tmp_path / "bad.rdrlog"
    data = bytearray(recording.read_bytes())
    data[20] ^= 0xFF  # inside the JSON header: its CRC fails
    bad.write_bytes(bytes(data))
    for fmt in FORMATS:
        out = tmp_path / f"bad.{fmt}"
        r = run_cli("decode", str(bad), "-o", str(out), "-q")
        err = r.stderr.decode().strip()
        assert r.returncode == 2
        assert len(err.splitlines()) == 1 and "bad.rdrlog" in err and "header" in err, err
        assert _leftovers(tmp_path, f"bad.{fmt}") == []


@pytest.mark.slow
def test_truncated_recording_counts_and_still_writes(recording, tmp_path):
    cut = tmp_path / "cut.rdrlog"
    data = recording.read_bytes()
    cut.write_bytes(data[:len(data) - 1001])
    out, stats = tmp_path / "cut.parquet", tmp_path / "cut.json"
    r = run_cli("decode", str(cut), "-o", str(out), "--stats", str(stats), "-q")
    assert r.returncode == 0, r.stderr
    st = json.loads(stats.read_text())
    assert st["recording"]["torn_tail_bytes"] > 0
    assert "torn tail" in r.stderr.decode()
    assert pq.read_metadata(out).num_rows == st["frames"] > 0


def _close_pipes(p: subprocess.Popen) -> None:
    for f in (p.stdin, p.stdout, p.stderr):
        if f is not None:
            try:
                f.close()
            except BrokenPipeError:
                pass


def _start_slow_decode(tmp_path, fmt, first: bytes):
    out = tmp_path / f"live.{fmt}"
    p = subprocess.Popen([sys.executable, "-m", "radar_io.cli", "decode", "-", "-o", str(out),
                          "-q"], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, cwd=ROOT)
    assert p.stdin is not None
    p.stdin.write(first)
    p.stdin.flush()
    deadline = time.monotonic() + 60
    while not any(n.endswith(".part") for n in _leftovers(tmp_path, f"live.{fmt}")):
        assert p.poll() is None, p.stderr.read() if p.stderr else ""
        assert time.monotonic() < deadline, "decode never created its temporary file"
        time.sleep(0.02)
    return p, out


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
@pytest.mark.parametrize("fmt", ["parquet", "csv"])
def test_interrupted_decode_leaves_no_output_and_keeps_the_old_file(recording, tmp_path,
                                                                    sig, fmt):
    with RecordingReader(recording) as rd:
        payload = b"".join(c.data for c in rd)
    (tmp_path / f"live.{fmt}").write_bytes(b"previous complete file")
    p, out = _start_slow_decode(tmp_path, fmt, payload * 2)
    try:
        p.send_signal(sig)
        p.wait(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
        _close_pipes(p)
    assert p.returncode == 130
    assert _leftovers(tmp_path, f"live.{fmt}") == [f"live.{fmt}"]
    assert out.read_bytes() == b"previous complete file"


@pytest.mark.slow
def test_killed_decode_leaves_only_a_hidden_part_file(recording, tmp_path):
    with RecordingReader(recording) as rd:
        payload = b"".join(c.data for c in rd)
    p, out = _start_slow_decode(tmp_path, "parquet", payload)
    try:
        p.kill()
        p.wait(timeout=60)
    finally:
        _close_pipes(p)
    assert not out.exists()
    left = _leftovers(tmp_path, "live.parquet")
    assert left and all(n.startswith(".live.parquet.") and n.endswith(".part") for n in left)


@pytest.mark.slow
def test_binary_formats_to_stdout_refused_in_one_line(recording):
    r = run_cli("decode", str(recording), "--format", "parquet", "-q")
    assert r.returncode == 2
    assert r.stderr.decode().strip() == "radar-io: error: parquet output needs a file " \
                                        "(-o OUT.parquet)"
    assert r.stdout == b""


@pytest.mark.slow
def test_metadata_names_site_and_calibration(recording, tmp_path):
    cal = tmp_path / "cal.json"
    cal.write_text(json.dumps({"format": "radar_io-calibration/1", "id": "flight-7",
                               "biases": {"dsr_m": 1.0, "del_deg": 0.0, "daz_deg": 0.0}}))
    site = ROOT / "firmware_specs" / "sites" / "demo.toml"
    out = tmp_path / "s.arrow"
    r = run_cli("decode", str(recording), "-o", str(out), "--site", str(site),
                "--calibration", str(cal), "-q")
    assert r.returncode == 0, r.stderr
    with pa.memory_map(str(out)) as src:
        t = pa.ipc.open_file(src).read_all()
    md = read_metadata(t.schema)
    assert md["calibration_id"] == "flight-7" and md["site"] not in ("", "unspecified")
    assert t.schema.names[-6:] == ["xr_m", "yr_m", "hr_m", "lat_deg", "lon_deg", "hae_m"]
    assert t.schema.field("lat_deg").metadata[b"unit"] == b"deg"
    assert os.path.getsize(out) > 0


@pytest.mark.slow
@pytest.mark.parametrize("fmt", ["csv", "jsonl"])
def test_stdout_reader_gone_stops_quietly(recording, fmt):
    p = subprocess.Popen([sys.executable, "-m", "radar_io.cli", "decode", str(recording),
                          "--format", fmt, "-q"], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, cwd=ROOT)
    try:
        assert p.stdout is not None and p.stderr is not None
        first = p.stdout.readline()
        p.stdout.close()  # like `| head -1`
        err = p.stderr.read()
        p.wait(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
        p.stderr.close()
    assert first.startswith(b"seq,tod_s," if fmt == "csv" else b'{"seq":0,')
    assert p.returncode == 0 and err == b""


def test_measurement_batch_to_arrow_matches_the_columns():
    """MeasurementBatch.to_arrow(): the decode columns in order, values equal, NaN as null,
    units in the field metadata."""
    import pyarrow as pa

    from radar_io import decode_bytes
    from radar_io.simulation.radar import FlightScript, RadarSimulator, SimConfig

    data, _ = RadarSimulator(FlightScript(), SimConfig(seed=5)).generate(3000)
    batch = decode_bytes(data)
    rb = batch.to_arrow({"source": "sim"})
    assert isinstance(rb, pa.RecordBatch) and rb.num_rows == len(batch) == 3000
    assert tuple(rb.schema.names) == tuple(batch.keys())
    for name in batch:
        col = np.asarray(batch[name])
        got = rb.column(name).to_numpy(zero_copy_only=False)
        if col.dtype.kind == "f":
            nan = np.isnan(col)
            assert rb.column(name).null_count == int(nan.sum())
            np.testing.assert_array_equal(got[~nan].astype(float), col[~nan])
        else:
            np.testing.assert_array_equal(got, col)
    assert rb.schema.field("sr_m").metadata[b"unit"] == b"m"
    assert rb.schema.metadata[b"radar_io.source"] == b"sim"
