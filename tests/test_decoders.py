"""Both decoders against the spec: shared outside vectors, an independent encoder, each other."""

from __future__ import annotations

import json
import math

import independent
import numpy as np
import pytest
from conftest import assert_golden
from hypothesis import given, settings
from hypothesis import strategies as st

from radar_io.decoding.decoders import DECODE_COLUMNS, BatchDecoder, FrameDecoder, decode_bytes
from radar_io.encoding.rdr1 import FrameEncoder, encode_frames, raw_words
from radar_io.framing.framers import BatchFramer

EXACT = ("seq", "tod_s", "sr_m", "dsr_m", "el_deg", "del_deg", "az_deg", "daz_deg",
         "go", "rx_good", "sync", "sr_c_m", "el_c_deg", "az_c_deg", "auto", "servo_bw", "status_raw")
VEC_KEYS = {"sr_c": "sr_c_m", "el_c": "el_c_deg", "az_c": "az_c_deg", "x": "x_m", "y": "y_m",
            "h": "h_m"}


def _same(got, want, tol: float = 0.0) -> bool:
    if want is None:
        return got is None or (isinstance(got, float) and math.isnan(got))
    if got is None or (isinstance(got, float) and math.isnan(got)):
        return False
    return abs(got - want) <= tol


def test_shared_vectors_decode_bit_for_bit(vectors, spec):
    frames = [bytes.fromhex(v["hex"]) for v in vectors["frames"]]
    per = FrameDecoder(spec)
    batch = decode_bytes(b"".join(frames))
    assert batch.stats["frames"] == len(frames) and batch.stats["crc_errors"] == 0
    for i, (fr, v) in enumerate(zip(frames, vectors["frames"], strict=True)):
        m = per.decode(fr)
        for key, want in v["expect"].items():
            col = VEC_KEYS.get(key, key)
            tol = 1e-9 * max(1.0, abs(want)) if key in ("x", "y", "h") and want is not None else 0
            assert _same(m[col], want, tol), (i, v["note"], col, m[col], want)
            assert _same(float(batch[col][i]), want, tol), (i, v["note"], col, batch[col][i], want)


words = st.fixed_dictionaries({
    "seq": st.integers(0, 0xFFFF), "tod": st.integers(0, 863_999_999),
    "sr": st.integers(0, 0xFFFF), "dsr": st.integers(0, 0xFFF), "el": st.integers(-32768, 32767),
    "dele": st.integers(0, 0xFFF), "az": st.integers(0, 0xFFFF), "daz": st.integers(0, 0xFFF),
    "sts": st.integers(0, 0xFFFF),
})


@pytest.mark.slow
@settings(max_examples=300, deadline=None)
@given(st.lists(words, min_size=1, max_size=40))
def test_independent_frames_decode_identically_in_both_decoders(spec, ws):
    frames = [independent.frame(**w) for w in ws]
    per = FrameDecoder(spec)
    batch = decode_bytes(b"".join(frames))
    assert len(batch) == len(frames)
    for i, fr in enumerate(frames):
        want = independent.decode(fr)
        got = per.decode(fr)
        for col in EXACT:
            assert _same(got[col], want[col]), (col, got[col], want[col])
            b = batch[col][i]
            assert _same(None if isinstance(b, float) and math.isnan(b) else float(b), want[col]), col
        for col in ("x_m", "y_m", "h_m"):
            # coordinates: per frame uses math.cos, batch exact-angle tables; 1 µm at 66 km
            assert _same(got[col], want[col], 1e-6), col
            b = float(batch[col][i])
            assert _same(None if math.isnan(b) else b, want[col], 1e-6), col


@pytest.mark.slow
@settings(max_examples=200, deadline=None)
@given(st.lists(st.binary(min_size=20, max_size=20), min_size=1, max_size=30),
       st.floats(-50, 50), st.floats(-1, 1), st.floats(-1, 1))
