"""Airborne recorder (radar-interface.md §9): DBC, simulator, recorder and clock fit, piece by piece."""

from __future__ import annotations

import math

import can
import numpy as np
import pytest
from conftest import ROOT

from radar_io.analysis.clock_alignment import fit_clock
from radar_io.decoding.airdata import decode_messages, load_dbc, read_can_log
from radar_io.errors import AirborneError
from radar_io.simulation.aircraft import AircraftConfig, AircraftSimulator
from radar_io.simulation.radar import FlightScript, SimConfig
from radar_io.sources.canbus import CanRecorder, open_bus


@pytest.fixture(scope="module")
def db():
    return load_dbc()


@pytest.mark.slow
def test_simulated_messages_decode_with_cantools(db):
    cfg = AircraftConfig(clock_offset_s=1234.56789, drift_ppm=50.0, qnh_hpa=1020.0,
                         shutter_count_start=7)
    sim = AircraftSimulator(FlightScript(), SimConfig(sync_every_s=1.25), cfg, duration_s=10.0, db=db)
    msgs = sim.messages(0.0, 10.0)
    log = decode_messages(msgs, db)
    # shutters at 1.25 s, 2.5 s, …, 8.75 s; counted on from 7; DAU time to 0.1 ms
    assert log.event_count.tolist() == list(range(8, 15))
    true_t = cfg.clock_offset_s + (1 + 50e-6) * 1.25 * np.arange(1, 8)
    assert np.max(np.abs(log.event_time_s - true_t)) <= 0.5e-4 + 1e-9
    s = log.samples
    assert s["time_s"].size == 80 and not any(np.isnan(v).any() for v in s.values())
    assert np.allclose(np.diff(s["time_s"]), 0.125)                 # 8 Hz on the DAU clock
    assert np.all(s["time_s"] * 8 == np.round(s["time_s"] * 8))
    # latched counter: shutter events at or before each sample
    t_sim = (s["time_s"] - cfg.clock_offset_s) / (1 + 50e-6)
    assert s["shutter_count"].tolist() == [7 + int(np.sum(1.25 * np.arange(1, 8) <= t)) for t in t_sim]
    script = FlightScript()
    x, y, h = script.position(t_sim)
    assert s["heading_deg"] == pytest.approx(np.full(80, 340.0))
    assert s["pitch_deg"] == pytest.approx(np.full(80, 2.5)) and np.all(s["roll_deg"] == 0)
    dme1 = np.sqrt((x + 20000) ** 2 + (y - 3000) ** 2 + (h - 40) ** 2) / 1852
    assert np.max(np.abs(s["dme1_nm"] - dme1)) <= 0.0005 + 1e-9
    # IAS below TAS at 600 m, QNH 1020 gives a pressure altitude below the true altitude
    assert np.all((s["ias_kt"] < 70 / 0.514444) & (s["ias_kt"] > 0.95 * 70 / 0.514444))
    assert np.all(s["pressure_altitude_ft"] * 0.3048 < 12 + 600 + 40)


def test_decoding_counts_unknown_and_bad_messages(db):
    good = AircraftSimulator(FlightScript(), SimConfig(sync_every_s=1.0), duration_s=2.0,
                             db=db).messages(0.0, 2.0)
    extra = [can.Message(arbitration_id=0x7FF, data=b"\x00" * 8, is_extended_id=False),
             can.Message(arbitration_id=0x101, data=b"\x00" * 8, is_extended_id=True),
             can.Message(arbitration_id=0x080, data=b"\x01", is_extended_id=False),
             can.Message(arbitration_id=0x102, data=bytes(8), is_extended_id=False)]  # count 0: no sample
    log = decode_messages([*good, *extra], db)
    assert log.unknown == 2 and log.undecodable == 2
    assert log.event_count.size == 1 and log.samples["time_s"].size == 16


def test_dbc_errors(tmp_path):
    text = (ROOT / "firmware_specs" / "airdata.dbc").read_text()
    f = tmp_path / "x.dbc"
    f.write_text(text.replace("BO_ 259 DME: 8 DAU", "BO_ 259 DMEX: 8 DAU"))
    with pytest.raises(AirborneError, match="message DME: missing"):
        load_dbc(f)
    f.write_text(text.replace("SG_ ShutterTime", "SG_ ShutterTick"))
    with pytest.raises(AirborneError, match="message SHUTTER_EVENT: missing signal"):
        load_dbc(f)
    with pytest.raises(AirborneError, match="not found"):
        load_dbc(tmp_path / "none.dbc")


