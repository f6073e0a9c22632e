"""The look-back index (radar_io.analysis.series): every answer equals numpy min / max over
the same buckets of ``decode_bytes``, with each frame timed by the per-frame framer fed
chunk by chunk (the live path's rule); open recordings grow, stale and damaged indexes
are rebuilt."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from radar_io.analysis.series import (
    FANOUT,
    SeriesIndex,
    SeriesOptions,
    index_dir,
    range_min_max,
)
from radar_io.coordinates.reference_path import add_deviation, load_path
from radar_io.coordinates.transforms import load_site
from radar_io.decoding.batch_decoder import decode_bytes
from radar_io.decoding.biases import Calibration
from radar_io.errors import StorageError, ValidationError
from radar_io.framing.core import Framer
from radar_io.recording.rdrlog import RecordingReader, RecordingWriter, encode_chunk
from radar_io.simulation.radar import FlightScript, RadarSimulator, SimConfig

PATH_FILE = Path(__file__).resolve().parents[1] / "firmware_specs" / "paths" / "demo_track_radar.toml"
T0_NS = 1_790_000_000_000_000_000
MONO0_NS = 5_000_000_000


def simulated_chunks(spec, seconds: float, seed: int = 3, damaged: bool = True
                     ) -> list[tuple[int, int, bytes]]:
    """(t_ns, mono_ns, payload) of a 1 kHz flight with many NG dropouts (and bit damage),
    cut into chunks of random sizes; the wall clock steps back once (mono does not)."""
    cfg = SimConfig(seed=seed, ng_per_min=60.0, flip_rate=2e-5 if damaged else 0.0,
                    sync_every_s=0.5, go_delay_s=0.3)
    data = b"".join(RadarSimulator(FlightScript(), cfg, spec).stream(duration_s=seconds))
    rng = np.random.default_rng(seed)
    out, pos, mono = [], 0, MONO0_NS
    while pos < len(data):
        n = int(rng.integers(1, 3000))
        mono += int(rng.integers(1, 40)) * 1_000_000
        wall = T0_NS + (mono - MONO0_NS) - (2_000_000_000 if len(out) > 10 else 0)
        out.append((wall, mono, data[pos:pos + n]))
        pos += n
    return out


def write_recording(path: Path, spec, chunks) -> RecordingWriter:
    w = RecordingWriter(path, spec, fsync_interval_s=3600)
    for t, m, d in chunks:
        w.write(d, t, m)
    return w


def reference(spec, chunks, options: SeriesOptions) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Frame times by the per-frame framer fed chunk by chunk, columns by decode_bytes."""
    fr = Framer(spec)
    times = []
    for _, mono, d in chunks:
        times += [(mono - chunks[0][1]) / 1e9] * len(fr.feed(d))
    b = decode_bytes(b"".join(d for _, _, d in chunks), options.calibration, spec=spec,
                     site=options.site)
    if options.path is not None:
        b = add_deviation(b, options.path)
    assert len(b) == len(times)
    return np.array(times), {c: np.asarray(b[c], dtype=np.float64) for c in b.columns}


def expected(t, cols, names, start_s, end_s, points):
    """The answer computed the slow, obvious way."""
    last = t[-1]
    s = 0.0 if start_s is None else min(max(start_s, 0.0), last)
    e = last if end_s is None else min(max(end_s, 0.0), last)
    inside = np.flatnonzero((t >= s) & (t <= e))
    if inside.size <= points:
        return {"decimated": False, "t_s": t[inside], "start_s": s, "end_s": e,
                "columns": {c: (cols[c][inside], cols[c][inside]) for c in names}}
    edges = np.minimum(s + np.arange(points) * ((e - s) / points), e)
    out = {c: (np.full(points, np.nan), np.full(points, np.nan)) for c in names}
    for k in range(points):
        hi = t <= e if k == points - 1 else t < edges[k + 1]
        rows = np.flatnonzero((t >= edges[k]) & hi)
        for c in names:
            v = cols[c][rows]
            v = v[~np.isnan(v)]
            if v.size:
                out[c][0][k], out[c][1][k] = v.min(), v.max()
    return {"decimated": True, "t_s": edges, "start_s": s, "end_s": e, "columns": out}


def as_array(values) -> np.ndarray:
    return np.array([np.nan if v is None else v for v in values], dtype=np.float64)


