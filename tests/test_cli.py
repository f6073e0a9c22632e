"""The CLI end to end, as separate processes: simulate → decode, formats, stats, errors."""

from __future__ import annotations

import csv
import io
import json
import subprocess
import sys

import numpy as np
import pytest
from conftest import ROOT, run_cli

from radar_io.decoding.decoders import DECODE_COLUMNS, decode_bytes
from radar_io.recording.rdrlog import RecordingReader

HEADER = ("seq,tod_s,sr_m,dsr_m,el_deg,del_deg,az_deg,daz_deg,go,rx_good,sync,sr_c_m,el_c_deg,"
          "az_c_deg,x_m,y_m,h_m")


@pytest.fixture(scope="module")
def sim_recording(tmp_path_factory):
    d = tmp_path_factory.mktemp("sim")
    rec = d / "approach.rdrlog"
    r = run_cli("simulate", "-o", str(rec), "--duration-s", "20", "--ng-per-min", "20", "-q")
    assert r.returncode == 0, r.stderr
    return rec


@pytest.mark.slow
def test_simulate_to_rdrlog_then_decode_csv(sim_recording, tmp_path):
    out, stats = tmp_path / "t.csv", tmp_path / "s.json"
    r = run_cli("decode", str(sim_recording), "-o", str(out), "--stats", str(stats))
    assert r.returncode == 0, r.stderr
    lines = out.read_text().splitlines()
    assert lines[0].startswith(HEADER + ",")
    rows = list(csv.DictReader(io.StringIO(out.read_text())))
    st = json.loads(stats.read_text())
    assert {"frames", "crc_errors", "bytes_discarded", "seq_gaps"} <= set(st)
    assert st["frames"] == len(rows) == 20000
    assert st["crc_errors"] == st["bytes_discarded"] == st["seq_gaps"] == 0
    ng = [row for row in rows if row["rx_good"] == "0"]
    good = [row for row in rows if row["rx_good"] == "1"]
    assert ng and good
    assert all(row[c] == "" for row in ng for c in ("sr_c_m", "el_c_deg", "x_m", "h_m"))
    assert all(row["sr_c_m"] != "" for row in good)
    heights = np.array([float(row["h_m"]) for row in good])
    assert abs(np.median(heights) - 600.0) < 5.0  # the default approach at 600 m
    assert "decode: frames 20000" in r.stderr.decode()  # the closing summary on stderr
    # the CSV is the API's numbers, to the last digit
    with RecordingReader(sim_recording) as rd:
        b = decode_bytes(b"".join(c.data for c in rd))
    assert [float(row["x_m"] or "nan") for row in rows[:500]] == pytest.approx(
        b["x_m"][:500].tolist(), nan_ok=True, rel=0, abs=0)


@pytest.mark.slow
def test_decode_jsonl_with_site_and_calibration(sim_recording, tmp_path):
    cal = tmp_path / "cal.json"
    cal.write_text(json.dumps({"format": "radar_io-calibration/1", "id": "t1",
                               "biases": {"dsr_m": 10.0, "del_deg": 0.0, "daz_deg": 0.0}}))
    out = tmp_path / "t.jsonl"
    r = run_cli("decode", str(sim_recording), "-o", str(out), "-q", "--calibration", str(cal),
                "--site", str(ROOT / "firmware_specs" / "sites" / "demo.toml"))
    assert r.returncode == 0, r.stderr
    objs = [json.loads(line) for line in out.read_text().splitlines()]
    assert list(objs[0])[:17] == list(DECODE_COLUMNS)
    assert {"xr_m", "yr_m", "hr_m", "lat_deg", "lon_deg", "hae_m"} <= set(objs[0])
    ng = [o for o in objs if o["rx_good"] == 0]
    assert ng and all(o["x_m"] is None and o["lat_deg"] is None for o in ng)
    good = [o for o in objs if o["rx_good"] == 1][:100]
    assert all(o["sr_c_m"] == pytest.approx(o["sr_m"] + o["dsr_m"] + 10.0) for o in good)
    assert all(35.3 < o["lat_deg"] < 35.8 for o in good)


