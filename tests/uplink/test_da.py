"""D/A recorder words (radar-interface.md §7), checked with a decoder written from the markdown."""

from __future__ import annotations

import struct

import numpy as np
import pytest
from conftest import ROOT

from radar_io.coordinates.reference_path import ReferencePath, add_deviation
from radar_io.decoding.decoders import decode_bytes
from radar_io.encoding.da import DAEncoder, decode_da_words, load_da_spec
from radar_io.errors import SpecError, UplinkError
from radar_io.simulation.radar import FlightScript, RadarSimulator, SimConfig
from radar_io.sinks import open_sink
from radar_io.sinks.uplink import DASink

# ---- typed in from radar-interface.md §7 and the documented defaults: channel → (column, full scale)
CHANNELS = [("x_m", 30000.0), ("y_m", 30000.0), ("dsr_m", 50.0), ("del_deg", 1.0),
            ("daz_deg", 1.0), ("dy_m", 500.0), ("dz_m", 150.0), ("h_m", 6000.0)]
#: channel 8 is Z = -H (§7 "8 Z", §5 "Z = -H is the right-handed down axis"): its sign per channel
SIGN = [1, 1, 1, 1, 1, 1, 1, -1]
NAMES = ["x", "y", "dsr", "del", "daz", "dy", "dz", "z"]


def ref_decode(data: bytes) -> list[list[tuple[int, int, int]]]:
    """Samples of 8 big-endian words: (pen_up, channel 0-7, data -2048..2047) each."""
    assert len(data) % 16 == 0
    out = []
    for k in range(0, len(data), 16):
        sample = []
        for w in struct.unpack(">8H", data[k:k + 16]):
            d = w & 0x0FFF
            sample.append((w >> 15, (w >> 12) & 7, d - 4096 if d >= 2048 else d))
        out.append(sample)
    return out


def columns(n: int, rng, beyond: float = 1.5) -> dict[str, np.ndarray]:
    cols = {c: rng.uniform(-beyond * fs, beyond * fs, n) for c, fs in CHANNELS}
    cols["rx_good"] = (rng.random(n) > 0.15).astype(np.uint8)
    cols["go"] = (rng.random(n) > 0.15).astype(np.uint8)
    return cols


def test_words_decode_back_within_one_lsb_and_saturate_without_wrapping():
    rng = np.random.default_rng(1)
    cols = columns(4000, rng)
    enc = DAEncoder()
    data = enc.encode_batch(cols)
    samples = ref_decode(data)
    assert len(samples) == 4000 == enc.samples                     # one group per sample
    valid = (cols["rx_good"] == 1) & (cols["go"] == 1)
    assert enc.pen_up_samples == (~valid).sum()
    for k, ((col, fs), name) in enumerate(zip(CHANNELS, NAMES, strict=True)):
        pen = np.array([s[k][0] for s in samples])
        ch = np.array([s[k][1] for s in samples])
        data12 = np.array([s[k][2] for s in samples])
        assert (ch == k).all()
        assert np.array_equal(pen == 1, ~valid)                     # PEN UP exactly on NG / GO = 0
        lsb = fs / 2048
        v = SIGN[k] * cols[col][valid]
        got = data12[valid] * lsb
        inside = (v >= -fs) & (v < fs - lsb / 2)
        assert np.max(np.abs(got[inside] - v[inside])) <= lsb / 2 + 1e-12
        # beyond full scale: clamped to the end of the range, never wrapped, and counted
        assert np.all(data12[valid][v >= fs] == 2047) and np.all(data12[valid][v < -fs - lsb / 2] == -2048)
        sat = (v >= fs - lsb / 2) | (v < -fs - lsb / 2)
        assert enc.saturation[name] == sat.sum() > 0


def test_pen_up_samples_hold_the_last_pen_down_data_across_batches():
    rng = np.random.default_rng(2)
    cols = columns(300, rng, beyond=0.9)
    enc = DAEncoder()
    data = b"".join(enc.encode_batch({c: v[i:i + 41] for c, v in cols.items()}) for i in range(0, 300, 41))
    assert data == DAEncoder().encode_batch(cols)                   # batching makes no difference
    samples = ref_decode(data)
    valid = (cols["rx_good"] == 1) & (cols["go"] == 1)
    held = [0] * 8                                                  # 0 before the first valid sample
    for i, s in enumerate(samples):
        if valid[i]:
            held = [w[2] for w in s]
        else:
            assert [w[2] for w in s] == held and all(w[0] == 1 for w in s)


