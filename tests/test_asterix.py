"""ASTERIX CAT048: our records decoded by Wireshark's ASTERIX dissector (tshark)."""

from __future__ import annotations

import shutil
import socket
import struct
import subprocess
import types

import numpy as np
import pytest
from conftest import ROOT, run_cli

from radar_io.coordinates.transforms import load_site
from radar_io.decoding.decoders import decode_bytes
from radar_io.encoding.asterix_cat048 import (
    HEIGHT_LSB_M,
    RHO_LSB_M,
    THETA_LSB_DEG,
    TOD_LSB_S,
    Cat048Encoder,
    decode_records,
    write_asterix,
)
from radar_io.errors import ConfigError, EncodeError
from radar_io.simulation.radar import FlightScript, RadarSimulator, SimConfig
from radar_io.sinks import open_sink

TSHARK = shutil.which("tshark")
PORT = 30048
FIELDS = ("asterix.category", "asterix.048_010_SAC", "asterix.048_010_SIC",
          "asterix.048_140_VALUE", "asterix.048_020_TYP", "asterix.048_020_SIM",
          "asterix.048_020_SPI", "asterix.048_040_RHO", "asterix.048_040_THETA",
          "asterix.048_110_3DH")


def flight(n: int = 6000, seed: int = 9):
    sim = RadarSimulator(FlightScript(), SimConfig(tod_start_s=86397.0, seed=seed,
                                                   ng_per_min=20))
    data, _ = sim.generate(n)
    return decode_bytes(data, site=load_site(ROOT / "firmware_specs" / "sites" / "demo.toml"))


def write_pcap(path, datagrams: list[bytes], port: int = PORT) -> None:
    """A minimal pcap (LINKTYPE_RAW: IPv4 packets) of UDP datagrams 127.0.0.1 → port."""
    out = [struct.pack("<IHHiIII", 0xA1B2C3D4, 2, 4, 0, 0, 65535, 101)]
    for k, d in enumerate(datagrams):
        udp = struct.pack("!HHHH", 40000, port, 8 + len(d), 0) + d
        ip = struct.pack("!BBHHHBBH4s4s", 0x45, 0, 20 + len(udp), k & 0xFFFF, 0, 64, 17, 0,
                         socket.inet_aton("127.0.0.1"), socket.inet_aton("127.0.0.1"))
        s = sum(struct.unpack("!10H", ip))
        while s >> 16:
            s = (s & 0xFFFF) + (s >> 16)
        ip = ip[:10] + struct.pack("!H", ~s & 0xFFFF) + ip[12:]
        pkt = ip + udp
        out.append(struct.pack("<IIII", k, 0, len(pkt), len(pkt)) + pkt)
    path.write_bytes(b"".join(out))


def _num(text: str) -> float:
    """tshark prints integer fields in hex (0x19) and doubles in decimal."""
    return float(int(text, 16)) if text.startswith("0x") else float(text)


def tshark_fields(pcap) -> dict[str, np.ndarray]:
    """Every CAT048 record's fields as tshark decodes them (one column per field)."""
    res = subprocess.run([TSHARK, "-n", "-r", str(pcap), "-d", f"udp.port=={PORT},asterix",
                          "-T", "fields", "-E", "occurrence=a", "-E", "aggregator=;",
                          *(a for f in FIELDS for a in ("-e", f))],
                         capture_output=True, text=True, timeout=300, check=True)
    cols: dict[str, list[float]] = {f: [] for f in FIELDS}
    for line in res.stdout.splitlines():
        parts = line.split("\t")
        vals = [p.split(";") if p else [] for p in parts]
        n = len(vals[1])
        assert all(len(v) == n for v in vals[1:]), line[:200]
        cols[FIELDS[0]] += [_num(vals[0][0])] * n
        for f, v in zip(FIELDS[1:], vals[1:], strict=True):
            cols[f] += [_num(x) for x in v]
    return {f: np.array(v) for f, v in cols.items()}


