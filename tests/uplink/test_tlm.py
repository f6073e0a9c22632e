"""TLM1 uplink frames (radar-interface.md §8), checked with a decoder written from the markdown."""

from __future__ import annotations

import binascii
import math
import socket
import struct

import numpy as np
import pytest
from conftest import ROOT

from radar_io.coordinates.reference_path import ReferencePath, add_deviation
from radar_io.coordinates.transforms import load_site
from radar_io.decoding.decoders import decode_bytes
from radar_io.encoding.kinematics import Kinematics
from radar_io.encoding.tlm1 import TelemetryDecoder, TelemetryEncoder, load_tlm_spec
from radar_io.errors import SpecError, UplinkError
from radar_io.simulation.radar import FlightScript, RadarSimulator, SimConfig
from radar_io.sinks import open_sink
from radar_io.sinks.uplink import TelemetrySink

# ---- the independent reference, typed in from radar-interface.md §8
FRAME = struct.Struct(">HH10hH")
SCALES = [("dy_m", 500.0), ("dz_m", 150.0), ("xr_m", 30000.0), ("yr_m", 30000.0),
          ("hr_m", 6000.0), ("sr_c_m", 60000.0), ("ground_speed_mps", 200.0), ("track_deg", 180.0)]
#: the channel names of firmware_specs/tlm1.toml, for the saturation counters
CHANNEL = {"dy_m": "dy", "dz_m": "dz", "xr_m": "xr", "yr_m": "yr", "hr_m": "hr", "sr_c_m": "sr"}


def ref_decode(data: bytes) -> list[dict]:
    """Frames back to back: sync 0x1ACF, seq, 10 x i16, CRC-16/CCITT-FALSE over bytes 0..23."""
    assert len(data) % 26 == 0
    out = []
    for k in range(0, len(data), 26):
        fr = data[k:k + 26]
        sync, seq, *ch, crc = FRAME.unpack(fr)
        assert sync == 0x1ACF
        assert crc == binascii.crc_hqx(fr[:24], 0xFFFF)
        d = {"seq": seq, "words": ch, "sts": ch[8] & 0xFFFF, "spare": ch[9]}
        for (name, fs), w in zip(SCALES, ch[:len(SCALES)], strict=True):  # then sts, spare
            d[name] = w * fs / 32767
        out.append(d)
    return out


def columns(n: int, rng, *, beyond: float = 1.5) -> dict[str, np.ndarray]:
    """Synthetic measurement columns; values up to ``beyond`` x full scale; straight-line motion."""
    t = 1000.0 + np.arange(n) * 1e-3
    cols = {"tod_s": t, "rx_good": (rng.random(n) > 0.1).astype(np.uint8),
            "go": (rng.random(n) > 0.1).astype(np.uint8),
            "status_raw": rng.integers(0, 65536, n),
            "x_m": -9000.0 + 55.0 * (t - t[0]), "y_m": 3000.0 - 40.0 * (t - t[0])}
    for name, fs in SCALES[:6]:
        cols[name] = rng.uniform(-beyond * fs, beyond * fs, n)
    return cols


def test_frames_decode_back_within_one_lsb_and_saturation_is_counted():
    rng = np.random.default_rng(1)
    cols = columns(3000, rng)
    enc = TelemetryEncoder()
    data = enc.encode_batch(cols)
    valid = np.flatnonzero((cols["rx_good"] == 1) & (cols["go"] == 1))
    frames = ref_decode(data)
    assert len(frames) == valid.size == enc.frames
    assert [f["seq"] for f in frames] == list(range(valid.size))
    for name, fs in SCALES[:6]:
        got = np.array([f[name] for f in frames])
        want = np.clip(cols[name][valid], -fs, fs)
        assert np.max(np.abs(got - want)) <= fs / 32767 * (0.5 + 1e-9)
        sat = np.abs(cols[name][valid]) > fs * (1 + 1 / 65534)
        assert enc.saturation[CHANNEL[name]] == sat.sum() > 0
        # saturated values come back exactly at the limit, never wrapped
        assert np.all(np.abs(got[sat]) == fs) and np.all(np.sign(got[sat]) == np.sign(cols[name][valid][sat]))
    assert [f["sts"] for f in frames] == cols["status_raw"][valid].tolist()
    assert all(f["spare"] == 0 for f in frames)
    # straight line at (55, -40) m/s: ground speed 68.007 m/s, track -36.03 deg once the 1 s window fills
    gs = np.array([f["ground_speed_mps"] for f in frames])
    trk = np.array([f["track_deg"] for f in frames])
    t = cols["tod_s"][valid]
    ready = t - cols["tod_s"][0] >= 0.5 + 0.01
    assert np.max(np.abs(gs[ready] - math.hypot(55, -40))) <= 200 / 32767 / 2 + 1e-9
    assert np.max(np.abs(trk[ready] - math.degrees(math.atan2(-40, 55)))) <= 180 / 32767 / 2 + 1e-9
    early = t - cols["tod_s"][0] < 0.5 - 0.01
    assert np.all(gs[early] == 0) and np.all(trk[early] == 0)
    assert enc.unavailable["ground_speed"] == enc.unavailable["track"] >= early.sum()