def test_per_frame_and_batch_agree_on_arbitrary_frames(spec, bodies, b_sr, b_el, b_az):
    """Arbitrary words (any status, any angles, any biases): the two decoders agree."""
    from radar_io.decoding.biases import Calibration

    cal = Calibration(dsr_m=b_sr, del_deg=b_el, daz_deg=b_az)
    frames = []
    for body in bodies:
        w = bytearray(b"\xeb\x90" + body)
        for off in (10, 14, 18):  # keep the 12-bit words plausible
            w[off] &= 0x0F
        w[4] &= 0x31  # TOD below 24 h (0x31FFFFFF < 864e6)
        frames.append(independent.frame(*independent.LAYOUT.unpack(bytes(w))[1:]))
    per = FrameDecoder(spec, calibration=cal)
    batch = decode_bytes(b"".join(frames), cal)
    assert len(batch) == len(frames)
    for i, fr in enumerate(frames):
        got = per.decode(fr)
        assert list(got) == list(batch.columns)
        for col in batch.columns:
            b = batch[col][i].item()
            b = None if isinstance(b, float) and math.isnan(b) else b
            tol = 1e-6 if col in ("x_m", "y_m", "h_m") else 0.0
            assert _same(b, got[col], tol), (col, b, got[col])


@pytest.mark.slow
@settings(max_examples=150, deadline=None)
@given(words)
def test_project_encoders_match_the_independent_encoder(spec, w):
    raw = {"seq": w["seq"], "tod": w["tod"], "sr": w["sr"], "dsr": w["dsr"], "el": w["el"] & 0xFFFF,
           "del": w["dele"], "az": w["az"], "daz": w["daz"], "sts": w["sts"]}
    want = independent.frame(**w)
    assert FrameEncoder(spec).encode_raw(raw) == want
    assert encode_frames(spec, {k: np.array([v]) for k, v in raw.items()}) == want


@pytest.mark.slow
@settings(max_examples=150, deadline=None)
@given(sr=st.floats(0, 65535), dsr=st.floats(-50, 49.97), el=st.floats(-180, 179.99),
       dele=st.floats(-1, 0.999), az=st.floats(0, 359.99), daz=st.floats(-1, 0.999),
       seq=st.integers(0, 65535), tod=st.floats(0, 86399.9))
def test_encode_then_decode_round_trips_to_half_an_lsb(spec, sr, dsr, el, dele, az, daz, seq, tod):
    vals = {"seq": seq, "tod_s": tod, "sr_m": sr, "dsr_m": dsr, "el_deg": el, "del_deg": dele,
            "az_deg": az, "daz_deg": daz, "status_raw": 0x0005}
    raw = raw_words(spec, vals)
    data = encode_frames(spec, raw)
    m = FrameDecoder(spec).decode(data)
    for f in spec.fields:
        if f.unit in ("count", "bits"):
            assert m[f.column] == vals[f.column]
        else:
            assert abs(m[f.column] - vals[f.column]) <= f.lsb / 2 + 1e-9, f.name
    assert decode_bytes(data)["sr_m"][0] == m["sr_m"]


def test_batch_coordinates_accurate_to_a_micrometre_at_max_range(spec):
    """The table method vs float64 trigonometry of the compensated angles, over every EL/AZ code."""
    n = 65536
    rng = np.random.default_rng(5)
    raw = {"seq": np.arange(n) & 0xFFFF, "tod": np.zeros(n, np.int64), "sr": np.full(n, 65535),
           "dsr": rng.integers(0, 4096, n), "el": np.arange(n), "del": rng.integers(0, 4096, n),
           "az": rng.permutation(n), "daz": rng.integers(0, 4096, n), "sts": np.full(n, 0x0005)}
    b = decode_bytes(encode_frames(spec, raw))
    el, az, sr = np.deg2rad(b["el_c_deg"]), np.deg2rad(b["az_c_deg"]), b["sr_c_m"]
    assert np.max(np.abs(b["x_m"] - sr * np.cos(el) * np.cos(az))) < 1e-6
    assert np.max(np.abs(b["y_m"] - sr * np.cos(el) * np.sin(az))) < 1e-6
    assert np.max(np.abs(b["h_m"] - sr * np.sin(el))) < 1e-6


