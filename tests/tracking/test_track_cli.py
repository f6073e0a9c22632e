"""``radar-io track`` end to end, as separate processes: simulate → track, formats, errors."""

from __future__ import annotations

import numpy as np
import pyarrow.parquet as pq
import pytest
from conftest import ROOT, run_cli

from radar_io.decoding.batch_decoder import decode_bytes
from radar_io.recording.rdrlog import iter_payloads
from radar_io.sinks.arrow_convert import read_metadata
from radar_io.tracking.tracker import TRACK_COLUMNS, TrackParams, track_batch


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    rec = tmp_path_factory.mktemp("trk") / "approach.rdrlog"
    r = run_cli("simulate", "-o", str(rec), "--duration-s", "20", "--ng-per-min", "10", "-q")
    assert r.returncode == 0, r.stderr
    return rec


def test_track_to_parquet_with_site_and_path(recording, tmp_path):
    out = tmp_path / "bet.parquet"
    path = ROOT / "firmware_specs" / "paths" / "demo_approach_runway.toml"
    r = run_cli("track", str(recording), "-o", str(out), "--site", "demo", "--path", str(path),
                "--q-mps2", "0.8")
    assert r.returncode == 0, r.stderr
    assert "outliers" in r.stderr.decode()
    t = pq.read_table(out)
    assert tuple(t.column_names[:len(TRACK_COLUMNS)]) == TRACK_COLUMNS
    assert {"xr_m", "lat_deg", "dy_m", "leg"} <= set(t.column_names)
    meta = read_metadata(t.schema)
    assert meta["tracking.model"] == "cv" and meta["tracking.q_mps2"] == "0.8"
    assert meta["tracking.sigma_range_m"] == "5.0"      # from the demo site file
    assert meta["tracking.estimate"] == "rts_smoothed"
    assert int(meta["tracking.outliers"]) == int(np.sum(t["outlier"].to_numpy()))
    footer = {k.decode(): v.decode() for k, v in pq.read_metadata(out).metadata.items()}
    assert footer["radar_io.tracking.used"] == meta["tracking.used"]
    assert int(footer["radar_io.frames"]) == t.num_rows
    assert t.schema.field("gs_mps").metadata[b"unit"] == b"m/s"
    # the file holds what the API computes on the same measurements
    batch = decode_bytes(b"".join(iter_payloads(recording)))
    api = track_batch(batch, TrackParams(q_mps2=0.8))
    assert t.num_rows == len(batch)
    np.testing.assert_array_equal(t["x_m"].to_numpy(), api["x_m"])
    np.testing.assert_array_equal(t["vh_sigma_mps"].to_numpy(), api["vh_sigma_mps"])


def test_forward_only_csv_and_overrides(recording, tmp_path):
    out = tmp_path / "fwd.csv"
    r = run_cli("track", str(recording), "-o", str(out), "--forward-only",
                "--sigma-range-m", "1", "--sigma-angle-deg", "0.005", "-q")
    assert r.returncode == 0, r.stderr
    lines = out.read_text().splitlines()
    assert lines[0] == ",".join(TRACK_COLUMNS) and len(lines) == 20_001
    assert r.stderr == b""


@pytest.mark.parametrize("args, message", [
    (["{tmp}/missing.rdrlog", "-o", "{tmp}/x.parquet"], "input not found: "),
    (["{rec}", "-o", "{tmp}/x.parquet", "--q-mps2", "0"], "--q-mps2: expected a positive number"),
    (["{rec}", "-o", "{tmp}/x.parquet", "--site", "{bad}"], "field radar.sigma_range_m"),
])
def test_bad_input_is_one_line_and_exit_2(recording, tmp_path, args, message):
    bad = tmp_path / "site.toml"
    bad.write_text((ROOT / "firmware_specs" / "sites" / "demo.toml").read_text()
                   .replace("sigma_range_m = 5.0", "sigma_range_m = -5.0"))
    argv = [a.format(rec=recording, bad=bad, tmp=tmp_path) for a in args]
    r = run_cli("track", *argv)
    err = r.stderr.decode().strip()
    assert r.returncode == 2 and len(err.splitlines()) == 1 and message in err, err
    if "site" in message:
        assert str(bad) in err
    assert not (tmp_path / "x.parquet").exists()