@pytest.mark.slow
def test_damaged_raw_capture_and_stdin(tmp_path):
    raw = tmp_path / "raw.bin"
    r = run_cli("simulate", "-o", str(raw), "--duration-s", "5", "--flip-rate", "0.002",
                "--drop-rate", "0.0005", "--insert-rate", "0.0005", "-q")
    assert r.returncode == 0, r.stderr
    data = raw.read_bytes()
    want = decode_bytes(data).stats
    st = tmp_path / "s.json"
    r = run_cli("decode", "-", "--stats", str(st), "-q", "--format", "jsonl", input=data)
    assert r.returncode == 0, r.stderr
    assert json.loads(st.read_text()) == want
    assert want["crc_errors"] > 0 and want["seq_gaps"] > 0 and want["bytes_discarded"] > 0
    assert len(r.stdout.splitlines()) == want["frames"]


@pytest.mark.slow
def test_simulate_pipe_into_decode():
    sim = subprocess.Popen([sys.executable, "-m", "radar_io.cli", "simulate", "--duration-s", "2"],
                           stdout=subprocess.PIPE, cwd=ROOT)
    dec = subprocess.run([sys.executable, "-m", "radar_io.cli", "decode", "-", "-q"],
                         stdin=sim.stdout, capture_output=True, text=True, cwd=ROOT, timeout=120)
    sim.wait(timeout=60)
    assert dec.returncode == 0 and len(dec.stdout.splitlines()) == 2001


@pytest.mark.slow
@pytest.mark.parametrize("args,needle", [
    (("decode", "/nonexistent/x.bin"), "input not found"),
    (("decode",), "required"),
    (("decode", "README.md", "--format", "xml"), "invalid choice"),
    (("decode", "README.md", "--calibration", "README.md"), "not valid JSON"),
    (("decode", "README.md", "--site", "/nonexistent.toml"), "site file not found"),
    (("decode", "README.md", "-o", "/nonexistent/dir/out.csv"), "cannot write"),
    (("decode", "README.md", "--spec", "README.md"), "not valid TOML"),
    (("simulate", "--rate-hz", "0", "-o", "/dev/null"), "must be positive"),
    (("simulate", "-o", "loop-nothing://x"), "cannot open"),
    (("frobnicate",), "invalid choice"),
])
def test_bad_input_is_one_clear_line(args, needle):
    r = run_cli(*args)
    err = r.stderr.decode()
    assert r.returncode != 0
    assert needle in err, err
    assert "Traceback" not in err
    assert len(err.strip().splitlines()) == 1, err


@pytest.mark.slow
def test_raw_garbage_decodes_to_nothing_without_error(tmp_path):
    p = tmp_path / "junk.bin"
    p.write_bytes(bytes(range(256)) * 100)
    r = run_cli("decode", str(p), "-q", "--stats", str(tmp_path / "s.json"))
    assert r.returncode == 0
    assert r.stdout.decode().splitlines() == [r.stdout.decode().splitlines()[0]]  # header only
    assert json.loads((tmp_path / "s.json").read_text())["bytes_discarded"] == 25600


@pytest.mark.slow
def test_bench_reports_all_figures():
    r = run_cli("bench", "--json", "--frames", "20000", "--repeat", "1", "--core-only")
    assert r.returncode == 0, r.stderr
    res = json.loads(r.stdout)
    for k in ("per_frame_fps", "batch_clean_fps", "batch_damaged_1pct_fps", "memcpy_ref_fps"):
        assert res[k] > 0
    assert 0.95 * 20000 > res["batch_damaged_1pct_accepted"] > 0.5 * 20000


@pytest.mark.slow
def test_monitor_shows_a_live_line():
    r = run_cli("monitor", "--duration-s", "2.5")
    out = r.stdout.decode()
    assert r.returncode == 0, r.stderr
    assert "SEQ" in out and "fr/s" in out and "crc 0" in out


PEAK_RSS = """
import resource, sys
from radar_io.cli import main
rc = main(["decode", sys.argv[1], "-o", "/dev/null", "-q"])
print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss // 1024)
sys.exit(rc)
"""