@pytest.mark.skipif(TSHARK is None, reason="tshark (Debian package tshark) is not installed")
def test_tshark_decodes_every_record_within_one_lsb(tmp_path):
    batch = flight()
    cols = {c: batch[c] for c in batch.columns}
    enc = Cat048Encoder(sac=25, sic=201, simulated=True)
    blocks = []
    for k in range(0, len(batch), 777):       # as the service's chunks arrive
        blocks += enc.encode_blocks({c: v[k:k + 777] for c, v in cols.items()})
    assert all(len(b) <= 1472 for b in blocks)
    pcap = tmp_path / "cat048.pcap"
    write_pcap(pcap, blocks)
    got = tshark_fields(pcap)
    valid = (batch["rx_good"] == 1) & (batch["go"] == 1)
    assert 0 < valid.sum() < len(batch)            # NG samples exist and are left out
    n = int(valid.sum())
    assert len(got["asterix.048_010_SAC"]) == n == enc.records   # 100 % decoded
    assert (got["asterix.category"] == 48).all()
    assert (got["asterix.048_010_SAC"] == 25).all() and (got["asterix.048_010_SIC"] == 201).all()
    assert (got["asterix.048_020_TYP"] == 1).all() and (got["asterix.048_020_SIM"] == 1).all()
    np.testing.assert_array_equal(got["asterix.048_020_SPI"], batch["sync"][valid])
    tod = batch["tod_s"][valid] % 86400.0
    dt = (got["asterix.048_140_VALUE"] - tod + 43200.0) % 86400.0 - 43200.0
    assert np.abs(dt).max() <= TOD_LSB_S
    assert got["asterix.048_140_VALUE"].min() < 10 < 86380 < got["asterix.048_140_VALUE"].max()
    sr = got["asterix.048_040_RHO"] * 1852.0
    assert np.abs(sr - batch["sr_c_m"][valid]).max() <= RHO_LSB_M
    daz = (got["asterix.048_040_THETA"] - batch["az_c_deg"][valid] + 180.0) % 360.0 - 180.0
    assert np.abs(daz).max() <= THETA_LSB_DEG
    h = got["asterix.048_110_3DH"] * 0.3048
    assert np.abs(h - batch["h_m"][valid]).max() <= HEIGHT_LSB_M
    assert enc.saturation == {"rho": 0, "height": 0}
    # our own reader agrees with tshark record for record
    ours = decode_records(b"".join(blocks))
    np.testing.assert_allclose(ours["sr_m"], sr, atol=1e-6)


def test_values_round_to_the_nearest_lsb_and_saturate():
    cols = {"tod_s": np.array([0.0, 86399.999, 12.5, 1.0]), "rx_good": np.array([1, 1, 1, 0]),
            "go": np.array([1, 1, 1, 1]), "sync": np.array([0, 1, 0, 0]),
            "sr_c_m": np.array([-5.0, 1e6, 1852.0, 10.0]),
            "az_c_deg": np.array([359.999, 0.0, 90.0, 1.0]),
            "h_m": np.array([-3000.0, 1e6, 7.62, 1.0])}
    enc = Cat048Encoder(1, 2)
    r = decode_records(enc.encode_batch(cols))
    assert len(r["sr_m"]) == 3
    assert r["sr_m"][0] == 0 and r["sr_m"][1] == 65535 * RHO_LSB_M and r["sr_m"][2] == 1852.0
    assert r["az_deg"][0] == 0.0 and r["az_deg"][2] == 90.0       # 359.999 wraps to 0
    assert r["h_m"][0] == pytest.approx(-3000.0, abs=HEIGHT_LSB_M / 2)
    assert r["h_m"][1] == 8191 * HEIGHT_LSB_M and r["h_m"][2] == pytest.approx(7.62)
    assert r["tod_s"][1] == 0.0                                  # 86400 s wraps to midnight
    assert list(r["spi"]) == [0, 1, 0]
    assert enc.saturation == {"rho": 2, "height": 1}


def test_bad_sac_and_missing_columns_are_one_line():
    with pytest.raises(ConfigError, match=r"sac = 300 must be an integer 0 \.\. 255") as ei:
        Cat048Encoder.for_site(types.SimpleNamespace(name="north", asterix_sac=300,
                                                     asterix_sic=1))
    assert "\n" not in str(ei.value) and "north" in str(ei.value)
    with pytest.raises(ConfigError, match="sic"):
        Cat048Encoder(1, -1)
    with pytest.raises(EncodeError, match=r"h_m .*--site"):
        Cat048Encoder().encode_batch({"tod_s": np.zeros(1), "rx_good": np.ones(1),
                                      "go": np.ones(1), "sr_c_m": np.ones(1),
                                      "az_c_deg": np.ones(1)})


def test_udp_sink_sends_one_block_per_datagram_and_file_writer(tmp_path):
    batch = flight(3000, seed=3)
    cols = {c: batch[c] for c in batch.columns}
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.settimeout(5)
    try:
        sink = open_sink("asterix", f"udp://127.0.0.1:{rx.getsockname()[1]}", sac=7, sic=8)
        try:
            sink.write(cols)
            st = sink.stats()
        finally:
            sink.close()
        grams = [rx.recv(65535) for _ in range(st["blocks"])]
    finally:
        rx.close()
    for g in grams:     # each datagram is exactly one data block
        assert g[0] == 48 and int.from_bytes(g[1:3], "big") == len(g)
    got = decode_records(b"".join(grams))
    assert len(got["sr_m"]) == st["records"] > 0 and (got["sac"] == 7).all()
    path = tmp_path / "out.ast"
    enc = write_asterix([cols], str(path), site=types.SimpleNamespace(asterix_sac=7,
                                                                       asterix_sic=8))
    assert path.read_bytes() == b"".join(grams) and enc.records == st["records"]