def test_per_frame_path_equals_batch_path():
    rng = np.random.default_rng(2)
    cols = columns(200, rng)
    cols["rx_good"][:] = 1
    cols["go"][:] = 1
    cols["ground_speed_mps"] = rng.uniform(-300, 300, 200)
    cols["track_deg"] = rng.uniform(-180, 180, 200)
    cols["track_deg"][:3] = np.nan
    a, b = TelemetryEncoder(seq_start=65500), TelemetryEncoder(seq_start=65500)
    batch = a.encode_batch(cols)
    one = b"".join(b.encode_frame({k: float(v[i]) for k, v in cols.items()}) for i in range(200))
    assert batch == one
    assert a.saturation == b.saturation and a.unavailable == b.unavailable
    assert a.unavailable["track"] == 3 and a.saturation["ground_speed"] > 0
    assert [f["seq"] for f in ref_decode(batch)][34:37] == [65534, 65535, 0]
    dec = TelemetryDecoder()
    frame = batch[26 * 7:26 * 8]
    assert dec.decode_frame(frame)["dy_m"] == pytest.approx(ref_decode(frame)[0]["dy_m"], abs=1e-12)
    with pytest.raises(UplinkError, match="CRC"):
        dec.decode_frame(frame[:-1] + bytes([frame[-1] ^ 1]))


def test_seq_continues_across_batches_and_only_valid_samples_send():
    rng = np.random.default_rng(3)
    enc = TelemetryEncoder(seq_start=65534)
    cols = columns(50, rng, beyond=0.5)
    cols["rx_good"][:] = 1
    cols["go"][:] = 1
    cols["go"][10:20] = 0          # GO = 0: no frames
    cols["rx_good"][30:35] = 0     # NG: no frames
    first = {k: v[:25] for k, v in cols.items()}
    second = {k: v[25:] for k, v in cols.items()}
    data = enc.encode_batch(first) + enc.encode_batch(second)
    seqs = [f["seq"] for f in ref_decode(data)]
    assert len(seqs) == 35
    assert seqs[:3] == [65534, 65535, 0] and seqs[-1] == 32


def test_cycle_limits_the_frame_rate():
    rng = np.random.default_rng(4)
    cols = columns(1000, rng, beyond=0.5)
    cols["rx_good"][:] = 1
    cols["go"][:] = 1
    cols["rx_good"][100:130] = 0           # an NG stretch covering a whole 20 ms cycle
    enc = TelemetryEncoder(cycle_s=0.02)
    data = b"".join(enc.encode_batch({k: v[i:i + 77] for k, v in cols.items()})
                    for i in range(0, 1000, 77))
    tods = np.array([cols["tod_s"][i] for i in range(1000)])
    cyc = np.floor(tods / 0.02)
    good = cols["rx_good"] == 1
    assert len(ref_decode(data)) == np.unique(cyc[good]).size


def test_decoder_hunts_counts_and_survives_damage():
    rng = np.random.default_rng(5)
    cols = columns(400, rng, beyond=0.5)
    cols["rx_good"][:] = 1
    cols["go"][:] = 1
    data = bytearray(TelemetryEncoder().encode_batch(cols))
    data[26 * 10 + 7] ^= 0x10                    # frame 10: CRC error
    del data[26 * 20:26 * 21]                     # frame 20 lost: a SEQ gap
    data[26 * 50:26 * 50] = b"\x1a\xcf\x00junk"   # garbage with a false sync word
    data = bytes(data)
    one = TelemetryDecoder()
    whole = one.feed(data)
    one.flush()
    assert one.stats == {"frames": 398, "crc_errors": 2, "implausible": 0, "bytes_discarded": 26 + 7,
                         "seq_gaps": 2}
    chunked = TelemetryDecoder()
    parts, pos = [], 0
    while pos < len(data):
        n = int(rng.integers(1, 60))
        parts.append(chunked.feed(data[pos:pos + n]))
        pos += n
    chunked.flush()
    assert chunked.stats == one.stats
    for k, v in whole.items():
        assert np.array_equal(np.concatenate([p[k] for p in parts]), v)


def test_missing_columns_are_one_clear_error():
    cols = columns(10, np.random.default_rng(6))
    del cols["xr_m"]
    with pytest.raises(UplinkError, match=r"channel 3 \(xr\) needs column 'xr_m' \(decode with --site\)"):
        TelemetryEncoder().encode_batch(cols)


