"""The campaign archive: three recordings → a Hive-partitioned Parquet dataset read by
DuckDB; idempotent re-runs; the queries of docs/analysis.md run on it."""

from __future__ import annotations

import datetime as dt
import math
import re

import duckdb
import numpy as np
import pyarrow.parquet as pq
import pytest
from conftest import ROOT, run_cli

from radar_io.coordinates.reference_path import add_deviation, load_path
from radar_io.coordinates.transforms import load_site
from radar_io.decoding.decoders import decode_bytes
from radar_io.recording.rdrlog import RecordingWriter
from radar_io.wirespec.frame import load_spec

PATH = ROOT / "firmware_specs" / "paths" / "demo_track_radar.toml"
SITE = ROOT / "firmware_specs" / "sites" / "demo.toml"
DAY1 = dt.datetime(2026, 5, 1, 9, 30, tzinfo=dt.UTC)
DAY2 = dt.datetime(2026, 5, 2, 14, 0, tzinfo=dt.UTC)


def _sim(tmp, name, *extra) -> bytes:
    raw = tmp / f"{name}.bin"
    r = run_cli("simulate", "-o", str(raw), "--duration-s", "6", "-q", *extra)
    assert r.returncode == 0, r.stderr
    return raw.read_bytes()


def _record(path, payload: bytes, start: dt.datetime, site=None) -> None:
    t0 = int(start.timestamp() * 1e9)
    with RecordingWriter(path, load_spec(), site=site, fsync_interval_s=60) as w:
        for k, s in enumerate(range(0, len(payload), 4800)):  # 0.2 s of frames per chunk
            w.write(payload[s:s + 4800], t0 + k * 200_000_000)


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    """Three recordings on two days; flight-1 has two runs and bit errors."""
    d = tmp_path_factory.mktemp("campaign")
    recs = d / "recordings"
    recs.mkdir()
    a = _sim(d, "a", "--flip-rate", "2e-5", "--seed", "3")
    b = _sim(d, "b", "--seed", "4", "--go-delay-s", "2")
    c = _sim(d, "c", "--seed", "5", "--ng-per-min", "40")
    payloads = {"flight-1": a + b, "flight-2": b, "flight-3": c}
    _record(recs / "flight-1.rdrlog", payloads["flight-1"], DAY1, site=load_site(SITE))
    _record(recs / "flight-2.rdrlog", payloads["flight-2"], DAY1 + dt.timedelta(hours=2))
    _record(recs / "flight-3.rdrlog", payloads["flight-3"], DAY2)
    # test points, added after the flight (radar-io annotate): TP1 in flight-2, TP2 (and a
    # marker inside it) in flight-3
    for rec, start, kind, label, after_s in (
            ("flight-2", DAY1 + dt.timedelta(hours=2), "test_point_start", "TP1", 1.5),
            ("flight-2", DAY1 + dt.timedelta(hours=2), "test_point_end", "TP1", 4.0),
            ("flight-3", DAY2, "test_point_start", "TP2", 2.0),
            ("flight-3", DAY2, "marker", "gust", 3.0),
            ("flight-3", DAY2, "test_point_end", "TP2", 5.0)):
        t_ns = int(start.timestamp() * 1e9) + int(after_s * 1e9)
        r = run_cli("annotate", str(recs / f"{rec}.rdrlog"), "--kind", kind, "--label", label,
                    "--t-ns", str(t_ns))
        assert r.returncode == 0, r.stderr
    return d, payloads


@pytest.fixture(scope="module")
def archived(campaign):
    d, payloads = campaign
    out = d / "archive"
    r = run_cli("archive", str(d / "recordings"), "--out", str(out), "--site-name", "range-a",
                "--path", str(PATH))
    assert r.returncode == 0, r.stderr
    assert "3 written, 0 up to date" in r.stderr.decode()
    path = load_path(PATH)
    ref = {k: add_deviation(decode_bytes(v), path) for k, v in payloads.items()}
    return out, ref


def _glob(out) -> str:
    return str(out / "**" / "*.parquet")