@pytest.mark.parametrize("suffix", [".asc", ".blf", ".log"])
def test_recorder_writes_logs_python_can_reads_back(tmp_path, db, suffix):
    sim = AircraftSimulator(FlightScript(), SimConfig(sync_every_s=0.7), duration_s=5.0, db=db)
    path = tmp_path / f"air{suffix}"
    tx = open_bus("virtual", f"rec{suffix}")
    rx = open_bus("virtual", f"rec{suffix}")
    try:
        with CanRecorder(rx, path) as rec:
            for t in np.arange(0.0, 5.0, 0.25):
                sim.send(tx, t, t + 0.25)
                rec.drain()
    finally:
        tx.shutdown()
        rx.shutdown()
    sent = decode_messages(sim.messages(0.0, 5.0), db)
    got = read_can_log(path, db)
    assert rec.messages == got.messages == len(sim.messages(0.0, 5.0))
    assert np.array_equal(got.event_count, sent.event_count)
    assert np.array_equal(got.event_time_s, sent.event_time_s)
    for k, v in sent.samples.items():
        assert np.array_equal(got.samples[k], v)


def test_recorder_errors(tmp_path):
    with pytest.raises(AirborneError, match="cannot open CAN interface 'nosuch'"):
        open_bus("nosuch", "x")
    bus = open_bus("virtual", "err")
    try:
        with pytest.raises(AirborneError, match="cannot write CAN log"):
            CanRecorder(bus, tmp_path / "air.unknownformat")
    finally:
        bus.shutdown()
    with pytest.raises(AirborneError, match="not found"):
        read_can_log(tmp_path / "none.asc")


# ------------------------------------------------------------------ clock fit
def events(rng, n=20, offset=3210.0, drift_ppm=-30.0, tod0=40000.0, period=0.001):
    """Irregular shutter instants; radar edge estimates (quantised to the frame grid) and DAU times."""
    s = np.cumsum(rng.uniform(0.7, 2.9, n))
    radar = (np.ceil(s / period) - 0.5) * period + tod0          # edge frame minus half a frame
    dau = np.round((offset + (1 + drift_ppm * 1e-6) * s) * 1e4) / 1e4
    return s, radar, dau


def test_fit_recovers_offset_and_drift_within_a_frame():
    rng = np.random.default_rng(1)
    s, radar, dau = events(rng)
    fit = fit_clock(radar, dau, np.arange(1, 21))
    assert fit.lag == 0 and fit.consistent and not fit.ambiguous and fit.radar_index.size == 20
    assert np.max(np.abs(fit.to_radar(dau) - (40000.0 + s))) < 0.001
    assert np.max(np.abs(fit.residuals_s)) <= 0.00055
    assert fit.drift_ppm == pytest.approx(-30.0, abs=15.0)
    assert fit.offset_s == pytest.approx(40000.0 + s[0] - dau[0], abs=0.001)
    s, radar, dau = events(rng, drift_ppm=100.0)                # 100 ppm over ~36 s: 3.6 ms
    assert fit_clock(radar, dau, np.arange(1, 21)).consistent
    no_drift = fit_clock(radar, dau, np.arange(1, 21), drift=False)
    assert no_drift.drift_ppm == 0.0 and not no_drift.consistent


@pytest.mark.parametrize("case", ["radar_missed_first", "aircraft_missed_first",
                                  "both_ends", "aircraft_lost_one_in_the_middle"])
def test_fit_finds_the_lag_when_an_event_is_missing(case):
    rng = np.random.default_rng(2)
    s, radar, dau = events(rng)
    counts = np.arange(101, 121)                                  # DAU counts from power-on
    r_sel, a_sel, lag = slice(None), np.ones(20, bool), 0
    if case == "radar_missed_first":
        r_sel, lag = slice(1, None), 1
    elif case == "aircraft_missed_first":
        a_sel[0], lag = False, -1
    elif case == "both_ends":
        r_sel, a_sel[-1], lag = slice(2, None), False, 2
    else:
        a_sel[7] = False
    fit = fit_clock(radar[r_sel], dau[a_sel], counts[a_sel])
    assert fit.lag == lag and fit.consistent and not fit.ambiguous
    assert np.max(np.abs(fit.to_radar(dau) - (40000.0 + s))) < 0.001


def test_fit_flags_ambiguity_and_refuses_too_little():
    period_s = np.arange(1, 16) * 1.5                            # a perfectly periodic shutter
    radar = 40000.0 + period_s - 0.0005
    dau = 100.0 + period_s
    fit = fit_clock(radar, dau, np.arange(1, 16))
    assert fit.ambiguous and fit.lag == 0 and fit.consistent
    with pytest.raises(AirborneError, match="too few shutter events"):
        fit_clock(radar[:2], dau[:2], np.arange(1, 3))
    with pytest.raises(AirborneError, match="no shutter events"):
        fit_clock(radar, np.empty(0), np.empty(0, int))
    # an edge whose timing is uncertain (NaN) keeps its place but is not fitted
    r = radar.copy()
    r[4] = np.nan
    fit = fit_clock(r, dau, np.arange(1, 16))
    assert fit.radar_index.size == 14 and 4 not in fit.radar_index.tolist()
    assert math.isclose(fit.offset_s, 40000.0 - 100.0 - 0.0005, abs_tol=1e-6)