def test_ng_samples_carry_no_position(spec):
    fr = independent.frame(sr=10000, el=100, az=200, sts=0x0001)  # GO without RX_GOOD
    m = FrameDecoder(spec).decode(fr)
    assert m["go"] == 1 and m["rx_good"] == 0 and m["sr_m"] == 10000.0
    assert all(m[c] is None for c in ("sr_c_m", "el_c_deg", "az_c_deg", "x_m", "y_m", "h_m"))
    b = decode_bytes(fr)
    assert all(np.isnan(b[c][0]) for c in ("sr_c_m", "el_c_deg", "az_c_deg", "x_m", "y_m", "h_m"))


def test_calibration_biases_apply_after_compensation(spec):
    from radar_io.decoding.biases import Calibration

    fr = independent.frame(sr=5000, dsr=0x800 + 41, el=1000, dele=0x800 - 20, az=65530,
                           daz=0x800 + 100, sts=0x0005)
    cal = Calibration(dsr_m=3.5, del_deg=-0.02, daz_deg=0.04)
    want = independent.decode(fr)
    for m in (FrameDecoder(spec, calibration=cal).decode(fr),
              {k: v[0].item() for k, v in ((c, decode_bytes(fr, cal)[c]) for c in DECODE_COLUMNS)}):
        assert m["sr_c_m"] == pytest.approx(want["sr_c_m"] + 3.5, abs=1e-9)
        assert m["el_c_deg"] == pytest.approx(want["el_c_deg"] - 0.02, abs=1e-12)
        assert m["az_c_deg"] == pytest.approx((want["az_c_deg"] + 0.04) % 360, abs=1e-12)


def test_batch_decoder_accepts_blocks_and_set_calibration(spec):
    from radar_io.decoding.biases import Calibration

    data = b"".join(independent.frame(seq=i, sr=1000 + i, sts=5) for i in range(50))
    fw = BatchFramer(spec)
    blocks = fw.feed_blocks(data)
    dec = BatchDecoder(spec)
    a = dec.decode(blocks)
    dec.set_calibration(Calibration(dsr_m=2.0))
    b = dec.decode(np.concatenate(blocks))
    assert np.array_equal(b["sr_c_m"], a["sr_c_m"] + 2.0)


# ---------------------------------------------------------------- chunked decode
@pytest.mark.slow
@pytest.mark.parametrize("block_frames", [65536, 1000, 7, 3])
@pytest.mark.parametrize("name", ["clean", "damaged"])
def test_decode_bytes_reproduces_the_previous_decoder_exactly(golden, name, block_frames):
    """Columns, dtypes, column order and counters as main's decoder gave them (tests/data)."""
    from radar_io.decoding.biases import Calibration

    data = golden[f"input_{name}"].tobytes()
    for cname, cal in (("nocal", None), ("cal", Calibration(dsr_m=2.5, del_deg=-0.013, daz_deg=0.021))):
        b = decode_bytes(data, cal, block_frames=block_frames)
        assert_golden(b, golden, f"{name}/{cname}")


def _per_frame(data: bytes, spec):
    from radar_io.framing.core import Framer

    f, dec = Framer(spec), FrameDecoder(spec)
    rows = [dec.decode(fr) for fr in f.feed(data)]
    f.flush()
    return rows, f.stats.as_dict()


def _same_rows(batch_cols: dict, rows: list[dict]) -> None:
    n = len(rows)
    for col, v in batch_cols.items():
        assert len(v) == n, col
        want = np.array([np.nan if r[col] is None else r[col] for r in rows], dtype=np.float64)
        tol = 1e-6 if col in ("x_m", "y_m", "h_m") else 0.0
        assert np.allclose(v.astype(np.float64), want, rtol=0, atol=tol, equal_nan=True), col


@pytest.mark.slow
def test_iter_decode_every_split_point_of_a_damaged_stream(spec, golden):
    """Two chunks split at every byte, tiny blocks: same frames and counters as the per-frame path."""
    from radar_io.decoding.batch_decoder import BatchDecoder, iter_decode

    data = golden["input_damaged"].tobytes()[:24 * 60]
    rows, stats = _per_frame(data, spec)
    assert stats["crc_errors"] > 0 and stats["frames"] > 20          # really damaged
    dec = BatchDecoder(spec)
    for k in range(len(data) + 1):
        batches = list(iter_decode([data[:k], data[k:]], block_frames=7, decoder=dec))
        assert all(1 <= len(b) <= 7 for b in batches[:-1]) and len(batches[-1]) == 0
        assert batches[-1].stats == stats, k
        cols = {c: np.concatenate([b[c] for b in batches]) for c in batches[0].columns}
        assert [int(s) for s in cols["seq"]] == [r["seq"] for r in rows], k
        if k % 97 == 0:                                  # every column, on a sample of the splits
            _same_rows(cols, rows)