def check(answer, want, points) -> None:
    assert answer["decimated"] is want["decimated"]
    assert (answer["start_s"], answer["end_s"]) == (want["start_s"], want["end_s"])
    np.testing.assert_array_equal(np.array(answer["t_s"]), want["t_s"])
    for c, (mn, mx) in want["columns"].items():
        got = answer["columns"][c]
        assert len(got["min"]) <= points and len(got["max"]) <= points
        np.testing.assert_array_equal(as_array(got["min"]), mn, err_msg=c)
        np.testing.assert_array_equal(as_array(got["max"]), mx, err_msg=c)


@pytest.fixture(scope="module")
def flight(spec, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("series")
    chunks = simulated_chunks(spec, 40.0)
    rec = tmp / "flight.rdrlog"
    write_recording(rec, spec, chunks).close()
    options = SeriesOptions(spec, Calibration(dsr_m=1.5, del_deg=0.01, daz_deg=-0.02, id="c1"),
                            load_site("demo"), load_path(PATH_FILE))
    t, cols = reference(spec, chunks, options)
    return rec, chunks, options, t, cols


COLUMNS = ["h_m", "dy_m", "el_c_deg", "lat_deg", "seq", "go", "sync", "rx_good", "leg",
           "az_deg", "tod_s"]


@pytest.mark.parametrize("start_s,end_s,points", [
    (None, None, 1000), (None, None, 7), (3.3, 17.9, 500), (0.0, 0.7, 1000),
    (12.0, 12.35, 1000), (10.0, 30.0, 3), (5.5, 5.5, 1000), (-4.0, 99.0, 999),
    (39.0, None, 10), (7.77, 8.01, 150)])
def test_answers_equal_numpy_min_max_over_the_same_buckets(flight, start_s, end_s, points):
    rec, _, options, t, cols = flight
    assert np.isnan(cols["h_m"]).sum() > 1000  # NG rows: null samples to skip
    answer = SeriesIndex(rec, options).series(COLUMNS, start_s, end_s, points)
    check(answer, expected(t, cols, COLUMNS, start_s, end_s, points), points)
    assert answer["frames"] == int(((t >= answer["start_s"]) & (t <= answer["end_s"])).sum())


def test_ranges_of_every_shape_against_the_pyramid(flight):
    """Random row ranges, from empty to the whole column, through range_min_max directly."""
    rec, _, options, _, cols = flight
    idx = SeriesIndex(rec, options)
    man = idx.update()
    _, levels = idx._open(man, ["h_m", "seq"])
    n = man["rows"]
    assert len(levels["h_m"]) >= 3  # pyramid levels 1.. exist
    rng = np.random.default_rng(7)
    a = rng.integers(0, n, 400)
    b = np.minimum(n, a + (10 ** rng.uniform(0, np.log10(n), 400)).astype(np.int64))
    a[:3], b[:3] = [0, 5, n - 1], [n, 5, n]
    for c in ("h_m", "seq"):
        mn, mx = range_min_max(levels[c], a, b)
        for k in range(a.size):
            v = cols[c][a[k]:b[k]]
            v = v[~np.isnan(v)]
            if v.size:
                assert (mn[k], mx[k]) == (v.min(), v.max())
            else:
                assert np.isnan(mn[k]) and np.isnan(mx[k])


def test_events_are_the_live_edges_and_the_event_log(flight, tmp_path):
    rec, chunks, options, t, cols = flight
    local = tmp_path / rec.name
    local.write_bytes(rec.read_bytes())
    wall0, mono0 = chunks[0][0], chunks[0][1]
    log_lines = [{"kind": "annotation", "t_ns": T0_NS, "mono_ns": mono0 + 2_500_000_000,
                  "text": "gear down"},
                 {"type": "alarm", "action": "raise", "id": "x", "t_s": (wall0 + 3e9) / 1e9},
                 {"kind": "sync", "t_ns": T0_NS, "mono_ns": mono0, "seq": 1},  # from the frames
                 "not an object", {"kind": "no time"}]
    local.with_suffix(".events.jsonl").write_text(
        "\n".join(json.dumps(r) for r in log_lines) + "\n{broken\n")
    ev = SeriesIndex(local, options).events()
    go, sync = cols["go"], cols["sync"]
    want = []
    for i in range(len(t)):  # the reader thread's rule, frame by frame
        if go[i] != (go[i - 1] if i else 0):
            want.append(("go", "rise" if go[i] else "fall", t[i], cols["seq"][i]))
        if sync[i] and not (sync[i - 1] if i else 0):
            want.append(("sync", None, t[i], cols["seq"][i]))
    got = [(e["kind"], e.get("edge"), e["t_s"], e["seq"]) for e in ev
           if e["kind"] in ("go", "sync")]
    assert got == want and len(want) > 40
    note = next(e for e in ev if e["kind"] == "annotation")
    assert note["t_s"] == 2.5 and note["text"] == "gear down"
    alarm = next(e for e in ev if e["kind"] == "alarm")
    assert alarm["t_s"] == pytest.approx(3.0, abs=1e-6)  # no mono_ns: mapped by the wall clock
    assert len([e for e in ev if e["kind"] not in ("go", "sync")]) == 2
    assert [e["t_s"] for e in ev] == sorted(e["t_s"] for e in ev)


def test_open_recording_is_queryable_up_to_its_last_whole_chunk_and_grows(spec, tmp_path):
    chunks = simulated_chunks(spec, 12.0, seed=5)
    options = SeriesOptions(spec, site=load_site("demo"))
    rec = tmp_path / "open.rdrlog"
    w = write_recording(rec, spec, [])
    written = 0
    assert len(chunks) > 150
    for upto in (100, 101, 150, len(chunks)):
        for t_ns, mono, d in chunks[written:upto]:
            w.write(d, t_ns, mono)
        written = upto
        committed = w.committed_bytes
        with open(rec, "ab") as f:  # a chunk being written: past committed_bytes, torn
            f.write(b"CHK2" + os.urandom(30))
        idx = SeriesIndex(rec, options)
        answer = idx.series(["h_m", "seq"], points=10_000_000, end=committed)
        t, cols = reference(spec, chunks[:upto], options)
        assert idx.last_update == ("built" if upto == 100 else "appended")
        check(answer, expected(t, cols, ["h_m", "seq"], None, None, 10_000_000), 10_000_000)
        with open(rec, "r+b") as f:
            f.truncate(committed)
    w.close()
    assert SeriesIndex(rec, options).series(["h_m"], points=5)["frames"] == len(t)


def test_stale_index_is_rebuilt_and_a_grown_file_extended(flight, tmp_path, spec):
    rec, chunks, options, _, _ = flight
    local = tmp_path / rec.name
    write_recording(local, spec, chunks[:200]).close()
    SeriesIndex(local, options).update()
    other = SeriesOptions(spec, Calibration(dsr_m=-7.0, id="c2"), options.site, options.path)
    idx = SeriesIndex(local, other)
    answer = idx.series(["sr_c_m", "dy_m"], points=50)
    assert idx.last_update == "rebuilt"
    t, cols = reference(spec, chunks[:200], other)
    check(answer, expected(t, cols, ["sr_c_m", "dy_m"], None, None, 50), 50)
    with open(local, "ab") as f:  # the file grew (chunks appended after it was indexed)
        f.write(b"".join(encode_chunk(d, t_ns, mono) for t_ns, mono, d in chunks[200:300]))
    idx = SeriesIndex(local, other)
    answer = idx.series(["sr_c_m"], points=50)
    assert idx.last_update == "appended"
    t, cols = reference(spec, chunks[:300], other)
    check(answer, expected(t, cols, ["sr_c_m"], None, None, 50), 50)
    SeriesIndex(local, SeriesOptions(spec, other.calibration)).update()  # no site, no path
    idx = SeriesIndex(local, other)
    idx.update()
    assert idx.last_update == "rebuilt"


@pytest.mark.parametrize("damage", ["manifest", "truncate", "header", "missing", "level",
                                    "events"])
def test_damaged_index_is_rebuilt(flight, tmp_path, damage):
    rec, _, options, t, cols = flight
    local = tmp_path / rec.name
    local.write_bytes(rec.read_bytes())
    SeriesIndex(local, options).events()
    d = index_dir(local)
    target = {"manifest": d / "manifest.json", "truncate": d / "h_m.npy",
              "header": d / "h_m.npy", "missing": d / "t_s.npy", "level": d / "h_m.2.npy",
              "events": d / "events.jsonl"}[damage]
    if damage == "manifest":
        target.write_text("{not json")
    elif damage == "truncate":
        with open(target, "r+b") as f:
            f.truncate(target.stat().st_size // 2)
    elif damage == "header":
        with open(target, "r+b") as f:
            f.write(b"garbage!" * 4)
    elif damage == "missing":
        target.unlink()
    elif damage == "level":
        target.write_bytes(b"")
    else:
        target.write_text("")
    idx = SeriesIndex(local, options)
    if damage == "events":
        assert len(idx.events()) > 40 and idx.last_update == "rebuilt"
        return
    answer = idx.series(["h_m"], 2.0, 30.0, 300)
    assert idx.last_update == "rebuilt"
    check(answer, expected(t, cols, ["h_m"], 2.0, 30.0, 300), 300)


def test_bad_requests_and_no_room(flight, tmp_path):
    rec, _, options, _, _ = flight
    idx = SeriesIndex(rec, options)
    with pytest.raises(ValidationError, match="unknown column 'nope'"):
        idx.series(["h_m", "nope"])
    with pytest.raises(ValidationError, match="after end_s"):
        idx.series(["h_m"], 5.0, 4.0)
    with pytest.raises(ValidationError, match="finite"):
        idx.series(["h_m"], float("nan"))
    local = tmp_path / rec.name
    local.write_bytes(rec.read_bytes())
    with pytest.raises(StorageError, match="bytes free") as exc:
        SeriesIndex(local, options, reserve_bytes=1 << 62).update()
    assert exc.value.errno is not None
    # nothing left behind but the (empty) lock file
    assert sorted(p.name for p in tmp_path.iterdir()) == [".flight.series.lock", local.name]


def test_empty_recording_and_block_boundaries(spec, tmp_path, monkeypatch):
    options = SeriesOptions(spec)
    empty = tmp_path / "empty.rdrlog"
    RecordingWriter(empty, spec, fsync_interval_s=3600).close()
    answer = SeriesIndex(empty, options).series(["h_m"])
    assert answer["frames"] == 0 and answer["t_s"] == [] and answer["columns"]["h_m"]["min"] == []
    # tiny build blocks: frames and pyramid blocks straddle every boundary
    from radar_io.analysis import series

    monkeypatch.setattr(series, "BLOCK_BYTES", 1000)
    chunks = simulated_chunks(spec, 3.0, seed=9)
    rec = tmp_path / "small.rdrlog"
    write_recording(rec, spec, chunks).close()
    t, cols = reference(spec, chunks, options)
    answer = SeriesIndex(rec, options).series(["h_m", "x_m"], 0.1, 2.9, 3)
    check(answer, expected(t, cols, ["h_m", "x_m"], 0.1, 2.9, 3), 3)
    assert len(t) > FANOUT ** 2


def test_version_1_recording_uses_its_wall_clock(spec, tmp_path):
    from radar_io.recording.rdrlog import FILE_MAGIC_V1, encode_chunk_v1

    chunks = simulated_chunks(spec, 2.0, seed=4, damaged=False)
    rec = tmp_path / "old.rdrlog"
    write_recording(rec, spec, []).close()
    with RecordingReader(rec) as r:
        head = rec.read_bytes()[len(FILE_MAGIC_V1):r.data_offset]
    hdr = json.loads(head[4:-4])
    hdr["format"] = "rdrlog/1"
    import struct
    import zlib

    raw = json.dumps(hdr).encode()
    rec.write_bytes(FILE_MAGIC_V1 + struct.pack(">I", len(raw)) + raw
                    + struct.pack(">I", zlib.crc32(raw))
                    + b"".join(encode_chunk_v1(d, t) for t, _, d in chunks))
    answer = SeriesIndex(rec, SeriesOptions(spec)).series(["seq"], points=100_000)
    t = np.array(answer["t_s"])
    assert np.all(np.diff(t) >= 0) and t[0] == 0.0  # the backward wall-clock step is held
    assert answer["frames"] == len(decode_bytes(b"".join(d for _, _, d in chunks)))


def test_two_processes_building_the_same_index_at_once(flight, tmp_path):
    """The index is locked across processes (``flock``): both get the right answer, one
    builds, the other finds it fresh; one directory, no temporary left."""
    from concurrent.futures import ProcessPoolExecutor

    from radar_io.analysis.series import query_series

    rec, _, options, t, cols = flight
    local = tmp_path / rec.name
    local.write_bytes(rec.read_bytes())
    with ProcessPoolExecutor(2) as pool:
        answers = list(pool.map(query_series, [local] * 2, [options] * 2, [["h_m"]] * 2,
                                [1.0] * 2, [30.0] * 2, [400] * 2))
    for a in answers:
        check(a, expected(t, cols, ["h_m"], 1.0, 30.0, 400), 400)
    assert sorted(p.name for p in tmp_path.iterdir()) == [".flight.series.lock", "flight.rdrlog",
                                                          "flight.series"]