def test_fixes_estimate_bias_and_bias_out(tmp_path):
    """Biases injected through the decoder's calibration set; 18 photo fixes of σ 2 m."""
    import csv
    import json

    from radar_io.simulation.radar import RadarSimulator, SimConfig

    sim = RadarSimulator(config=SimConfig(tod_start_s=50_000.0, seed=9, ng_per_min=0.0))
    data, truth = sim.generate(92_000)
    raw = tmp_path / "flight.bin"
    raw.write_bytes(data)
    injected = {"dsr_m": -12.5, "del_deg": 0.334, "daz_deg": 1.135}  # readings = truth + these
    cal = tmp_path / "cal.json"
    cal.write_text(json.dumps({"format": "radar_io-calibration/1", "id": "wrong",
                               "biases": injected}))
    s = truth["sync"].astype(np.int8)
    rows = np.flatnonzero((s == 1) & (np.concatenate(([0], s[:-1])) == 0))
    assert rows.size == 18
    rng = np.random.default_rng(4)
    fixes = tmp_path / "fixes.csv"
    with open(fixes, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["sync_index", "photo_x_m", "photo_y_m", "photo_z_m", "sigma_x_m",
                    "sigma_y_m", "sigma_z_m"])
        for i, r in enumerate(rows):
            e = rng.normal(0.0, 2.0, 3)
            w.writerow([i, truth["x_m"][r] + e[0], truth["y_m"][r] + e[1],
                        -(truth["h_m"][r] + e[2]), 2, 2, 2])
    out, cal_out = tmp_path / "bet.arrow", tmp_path / "new_cal.json"
    r = run_cli("track", str(raw), "-o", str(out), "--calibration", str(cal), "--fixes",
                str(fixes), "--estimate-bias", "--bias-out", str(cal_out),
                "--sigma-range-m", "1.04", "--sigma-angle-deg", "0.005")
    assert r.returncode == 0, r.stderr
    assert "bias dsr_m" in r.stderr.decode()
    doc = json.loads(cal_out.read_text())
    st = doc["statistics"]
    assert "method" in st and doc["provenance"]["fixes"] == "fixes.csv"
    for k in injected:
        # the new set's totals undo the wrong calibration: ≈ 0 within 3σ
        assert abs(doc["biases"][k]) <= 3 * st[k]["sigma"], (k, doc["biases"][k], st[k])
        assert doc["biases"][k] == st[k]["estimate"]
    import pyarrow as pa

    with pa.ipc.open_file(out) as f:
        meta = read_metadata(f.schema)
        t = f.read_all()
    assert meta["tracking.fixes_used"] == "18"
    est = float(meta["tracking.bias_dsr_m"].split(" ± ")[0])
    assert abs(est - 12.5) < 3 * st["dsr_m"]["sigma"] + 1e-3
    e = np.hypot(t["x_m"].to_numpy() - truth["x_m"], t["y_m"].to_numpy() - truth["y_m"])
    assert np.nanmedian(e[5000:]) < 2.0   # the bias-corrected track
    # the set decodes: a later decode / track can use it
    r = run_cli("track", str(raw), "-o", str(tmp_path / "again.csv"), "--calibration",
                str(cal_out), "-q")
    assert r.returncode == 0, r.stderr


def test_fix_errors_are_one_line(recording, tmp_path):
    bad = tmp_path / "fixes.csv"
    bad.write_text("sync_index,photo_x_m,photo_y_m,photo_z_m,sigma_x_m,sigma_y_m,sigma_z_m\n"
                   "0,1,2,-3,2,2,0\n")
    r = run_cli("track", str(recording), "-o", str(tmp_path / "x.csv"), "--fixes", str(bad),
                "--estimate-bias")
    err = r.stderr.decode().strip()
    assert r.returncode == 2 and len(err.splitlines()) == 1
    assert f"{bad}, line 2, column sigma_z_m" in err
    far = tmp_path / "far.csv"
    far.write_text(bad.read_text().replace("0,1,2,-3,2,2,0", "99,1,2,-3,2,2,2"))
    r = run_cli("track", str(recording), "-o", str(tmp_path / "x.csv"), "--fixes", str(far))
    err = r.stderr.decode().strip()
    assert r.returncode == 2 and "sync_index 99 but the input has only 3 SYNC edges" in err, err
    assert not (tmp_path / "x.csv").exists()


def test_airdata_pressure_altitude_fused(tmp_path):
    """Pressure altitude from a simulated CAN log, aligned by the shutter events."""
    import can

    from radar_io.simulation.aircraft import (
        AircraftConfig,
        AircraftSimulator,
        qnh_height_m,
    )
    from radar_io.simulation.radar import RadarSimulator, SimConfig

    antenna_msl_m, qnh_hpa = 12.0, 1003.0
    radar = RadarSimulator(config=SimConfig(tod_start_s=30_000.0, seed=2, ng_per_min=0.0,
                                            sync_every_s=1.7))
    data, truth = radar.generate(40_000)
    raw = tmp_path / "flight.bin"
    raw.write_bytes(data)
    aircraft = AircraftSimulator(radar.script, radar.cfg,
                                 AircraftConfig(clock_offset_s=5555.5, drift_ppm=20.0,
                                                antenna_msl_m=antenna_msl_m, qnh_hpa=qnh_hpa),
                                 duration_s=40.0)
    log = tmp_path / "aircraft.asc"
    writer = can.Logger(str(log))
    for msg in aircraft.messages(0.0, 40.0):
        writer.on_message_received(msg)
    writer.stop()
    out = tmp_path / "bet.parquet"
    r = run_cli("track", str(raw), "-o", str(out), "--airdata", str(log), "--sigma-range-m",
                "1.04", "--sigma-angle-deg", "0.005", "--sigma-pa-m", "1.0")
    assert r.returncode == 0, r.stderr
    assert "pressure altitude:" in r.stderr.decode()
    meta = read_metadata(pq.read_schema(out))
    offset, sigma = (float(v) for v in meta["tracking.pa_offset_m"].split(" ± "))
    # PA − (H + curvature) = antenna MSL height + the ISA height of the QNH level
    assert abs(offset - (antenna_msl_m + qnh_height_m(qnh_hpa))) < 0.5 and 0 < sigma < 0.5
    assert int(meta["tracking.pa_samples"]) > 250          # 8 Hz for ~38 s
    assert int(meta["tracking.fixes_used"]) == int(meta["tracking.pa_samples"])
    assert abs(float(meta["tracking.pa_clock_drift_ppm"]) - 20.0) < 15.0
    h = pq.read_table(out, columns=["h_m"])["h_m"].to_numpy()
    assert np.sqrt(np.mean((h[2000:] - truth["h_m"][2000:]) ** 2)) < 0.3