@pytest.mark.parametrize("block_frames", [1, 5, 24, 1000])
def test_decode_bytes_every_block_split_of_a_damaged_stream(spec, golden, block_frames):
    """Block boundaries fall at every phase of the frames: nothing lost, nothing doubled."""
    data = golden["input_damaged"].tobytes()[:24 * 400]
    _rows, stats = _per_frame(data, spec)
    for shift in range(0, 24, 5):                  # move every boundary inside the frames
        b = decode_bytes(data[shift:], block_frames=block_frames)
        want_rows, want_stats = _per_frame(data[shift:], spec)
        assert b.stats == want_stats
        _same_rows({c: b[c] for c in b.columns}, want_rows)
    assert decode_bytes(data, block_frames=block_frames).stats == stats


def test_iter_decode_yields_each_chunk_before_reading_the_next():
    """A live source (a pipe, a serial port): frames come out as soon as their chunk is in."""
    from radar_io.decoding.batch_decoder import iter_decode

    frames = [independent.frame(seq=i, sr=100 + i, sts=5) for i in range(10)]
    read = []

    def live():
        for i in range(0, 10, 3):
            read.append(i)
            yield b"".join(frames[i:i + 3])

    for batch in iter_decode(live(), block_frames=65536):
        if len(batch):
            assert batch["seq"].tolist() == list(range(read[-1], min(read[-1] + 3, 10)))
    assert batch.stats["frames"] == 10 and len(batch) == 0


def test_iter_decode_takes_bytes_paths_files_and_chunk_iterables(tmp_path, golden):
    from radar_io.decoding.batch_decoder import iter_decode

    data = golden["input_damaged"].tobytes()
    want = decode_bytes(data)
    p = tmp_path / "capture.bin"
    p.write_bytes(data)
    chunks = [data[i:i + 1000] for i in range(0, len(data), 1000)]
    with open(p, "rb") as f:
        for source in (data, memoryview(data), str(p), p, f, iter(chunks)):
            batches = list(iter_decode(source, block_frames=512))
            assert all(1 <= len(b) <= 512 for b in batches[:-1]) and len(batches[-1]) == 0
            assert batches[-1].stats == want.stats
            for col in want.columns:
                got = np.concatenate([b[col] for b in batches])
                assert np.array_equal(got, want[col], equal_nan=got.dtype.kind == "f"), col


@pytest.mark.slow
def test_bench_measures_a_fresh_process_with_anchors_from_the_same_run():
    """`radar-io bench --json`: fresh-child figures and anchors that agree with each other."""

    from conftest import run_cli

    r = run_cli("bench", "--json", "--frames", "20000", "--repeat", "1", "--core-only")
    assert r.returncode == 0, r.stderr
    res = json.loads(r.stdout)
    c, d = res["clean"], res["damaged_1pct"]
    # the clean stream: every frame accepted, by the decoder and by the plain-Python reference
    assert c["frames_in"] == c["frames_accepted"] == c["reference_frames_ok"] == 20000
    assert c["stats"]["crc_errors"] == 0 and c["bytes"] == 24 * 20000
    # the damaged stream (bytes XORed, alignment kept) loses the same frames in both
    assert d["stats"]["crc_errors"] > 0
    assert d["reference_frames_ok"] == d["frames_accepted"] < 0.95 * 20000
    for x in (c, d):
        assert x["first_call_vs_reference"] == x["reference_s"] / x["first_call_s"]
        assert x["best_vs_reference"] == x["reference_s"] / x["best_of_n_s"]
        # a fresh child: its own peak, not the parent's (which holds both streams)
        assert x["rss_before_mib"] <= x["peak_rss_mib"]
    assert res["batch_damaged_1pct_accepted"] == d["frames_accepted"]