@pytest.mark.slow
def test_layout_row_counts_and_partition_columns_in_duckdb(archived):
    out, ref = archived
    files = sorted(p.relative_to(out).as_posix() for p in out.rglob("*.parquet"))
    assert files == ["site=range-a/date=2026-05-01/recording=flight-1/part-0.parquet",
                     "site=range-a/date=2026-05-01/recording=flight-2/part-0.parquet",
                     "site=range-a/date=2026-05-02/recording=flight-3/part-0.parquet"]
    rows = duckdb.sql(f"SELECT site, CAST(date AS VARCHAR), recording, count(*) FROM "
                      f"read_parquet('{_glob(out)}', hive_partitioning = true) "
                      f"GROUP BY ALL ORDER BY 3").fetchall()
    assert rows == [("range-a", "2026-05-01", "flight-1", len(ref["flight-1"])),
                    ("range-a", "2026-05-01", "flight-2", len(ref["flight-2"])),
                    ("range-a", "2026-05-02", "flight-3", len(ref["flight-3"]))]
    # the columns of `decode --path` in order, and the rows exactly
    con = duckdb.connect()
    try:
        got = con.execute(f"SELECT * FROM read_parquet('{out}/site=range-a/date=2026-05-02/"
                          f"recording=flight-3/part-0.parquet', hive_partitioning = false)").fetchall()
        names = [x[0] for x in con.description]
    finally:
        con.close()
    b = ref["flight-3"]
    assert names == list(b.columns)
    want = [tuple(None if isinstance(v, float) and math.isnan(v) else v for v in row)
            for row in zip(*(b[c].tolist() for c in b.columns), strict=True)]
    assert got == want
    md = pq.read_metadata(out / "site=range-a/date=2026-05-01/recording=flight-1/part-0.parquet")
    kv = {k.decode(): v.decode() for k, v in md.metadata.items()}
    assert kv["radar_io.source_file"] == "flight-1.rdrlog"
    assert kv["radar_io.spec_version"] == "RDR1-1.0"
    assert int(kv["radar_io.crc_errors"]) == ref["flight-1"].stats["crc_errors"] > 0


@pytest.mark.slow
def test_rerun_is_idempotent_and_rewrites_only_what_changed(campaign, archived, tmp_path):
    d, payloads = campaign
    out, _ = archived
    files = sorted(out.rglob("*.parquet"))
    before = {p: (p.stat().st_ino, p.stat().st_mtime_ns) for p in files}
    args = ("archive", str(d / "recordings"), "--out", str(out), "--site-name", "range-a",
            "--path", str(PATH))
    r = run_cli(*args)
    assert r.returncode == 0, r.stderr
    assert "0 written, 3 up to date" in r.stderr.decode()
    assert {p: (p.stat().st_ino, p.stat().st_mtime_ns) for p in files} == before
    # a recording that changed (here: one more chunk) is archived again, the others not
    extra = d / "recordings" / "flight-2.rdrlog"
    with open(extra, "ab") as f:
        from radar_io.recording.rdrlog import encode_chunk

        f.write(encode_chunk(payloads["flight-2"][:2400], int(DAY1.timestamp() * 1e9) + 10**12))
    r = run_cli(*args)
    assert "1 written, 2 up to date" in r.stderr.decode(), r.stderr
    changed = [p for p in files if (p.stat().st_ino, p.stat().st_mtime_ns) != before[p]]
    assert [p.parent.name for p in changed] == ["recording=flight-2"]
    assert pq.read_metadata(changed[0]).num_rows == len(decode_bytes(payloads["flight-2"])) + 100
    assert not [p for p in out.rglob("*") if p.name.endswith(".part")]


@pytest.mark.slow
def test_archive_recording_api_uses_the_header_site(campaign, tmp_path):
    from radar_io.analysis.archive import archive_recording

    d, payloads = campaign
    res = archive_recording(d / "recordings" / "flight-1.rdrlog", tmp_path)
    assert res.written and res.rows == len(decode_bytes(payloads["flight-1"]))
    site = load_site(SITE).name
    assert res.path == tmp_path / f"site={site}" / "date=2026-05-01" / "recording=flight-1" \
        / "part-0.parquet"
    again = archive_recording(d / "recordings" / "flight-1.rdrlog", tmp_path)
    assert not again.written and again.stats == res.stats
    # with a Site object: runway and geodetic columns, the site's name as partition
    res = archive_recording(d / "recordings" / "flight-3.rdrlog", tmp_path, site=load_site(SITE))
    assert pq.read_schema(res.path).names[-6:] == ["xr_m", "yr_m", "hr_m", "lat_deg",
                                                   "lon_deg", "hae_m"]


def test_missing_input_is_one_line(tmp_path):
    r = run_cli("archive", str(tmp_path / "nope.rdrlog"), "--out", str(tmp_path / "a"))
    assert r.returncode == 2
    assert r.stderr.decode().strip() == f"radar-io: error: recording not found: " \
                                        f"{tmp_path / 'nope.rdrlog'}"


# -- the queries of docs/analysis.md, run on the archive --------------------------------
def _doc_queries() -> dict[str, str]:
    text = (ROOT / "docs" / "analysis.md").read_text()
    out = {}
    for block in re.findall(r"```sql\n(.*?)```", text, re.S):
        m = re.match(r"-- query: (\w+)\n", block)
        if m:
            out[m.group(1)] = block
    return out