def test_file_writer_appears_only_when_complete(tmp_path):
    from radar_io.sinks.asterix import AsterixFileWriter

    batch = flight(2000, seed=5)
    cols = {c: batch[c] for c in batch.columns}
    out = tmp_path / "run.ast"
    with pytest.raises(RuntimeError), AsterixFileWriter(str(out), metadata={"site": "demo"}) as w:
        w.write(cols)
        raise RuntimeError("interrupted")
    assert list(tmp_path.iterdir()) == []          # aborted: no file, no leftover part
    w = AsterixFileWriter(str(out), site=types.SimpleNamespace(asterix_sac=3, asterix_sic=4))
    w.open()
    w.write(cols)
    assert not out.exists()
    w.close()
    got = decode_records(out.read_bytes())
    valid = (batch["rx_good"] == 1) & (batch["go"] == 1)
    assert len(got["sr_m"]) == valid.sum() == w.stats()["records"]
    assert (got["sic"] == 4).all() and [p.name for p in tmp_path.iterdir()] == ["run.ast"]
    assert out.stat().st_mode & 0o777 == 0o644
    with pytest.raises(ConfigError, match="cannot write"):
        AsterixFileWriter(str(tmp_path / "no" / "x.ast")).open()


def _site_toml(tmp_path, sac: int) -> str:
    text = (ROOT / "firmware_specs" / "sites" / "demo.toml").read_text()
    text = "\n".join(line for line in text.splitlines() if not line.startswith("[asterix]")
                     and not line.startswith(("sac", "sic")))
    p = tmp_path / f"site{sac}.toml"
    p.write_text(text + f"\n\n[asterix]\nsac = {sac}\nsic = 17\n")
    return str(p)


def test_site_sac_sic_reach_the_records_and_sac_over_255_is_one_line(tmp_path):
    sim = RadarSimulator(FlightScript(), SimConfig(seed=2))
    raw = tmp_path / "capture.bin"
    raw.write_bytes(sim.generate(3000)[0])
    site = load_site(_site_toml(tmp_path, 42))
    assert (getattr(site, "asterix_sac", None), getattr(site, "asterix_sic", None)) == (42, 17)
    from radar_io.decoding.decoders import iter_decode

    out = tmp_path / "out.ast"
    sink = open_sink("ast", str(out), site=site)     # what `decode -o OUT.ast` opens
    for batch in iter_decode([raw.read_bytes()], site=site):
        sink.write(batch)
    sink.close()
    got = decode_records(out.read_bytes())
    assert len(got["sac"]) > 0 and (got["sac"] == 42).all() and (got["sic"] == 17).all()
    res = run_cli("decode", str(raw), "--site", _site_toml(tmp_path, 300), "-o",
                  str(tmp_path / "x.csv"))
    err = res.stderr.decode().strip()
    assert res.returncode == 2 and "\n" not in err and "sac" in err and "300" in err, err


def test_decode_cli_writes_ast_from_the_extension(tmp_path):
    """`radar-io decode INPUT -o OUT.ast`: one CAT048 record per valid sample (GO and RX_GOOD),
    SAC/SIC from the site, values equal to the decoded batch within one LSB."""
    raw = tmp_path / "capture.bin"
    raw.write_bytes(RadarSimulator(FlightScript(), SimConfig(seed=9)).generate(4000)[0])
    site_toml = _site_toml(tmp_path, 7)
    res = run_cli("decode", str(raw), "--site", site_toml, "-o", str(tmp_path / "out.ast"), "-q")
    assert res.returncode == 0, res.stderr
    got = decode_records((tmp_path / "out.ast").read_bytes())
    batch = decode_bytes(raw.read_bytes(), site=load_site(site_toml))
    valid = (batch["go"] == 1) & (batch["rx_good"] == 1)
    assert len(got["sac"]) == int(valid.sum()) > 1000
    assert (got["sac"] == 7).all() and (got["sic"] == 17).all()
    assert np.abs(got["sr_m"] - batch["sr_c_m"][valid]).max() <= 1852.0 / 256
    assert not list(tmp_path.glob(".out.ast.*"))  # no temporary file left
