"""The simulator: its frames decode back to the scripted flight, with the events it promises."""

from __future__ import annotations

import numpy as np
import pytest

from radar_io.decoding.decoders import decode_bytes
from radar_io.simulation.radar import FlightScript, RadarSimulator, SimConfig
from radar_io.sources.sim import SimSource


def test_compensated_track_recovers_the_truth():
    sim = RadarSimulator(FlightScript(course_deg=200.0, height_m=900.0, speed_mps=120.0,
                                      start_x_m=20000.0, start_y_m=3000.0),
                         SimConfig(seed=4, noise_sr_m=0.0, noise_angle_deg=0.0, lag_s=0.2))
    data, truth = sim.generate(30000)
    b = decode_bytes(data)
    good = b["rx_good"] == 1
    assert np.array_equal(good, truth["rx_good"] == 1)
    # without noise, compensation leaves only quantisation: ≤ LSBs projected at range
    for c in ("x_m", "y_m", "h_m"):
        err = np.abs(b[c][good] - truth[c][good])
        assert err.max() < 2.5, c
    # and servo lag is real: the raw words alone are off by tens of metres
    raw_x = b["sr_m"] * np.cos(np.radians(b["el_deg"])) * np.cos(np.radians(b["az_deg"]))
    assert np.abs(raw_x[good] - truth["x_m"][good]).max() > 10


def test_events_sync_go_and_ng():
    sim = RadarSimulator(config=SimConfig(seed=9, sync_every_s=2.0, go_delay_s=1.0, ng_per_min=30))
    data, _truth = sim.generate(10000)  # 10 s
    b = decode_bytes(data)
    edges = np.flatnonzero(np.diff(b["sync"].astype(int)) == 1) + 1
    assert np.array_equal(b["tod_s"][edges] - b["tod_s"][0], np.array([2.0, 4.0, 6.0, 8.0])) or \
        np.allclose(b["tod_s"][edges] - b["tod_s"][0], [2.0, 4.0, 6.0, 8.0], atol=2e-3)
    assert b["go"][:1000].sum() == 0 and b["go"][1000:].all()
    ng = 1 - b["rx_good"].mean()
    assert 0.0 < ng < 0.5
    assert b.stats["seq_gaps"] == 0


def test_corruption_is_applied_and_counted():
    sim = RadarSimulator(config=SimConfig(seed=1, flip_rate=1e-3, drop_rate=1e-4, insert_rate=1e-4))
    data, _ = sim.generate(20000)
    bad = sim.corrupt(data)
    c = sim.state.counts
    assert c["flipped"] > 300 and c["dropped"] > 10 and c["inserted"] > 10
    assert len(bad) == len(data) - c["dropped"] + c["inserted"]
    st = decode_bytes(bad).stats
    assert st["crc_errors"] > 0 and 15000 < st["frames"] < 20000


@pytest.mark.slow
def test_sim_source_paces_in_real_time():
    import time

    src = SimSource("sim://?rate_hz=500&seed=3")
    src.open()
    t0, n = time.monotonic(), 0
    while time.monotonic() - t0 < 1.0:
        n += len(src.read(0.05))
    src.close()
    assert 0.7 * 500 * 24 < n < 1.3 * 500 * 24