def _run(query: str, out) -> list[tuple]:
    return duckdb.sql(query.replace("'archive/", f"'{out}/")).fetchall()


def _valid(b) -> np.ndarray:
    return (b["go"] == 1) & (b["rx_good"] == 1)


@pytest.mark.slow
def test_doc_queries_dy_dz_per_run(archived):
    out, ref = archived
    rows = _run(_doc_queries()["dy_dz_per_run"], out)
    want = []
    for name in ("flight-1", "flight-2", "flight-3"):
        b = ref[name]
        go = b["go"].astype(int)
        run = np.cumsum((go == 1) & (np.r_[0, go[:-1]] == 0))
        for k in np.unique(run[_valid(b)]):
            sel = _valid(b) & (run == k)
            want.append((name, int(k), int(sel.sum()), b["dy_m"][sel].mean(),
                         b["dz_m"][sel].mean()))
    assert [r[2] for r in rows] == [w[0] for w in want]
    assert [r[3] for r in rows] == [1, 2, 1, 1]  # flight-1 holds two runs
    assert [(r[2], r[3], r[4]) for r in rows] == [w[:3] for w in want]
    np.testing.assert_allclose([(r[5], r[8]) for r in rows], [w[3:] for w in want],
                               rtol=1e-9, atol=1e-9)
    assert all(abs(r[8]) < 5 for r in rows)  # the simulated flight follows the path


def test_doc_queries_bias_per_flight(archived):
    out, ref = archived
    rows = _run(_doc_queries()["bias_per_flight"], out)
    assert [r[2] for r in rows] == ["flight-1", "flight-2", "flight-3"]
    assert {r[3] for r in rows} == {"none"}
    for r in rows:
        b = ref[r[2]]
        v = _valid(b)
        assert r[4] == int(v.sum())
        np.testing.assert_allclose([r[5], r[6]], [b["dy_m"][v].mean(), b["dz_m"][v].mean()],
                                   rtol=1e-9, atol=1e-9)


def test_doc_queries_crc_errors_per_day(archived):
    out, ref = archived
    rows = _run(_doc_queries()["crc_errors_per_day"], out)
    day1 = ref["flight-1"].stats["crc_errors"] + ref["flight-2"].stats["crc_errors"]
    assert rows == [("range-a", "2026-05-01", day1),
                    ("range-a", "2026-05-02", ref["flight-3"].stats["crc_errors"])]
    assert day1 > 0


@pytest.mark.slow
def test_a_damaged_recording_is_one_line_and_the_others_are_archived(campaign, tmp_path):
    d, _ = campaign
    recs = tmp_path / "recs"
    recs.mkdir()
    good = recs / "good.rdrlog"
    good.write_bytes((d / "recordings" / "flight-2.rdrlog").read_bytes())
    bad = recs / "bad.rdrlog"
    data = bytearray(good.read_bytes())
    data[20] ^= 0xFF  # inside the JSON header: its CRC fails
    bad.write_bytes(bytes(data))
    out = tmp_path / "archive"
    r = run_cli("archive", str(recs), "--out", str(out), "-q")
    err = r.stderr.decode().strip().splitlines()
    assert r.returncode == 2
    assert len(err) == 2 and "bad.rdrlog" in err[0] and "header" in err[0], err
    assert err[1] == "radar-io archive: 1 written, 0 up to date, 1 failed"
    files = [p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file()]
    assert files == ["site=unknown/date=2026-05-01/recording=good/part-0.parquet"]
    from radar_io.recording.rdrlog import RecordingReader

    with RecordingReader(good) as rd:
        want = len(decode_bytes(b"".join(c.data for c in rd)))
    assert pq.read_metadata(out / files[0]).num_rows == want > 0


def test_doc_query_test_point_stats_equals_the_report(archived):
    """The doc's test-point query (DuckDB, frames joined to the events table) gives the
    report's DY / DZ RMS and max |.| per test point."""
    from radar_io.analysis.flight_digest import digest_recording

    out, _ = archived
    rows = _run(_doc_queries()["test_point_stats"], out)
    assert [(r[2], r[3]) for r in rows] == [("flight-2", "TP1"), ("flight-3", "TP2")]
    recs = out.parent / "recordings"
    for r in rows:
        (tp,) = digest_recording(recs / f"{r[2]}.rdrlog", ref_path=load_path(PATH)).test_points()
        assert tp["label"] == r[3] and tp["samples"] == r[6] > 1000
        for got, want in zip(r[7:], (tp["dy_rms_m"], tp["dy_max_abs_m"], tp["dz_rms_m"],
                                     tp["dz_max_abs_m"]), strict=True):
            assert math.isclose(got, want, rel_tol=1e-9), (r, tp)
