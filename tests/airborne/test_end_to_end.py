"""Radar and aircraft simulators on loop:// and a virtual CAN bus, recorded, then aligned (§9)."""

from __future__ import annotations

import binascii
import json
import math
import subprocess
import sys

import can
import numpy as np
import pytest
from conftest import ROOT, run_cli

from radar_io.analysis.clock_alignment import align_files, compare_altitude, fit_clock, read_radar_track
from radar_io.decoding.airdata import read_can_log
from radar_io.recording.rdrlog import RecordingWriter
from radar_io.simulation.aircraft import AircraftConfig, AircraftSimulator
from radar_io.simulation.radar import FlightScript, RadarSimulator, SimConfig
from radar_io.sources.canbus import CanRecorder, open_bus
from radar_io.sources.serialport import SerialSource
from radar_io.wirespec.frame import load_spec

TOD0 = 43210.0
ANTENNA_MSL_M, QNH_HPA = 12.0, 1003.0


def with_shutters(frames: bytes, t: np.ndarray, shutters: np.ndarray, width: float) -> bytes:
    """Set the STS SYNC bit (B0, 0x8000) from a shutter schedule and redo the CRC (§2, §3)."""
    b = np.frombuffer(frames, dtype=np.uint8).reshape(-1, 24).copy()
    k = np.searchsorted(shutters, t, side="right") - 1
    on = (k >= 0) & (t - shutters[np.maximum(k, 0)] < width)
    b[:, 20] = (b[:, 20] & 0x7F) | np.where(on, 0x80, 0)
    for row in b:
        row[22:24] = np.frombuffer(binascii.crc_hqx(row[:22].tobytes(), 0xFFFF).to_bytes(2, "big"), np.uint8)
    return b.tobytes()


def expected_difference(t_sim: np.ndarray) -> np.ndarray:
    """Pressure altitude minus radar height, from first principles (independent of radar_io).

    True altitude above MSL: antenna height + H + d²/2R (earth curvature below the
    radar's tangent plane). With the altimeter's ISA curve shifted to QNH, pressure
    altitude = true altitude + the ISA height of the QNH pressure level, found here
    by bisection of p(h) = 1013.25 (1 - 0.0065 h / 288.15)^5.25588.
    """
    lo, hi = -2000.0, 2000.0
    for _ in range(100):
        mid = (lo + hi) / 2
        if 1013.25 * (1 - 0.0065 * mid / 288.15) ** 5.25588 > QNH_HPA:
            lo = mid
        else:
            hi = mid
    qnh_level = (lo + hi) / 2
    assert 8.0 < qnh_level / (1013.25 - QNH_HPA) < 8.8     # the 27 ft/hPa rule of thumb
    x, y, _ = FlightScript().position(t_sim)
    return ANTENNA_MSL_M + (x ** 2 + y ** 2) / (2 * 6_371_000.0) + qnh_level