def test_kinematics_is_the_same_in_any_batching_and_across_midnight():
    t = 86399.0 + np.arange(3000) * 1e-3
    tod = np.mod(t, 86400.0)
    rng = np.random.default_rng(7)
    x = 100.0 + 30.0 * (t - t[0]) + rng.normal(0, 1, t.size)
    y = -50.0 - 60.0 * (t - t[0]) + rng.normal(0, 1, t.size)
    x[1500:1700] = np.nan                          # NG
    cols = {"tod_s": tod, "x_m": x, "y_m": y}
    whole = Kinematics().update(cols)
    k = Kinematics()
    parts = [k.update({c: v[i:i + 333] for c, v in cols.items()}) for i in range(0, t.size, 333)]
    for c in whole:
        assert np.allclose(np.concatenate([p[c] for p in parts]), whole[c], equal_nan=True, atol=1e-9)
    gs = whole["ground_speed_mps"]
    assert np.isnan(gs[:490]).all() and np.isnan(gs[1500:1700]).all()
    ok = np.isfinite(gs)
    assert abs(np.mean(gs[ok]) - math.hypot(30, 60)) < 0.1        # noisy positions, 1 s window
    assert abs(np.mean(whole["track_deg"][ok]) - math.degrees(math.atan2(-60, 30))) < 0.1


def test_sinks_udp_serial_and_file(tmp_path):
    rng = np.random.default_rng(8)
    cols = columns(30, rng, beyond=0.5)
    cols["rx_good"][:] = 1
    cols["go"][:] = 1
    expected = TelemetryEncoder().encode_batch(cols)
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.settimeout(2.0)
    try:
        with TelemetrySink(f"udp://127.0.0.1:{rx.getsockname()[1]}") as sink:
            sink.send(cols)
        grams = [rx.recv(100) for _ in range(30)]
    finally:
        rx.close()
    assert all(len(g) == 26 for g in grams) and b"".join(grams) == expected
    sink = open_sink("tlm1", "loop://")
    sink.write(cols)
    got = sink.link.handle.read(len(expected))
    sink.close()
    assert got == expected
    f = tmp_path / "t.tlm"
    with TelemetrySink(str(f)) as sink:
        sink.send(cols)
    assert f.read_bytes() == expected
    with pytest.raises(UplinkError, match="udp://HOST:PORT"):
        TelemetrySink("udp://nohost")
    with pytest.raises(UplinkError, match="cannot write"):
        open_sink("tlm1", str(tmp_path / "missing" / "x.tlm"))


def test_on_a_decoded_simulated_flight(tmp_path):
    sim = RadarSimulator(FlightScript(), SimConfig(tod_start_s=5000.0, seed=9, ng_per_min=20))
    data, _ = sim.generate(6000)
    batch = decode_bytes(data, site=load_site(ROOT / "firmware_specs" / "sites" / "demo.toml"))
    path = ReferencePath([[-15000, 0, 700], [0, 0, 15]], 1000.0, frame="runway")
    batch = add_deviation(batch, path)
    out = tmp_path / "tlm.bin"
    with TelemetrySink(str(out)) as sink:
        for k in range(0, len(batch), 1500):   # as decode streams its batches
            sub = {c: batch[c][k:k + 1500] for c in batch.columns}
            sink.send(sub)
    frames = ref_decode(out.read_bytes())
    valid = (batch["rx_good"] == 1) & (batch["go"] == 1)
    assert len(frames) == valid.sum() == sink.encoder.frames
    for name, fs in SCALES[:6]:
        got = np.array([f[name] for f in frames])
        assert np.max(np.abs(got - batch[name][valid])) <= fs / 32767 * 0.5 + 1e-9
    assert sum(sink.encoder.saturation.values()) == 0


def test_spec_errors(tmp_path):
    text = (ROOT / "firmware_specs" / "tlm1.toml").read_text()
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace("offset = 6\n", "offset = 4\n", 1))
    with pytest.raises(SpecError, match="overlaps"):
        load_tlm_spec(bad)
    bad.write_text(text.replace("check = 0x29B1", "check = 0x1234"))
    with pytest.raises(SpecError, match="check value"):
        load_tlm_spec(bad)
    bad.write_text(text.replace('scaling = "raw_bits"', 'scaling = "log"'))
    with pytest.raises(SpecError, match="scaling must be"):
        load_tlm_spec(bad)
    bad.write_text(text.replace("full_scale = 500.0", "full_scale = -500.0"))
    with pytest.raises(SpecError, match="full_scale must be a positive"):
        load_tlm_spec(bad)


def test_infinities_saturate_and_just_over_full_scale_counts():
    from radar_io.encoding.tlm1 import channel_words, load_tlm_spec

    spec = load_tlm_spec()
    dy = next(c for c in spec.channels if c.name == "dy")
    w, sat, bad = channel_words(dy, np.array([np.inf, -np.inf, 500.005, 499.99, np.nan]),
                                spec.full_scale_count)
    assert w.view(np.int16).tolist() == [32767, -32767, 32767, 32766, 0]
    assert sat.tolist() == [True, True, True, False, False]
    assert bad.tolist() == [False, False, False, False, True]