@pytest.mark.slow
def test_decode_streams_in_constant_memory(tmp_path, spec):
    """Peak RSS does not grow with the recording: 10× the frames, about the same memory."""
    from radar_io.recording.rdrlog import RecordingWriter
    from radar_io.simulation.radar import RadarSimulator, SimConfig

    peaks = {}
    for n_blocks in (4, 40):
        p = tmp_path / f"r{n_blocks}.rdrlog"
        sim = RadarSimulator(config=SimConfig(seed=2, loop=True))
        with RecordingWriter(p, spec) as w:
            for _ in range(n_blocks):  # 25 000 frames (600 kB) per block
                data, _ = sim.generate(25_000)
                for k in range(0, len(data), 4800):
                    w.write(data[k:k + 4800])
        r = subprocess.run([sys.executable, "-c", PEAK_RSS, str(p)], capture_output=True,
                           text=True, cwd=ROOT, timeout=300)
        assert r.returncode == 0, r.stderr
        peaks[n_blocks] = int(r.stdout.split()[-1])
    # 24 MB of input and ~1 M rows more must not cost more than a few MB more
    assert peaks[40] - peaks[4] < 30, peaks


@pytest.mark.slow
def test_simulate_to_a_serial_device_in_real_time():
    """`-o /dev/pts/N`: the simulator paces its frames to the serial line like a radar."""
    import os
    import select
    import time

    from radar_io.benchmarks.service_load import Pty

    pty = Pty()
    try:
        t0 = time.monotonic()
        r = run_cli("simulate", "-o", f"{pty.path}?baudrate=921600", "--duration-s", "1.0",
                    "--rate-hz", "400", "-q")
        elapsed = time.monotonic() - t0
        assert r.returncode == 0, r.stderr
        data = b""
        while select.select([pty.master], [], [], 0.2)[0]:
            data += os.read(pty.master, 1 << 16)
    finally:
        pty.close()
    b = decode_bytes(data)
    assert len(b) == 400 and b.stats["crc_errors"] == 0
    assert elapsed > 0.9  # paced, not dumped


@pytest.mark.slow
def test_decode_with_path_tlm_and_da_outputs(sim_recording, tmp_path):
    """--path adds the deviation columns; --tlm-out / --da-out write what the aircraft and the
    recorders decode back to the same numbers (struct + binascii here, not the project's decoder)."""
    import binascii
    import struct

    out, tlm, da = tmp_path / "t.csv", tmp_path / "up.tlm", tmp_path / "da.bin"
    r = run_cli("decode", str(sim_recording), "-o", str(out), "--tlm-out", str(tlm), "--da-out",
                str(da), "--site", str(ROOT / "firmware_specs" / "sites" / "demo.toml"),
                "--path", str(ROOT / "firmware_specs" / "paths" / "demo_approach_runway.toml"))
    assert r.returncode == 0, r.stderr
    assert "tlm-out:" in r.stderr.decode() and "saturated" in r.stderr.decode()
    rows = list(csv.DictReader(io.StringIO(out.read_text())))
    assert list(rows[0])[-4:] == ["dy_m", "dz_m", "along_m", "leg"]
    valid = [row for row in rows if row["rx_good"] == "1" and row["go"] == "1"]
    data = tlm.read_bytes()
    assert len(data) == 26 * len(valid)
    for k in range(0, len(valid), 997):
        fr = data[26 * k:26 * (k + 1)]
        sync, _seq, *ch = struct.unpack(">HH10h", fr[:24])
        assert sync == 0x1ACF and binascii.crc_hqx(fr[:24], 0xFFFF) == struct.unpack(">H", fr[24:])[0]
        dz = float(valid[k]["dz_m"])
        want = max(-32767, min(32767, round(dz / 150.0 * 32767)))
        assert ch[1] == want  # channel 2: DZ, ±150 m
    words = struct.unpack(f">{len(rows) * 8}H", da.read_bytes())
    assert len(words) == 8 * len(rows)
    for k in range(0, len(rows), 1013):
        w = words[8 * k:8 * k + 8]
        assert [(x >> 12) & 7 for x in w] == list(range(8))  # channel numbers 0..7
        pen_up = rows[k]["rx_good"] == "0" or rows[k]["go"] == "0"
        assert all(bool(x & 0x8000) == pen_up for x in w)