@pytest.mark.slow
def test_simulated_approach_aligns_within_one_radar_frame(tmp_path):
    rng = np.random.default_rng(11)
    duration, rate = 36.0, 1000.0
    # an irregular shutter (camera run, event button), off the radar's 1 ms frame grid
    shutters = np.cumsum(rng.uniform(0.9, 2.6, 40)) + 0.6
    shutters = shutters[shutters < duration - 0.5]
    script = FlightScript()
    radar = RadarSimulator(script, SimConfig(rate_hz=rate, seed=12, tod_start_s=TOD0, sync_every_s=0.0,
                                             ng_per_min=6.0))
    cfg = AircraftConfig(clock_offset_s=7777.7777, drift_ppm=35.0, antenna_msl_m=ANTENNA_MSL_M,
                         qnh_hpa=QNH_HPA)
    aircraft = AircraftSimulator(script, radar.cfg, cfg, duration_s=duration, shutter_times_s=shutters)
    # the radar recording starts after the first shutter, the CAN log stops before the last one
    radar_from, can_until = shutters[0] + 0.3, shutters[-1] - 0.3
    spec = load_spec()
    port = SerialSource("loop://")
    port.open()
    rdr, log = tmp_path / "radar.rdrlog", tmp_path / "aircraft.blf"
    tx, rx = open_bus("virtual", "e2e"), open_bus("virtual", "e2e")
    try:
        with RecordingWriter(rdr, spec, source="loop://") as writer, CanRecorder(rx, log) as recorder:
            block = 100
            for i in range(int(duration * rate) // block):
                t0 = i * block / rate
                frames, truth = radar.generate(block)
                frames = with_shutters(frames, truth["t_s"], shutters, 0.02)
                port.write(frames)
                got = b""
                while len(got) < len(frames):
                    got += port.read(0.5)
                assert got == frames
                if t0 >= radar_from:
                    writer.write(got, int((TOD0 + t0) * 1e9))      # simulated receive time
                if t0 < can_until:
                    aircraft.send(tx, t0, t0 + block / rate)
                    recorder.drain()
    finally:
        port.close()
        tx.shutdown()
        rx.shutdown()

    doc = align_files(rdr, log, antenna_msl_m=ANTENNA_MSL_M, qnh_hpa=QNH_HPA)
    json.dumps(doc)
    clock = doc["clock"]
    assert clock["lag"] == 1 and clock["consistent"] and not clock["ambiguous"]
    assert clock["matched_events"] == shutters.size - 2 >= 15
    assert doc["residuals_ms"]["max_abs"] < 1.0
    assert clock["drift_ppm"] == pytest.approx(35.0, abs=15.0)

    # every matched shutter maps onto its true radar time within one radar frame (1 ms)
    track = read_radar_track(rdr)
    air = read_can_log(log)
    fit = fit_clock(track.edge_s, air.event_time_s, air.event_count)
    true_tod = TOD0 + (air.event_time_s - cfg.clock_offset_s) / (1 + 35e-6)
    err = fit.to_radar(air.event_time_s[fit.aircraft_index]) - true_tod[fit.aircraft_index]
    assert np.max(np.abs(err)) < 1e-3
    assert clock["offset_s"] == pytest.approx(TOD0 + (fit.t_ref_s - cfg.clock_offset_s) / (1 + 35e-6)
                                              - fit.t_ref_s, abs=1e-3)

    # aligned pressure altitude vs radar height: the expected difference, sample by sample
    alt = compare_altitude(fit, air, track)
    t_sim = alt["tod_s"] - TOD0
    assert alt["difference_m"].size > 200
    resid = alt["difference_m"] - expected_difference(t_sim)
    assert abs(resid.mean()) < 0.3 and resid.std() < 3.0
    stats = doc["altitude"]["pressure_altitude_minus_radar_h_m"]
    assert stats["mean"] == pytest.approx(expected_difference(t_sim).mean(), abs=0.3)
    assert 95 < stats["mean"] < 125
    assert abs(doc["altitude"]["difference_minus_expected_m"]["mean"]) < 0.3


# ------------------------------------------------------------------ the CLI, as separate processes
def _run_airborne(*args: str) -> subprocess.CompletedProcess:
    """``radar-io can-log|align`` in a fresh interpreter (the console script's entry point)."""
    return subprocess.run([sys.executable, "-m", "radar_io.cli", *args], capture_output=True,
                          timeout=120, cwd=ROOT)


@pytest.mark.slow
def test_cli_can_log_and_align(tmp_path):
    rdr, log = tmp_path / "r.rdrlog", tmp_path / "a.asc"
    r = run_cli("simulate", "-o", str(rdr), "--duration-s", "20", "--sync-every-s", "1.5", "-q")
    assert r.returncode == 0, r.stderr
    r = _run_airborne("can-log", "--interface", "virtual", "--channel", "cli", "-o", str(log),
                      "--simulate", "--duration-s", "20", "--sync-every-s", "1.5", "--drift-ppm", "20",
                      "--qnh-hpa", str(QNH_HPA), "--antenna-msl-m", str(ANTENNA_MSL_M))
    assert r.returncode == 0, r.stderr
    n = int(r.stderr.decode().split("can-log: ")[1].split()[0])
    with can.LogReader(str(log)) as reader:
        assert sum(1 for _ in reader) == n > 600                 # 8 Hz x 4 messages x 20 s + 13 events
    r = _run_airborne("align", str(rdr), str(log), "--antenna-msl-m", str(ANTENNA_MSL_M),
                      "--qnh-hpa", str(QNH_HPA))
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    assert doc["clock"]["matched_events"] == 13 and doc["clock"]["lag"] == 0
    assert doc["clock"]["ambiguous"]                         # a periodic shutter cannot tell lags apart
    assert doc["residuals_ms"]["max_abs"] < 1.0
    assert doc["clock"]["drift_ppm"] == pytest.approx(20.0, abs=10.0)
    assert abs(doc["altitude"]["difference_minus_expected_m"]["mean"]) < 0.5
    assert math.isfinite(doc["clock"]["offset_s"])


@pytest.mark.slow
def test_cli_bad_inputs(tmp_path):
    r = _run_airborne("can-log", "--interface", "nosuch", "--channel", "x", "-o", str(tmp_path / "a.asc"),
                      "--duration-s", "0.1")
    err = r.stderr.decode()
    assert r.returncode == 2 and err.startswith("radar-io: error: cannot open CAN interface 'nosuch'")
    assert err.count("\n") == 1 and "Traceback" not in err
    r = _run_airborne("can-log", "--interface", "virtual", "--channel", "x", "-o", str(tmp_path / "a.xyz"),
                      "--duration-s", "0.1")
    assert r.returncode == 2 and "cannot write CAN log" in r.stderr.decode()
    r = _run_airborne("align", str(tmp_path / "none.rdrlog"), str(tmp_path / "a.asc"))
    err = r.stderr.decode()
    assert r.returncode == 2
    assert err == f"radar-io: error: radar recording not found: {tmp_path / 'none.rdrlog'}\n"
    # a real recording but a CAN log without any shutter event
    rdr, empty = tmp_path / "r.rdrlog", tmp_path / "quiet.asc"
    r = run_cli("simulate", "-o", str(rdr), "--duration-s", "3", "--sync-every-s", "1", "-q")
    assert r.returncode == 0
    r = _run_airborne("can-log", "--interface", "virtual", "--channel", "q", "-o", str(empty),
                      "--duration-s", "0.2", "-q")
    assert r.returncode == 0 and empty.exists()
    r = _run_airborne("align", str(rdr), str(empty))
    err = r.stderr.decode()
    assert r.returncode == 2 and "no shutter events to match" in err and "Traceback" not in err