def test_a_nan_value_lifts_only_its_own_pen(tmp_path):
    cols = columns(5, np.random.default_rng(3), beyond=0.5)
    cols["rx_good"][:] = 1
    cols["go"][:] = 1
    cols["dz_m"][2] = np.nan
    s = ref_decode(DAEncoder().encode_batch(cols))
    assert [w[0] for w in s[2]] == [0, 0, 0, 0, 0, 0, 1, 0]
    assert s[2][6][2] == s[1][6][2]                                 # holds the last value
    # pen_up_data = "zero", and channel 8 records H instead of Z = -H: both options of the spec file
    text = (ROOT / "firmware_specs" / "da_words.toml").read_text()
    f = tmp_path / "da.toml"
    f.write_text(text.replace('pen_up_data = "hold"', 'pen_up_data = "zero"')
                 .replace('source = "z_m"', 'source = "h_m"'))
    spec = load_da_spec(f)
    s = ref_decode(DAEncoder(spec).encode_batch(cols))
    assert s[2][6] == (1, 6, 0)
    assert s[0][7][2] == round(cols["h_m"][0] / (6000 / 2048))
    words = decode_da_words(DAEncoder(spec).encode_batch(cols), spec)
    assert words.values[0, 7] == pytest.approx(cols["h_m"][0], abs=6000 / 2048 / 2)


def test_channel_8_is_z_minus_h_by_default():
    """An aircraft 1000 m above the antenna: channel 8 reads -1000 m (Z = -H), channels 1-2 X, Y."""
    cols = {c: np.zeros(3) for c, _ in CHANNELS}
    cols["h_m"][:] = [1000.0, -250.0, 0.0]
    cols["x_m"][:] = [5000.0, 0.0, 0.0]
    cols["rx_good"] = np.ones(3, np.uint8)
    cols["go"] = np.ones(3, np.uint8)
    s = ref_decode(DAEncoder().encode_batch(cols))
    lsb = 6000 / 2048
    assert [x[7][2] for x in s] == [round(-1000 / lsb), round(250 / lsb), 0]
    assert s[0][0][2] == round(5000 / (30000 / 2048))
    assert decode_da_words(DAEncoder().encode_batch(cols)).values[0, 7] == pytest.approx(-1000, abs=lsb / 2)
    cols["z_m"] = np.array([7.0, 7.0, 7.0])     # a batch that carries Z itself is used as it is
    assert ref_decode(DAEncoder().encode_batch(cols))[0][7][2] == round(7 / lsb)
    del cols["z_m"], cols["h_m"]
    with pytest.raises(UplinkError, match=r"channel 8 \(z\) needs column 'z_m'"):
        DAEncoder().encode_batch(cols)


def test_library_decoder_and_sinks(tmp_path):
    cols = columns(50, np.random.default_rng(4))
    data = DAEncoder().encode_batch(cols)
    words = decode_da_words(data)
    ref = ref_decode(data)
    assert words.channels == tuple(NAMES)
    assert words.counts.tolist() == [[w[2] for w in s] for s in ref]
    assert words.pen_up.tolist() == [[bool(w[0]) for w in s] for s in ref]
    assert np.allclose(words.values, words.counts * np.array([fs / 2048 for _, fs in CHANNELS]))
    with pytest.raises(UplinkError, match="whole number"):
        decode_da_words(data[:-2])
    swapped = data[2:4] + data[0:2] + data[4:]
    with pytest.raises(UplinkError, match="channel numbers"):
        decode_da_words(swapped)
    f = tmp_path / "da.bin"
    with DASink(str(f)) as sink:
        sink.send(cols)
    assert f.read_bytes() == data
    sink = open_sink("da", "loop://")
    sink.write(cols)
    assert sink.link.handle.read(len(data)) == data
    sink.close()


def test_missing_dy_needs_a_path_and_real_flight():
    sim = RadarSimulator(FlightScript(), SimConfig(tod_start_s=100.0, seed=5, ng_per_min=30))
    data, _ = sim.generate(3000)
    batch = decode_bytes(data)
    with pytest.raises(UplinkError, match=r"needs column 'dy_m' \(decode with --path\)"):
        DAEncoder().encode_batch(batch)
    batch = add_deviation(batch, ReferencePath([[-15000, 4000, 600], [0, 0, 600]], 1000.0))
    enc = DAEncoder()
    samples = ref_decode(enc.encode_batch(batch))
    valid = (batch["rx_good"] == 1) & (batch["go"] == 1)
    assert (~valid).sum() > 0 and enc.pen_up_samples == (~valid).sum()
    for k, (col, fs) in enumerate(CHANNELS):
        got = np.array([s[k][2] for s in samples])[valid] * fs / 2048
        assert np.max(np.abs(got - SIGN[k] * batch[col][valid])) <= fs / 2048 / 2 + 1e-9


def test_spec_errors(tmp_path):
    text = (ROOT / "firmware_specs" / "da_words.toml").read_text()
    f = tmp_path / "bad.toml"
    for old, new, msg in [("data_mask = 0x0FFF", "data_mask = 0x0F0F", "contiguous"),
                          ("number = 8", "number = 9", "number must be 1 .. 8"),
                          ("number = 8", "number = 7", "numbers must be unique"),
                          ('pen_up_data = "hold"', 'pen_up_data = "last"', "pen_up_data"),
                          ("full_scale = 6000.0", 'full_scale = "6000 *"', "cannot parse"),
                          ('gain = 1.0', 'gian = 1.0', "channel 'z': unknown key 'gian'"),
                          ('pen_up_data = "hold"', 'pen_up_data = "hold"\nbyteorder = 1',
                           r"\[word\]: unknown key 'byteorder'")]:
        f.write_text(text.replace(old, new))
        with pytest.raises(SpecError, match=msg):
            load_da_spec(f)
