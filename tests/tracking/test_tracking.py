"""The tracker against truth: an independently made approach and the simulator."""

from __future__ import annotations

import numpy as np
import pytest

from radar_io.coordinates.transforms import radar_xyh
from radar_io.decoding.measurement import MeasurementBatch
from radar_io.tracking.tracker import (
    TRACK_COLUMNS,
    TrackParams,
    TrackSummary,
    iter_track,
    track_batch,
)
from tests.tracking.approach import approach_truth, measure

AXES = ("x", "y", "h")


def _errors(out: MeasurementBatch, truth: dict[str, np.ndarray], after_s: float = 5.0
            ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], np.ndarray]:
    pos = {a: out[f"{a}_m"] - truth[f"{a}_m"] for a in AXES}
    vel = {a: out[f"v{a}_mps"] - truth[f"v{a}_mps"] for a in AXES}
    m = (truth["t_s"] > after_s) & np.isfinite(pos["x"])
    return pos, vel, m


def _raw_rms(batch: MeasurementBatch, truth: dict[str, np.ndarray]) -> float:
    x, y, h = radar_xyh(batch["sr_c_m"], batch["el_c_deg"], batch["az_c_deg"])
    e2 = (x - truth["x_m"]) ** 2 + (y - truth["y_m"]) ** 2 + (h - truth["h_m"]) ** 2
    return float(np.sqrt(np.nanmean(e2)))


def _rms3(e: dict[str, np.ndarray], m: np.ndarray) -> float:
    return float(np.sqrt(np.mean(sum(e[a][m] ** 2 for a in AXES))))


@pytest.fixture(scope="module")
def approach() -> tuple[dict[str, np.ndarray], MeasurementBatch, np.ndarray]:
    truth = approach_truth()
    bad = np.arange(40_000, 40_010)
    return truth, measure(truth, ng=[(30.0, 30.4), (61.0, 62.0)], outliers=bad), bad


def test_smoothed_approach_against_truth(approach, capsys):
    truth, batch, bad = approach
    summary = TrackSummary()
    out = track_batch(batch, TrackParams(q_mps2=0.5), summary=summary)
    assert out.columns == TRACK_COLUMNS and len(out) == len(batch)
    pos, vel, m = _errors(out, truth)
    raw, smoothed, v_rms = _raw_rms(batch, truth), _rms3(pos, m), _rms3(vel, m)
    inside = {a: float(np.mean(np.abs(pos[a][m]) <= 1.96 * out[f"{a}_sigma_m"][m]))
              for a in AXES}
    inside_v = {a: float(np.mean(np.abs(vel[a][m]) <= 1.96 * out[f"v{a}_sigma_mps"][m]))
                for a in AXES}
    with capsys.disabled():
        print(f"\napproach, smoothed: raw RMS {raw:.2f} m, smoothed {smoothed:.3f} m "
              f"(1/{raw / smoothed:.0f}), 3-D velocity RMS {v_rms:.3f} m/s, "
              f"within 1.96σ {inside} (velocity {inside_v})")
    assert smoothed <= raw / 10
    assert v_rms <= 0.5
    for a in AXES:
        assert 0.90 <= inside[a] <= 0.99, (a, inside[a])
    # the injected range outliers are flagged, not used; nothing else is
    assert np.array_equal(np.flatnonzero(out["outlier"]), bad)
    assert summary.outliers == bad.size and summary.tracks == 1
    # TOD wrapped at midnight (t = 60 s) without a restart; NG rows are predictions
    assert np.all(np.isfinite(out["x_m"])) and np.isnan(out["nis"][30_100])


def test_forward_filter_velocity_rms_and_lag(approach, capsys):
    truth, batch, _ = approach
    out = track_batch(batch, TrackParams(q_mps2=0.5), smooth=False)
    pos, vel, m = _errors(out, truth)
    v_rms = _rms3(vel, m)
    # lag: the shift of the truth that best matches the filtered velocity
    shifts = np.arange(0, 1001, 10)
    rms = [np.sqrt(np.mean(sum((out[f"v{a}_mps"][m][s:] - truth[f"v{a}_mps"][m][:m.sum() - s]) ** 2
                               for a in AXES))) for s in shifts]
    lag_s = shifts[int(np.argmin(rms))] / 1000.0
    with capsys.disabled():
        print(f"\napproach, forward filter: position RMS {_rms3(pos, m):.3f} m, 3-D velocity RMS "
              f"{v_rms:.3f} m/s, lag {lag_s:.2f} s (RMS {min(rms):.3f} m/s after the shift)")
    assert v_rms < 3.0 and lag_s < 1.0


def test_simulator_flight_against_truth(capsys):
    from radar_io.decoding.batch_decoder import decode_bytes
    from radar_io.simulation.radar import RadarSimulator, SimConfig

    sim = RadarSimulator(config=SimConfig(tod_start_s=86_380.0, seed=5, ng_per_min=6.0))
    data, truth = sim.generate(60_000)
    batch = decode_bytes(data)
    truth["vx_mps"], truth["vy_mps"] = (np.full(60_000, 70.0 * f(np.radians(340.0)))
                                        for f in (np.cos, np.sin))
    truth["vh_mps"] = np.zeros(60_000)
    # the simulator's noise: 1 m and 0.005° servo noise, plus the 1-m range word's rounding
    params = TrackParams(q_mps2=0.5, sigma_range_m=1.04, sigma_angle_deg=0.005)
    out = track_batch(batch, params)
    pos, vel, m = _errors(out, truth)
    raw, smoothed, v_rms = _raw_rms(batch, truth), _rms3(pos, m), _rms3(vel, m)
    inside = {a: float(np.mean(np.abs(pos[a][m]) <= 1.96 * out[f"{a}_sigma_m"][m]))
              for a in AXES}
    with capsys.disabled():
        print(f"\nsimulator, smoothed: raw RMS {raw:.3f} m, smoothed {smoothed:.4f} m "
              f"(1/{raw / smoothed:.0f}), 3-D velocity RMS {v_rms:.3f} m/s, within 1.96σ {inside}")
    assert smoothed <= raw / 10 and v_rms <= 0.5
    for a in AXES:
        assert 0.90 <= inside[a] <= 0.99, (a, inside[a])


def test_long_gap_restarts_the_track(approach):
    truth, _, _ = approach
    batch = measure(truth, ng=[(40.0, 47.0)])
    summary = TrackSummary()
    out = track_batch(batch, TrackParams(max_gap_s=5.0), summary=summary)
    t = truth["t_s"]
    assert summary.tracks == 2
    assert np.all(np.isfinite(out["x_m"][(t >= 40.0) & (t < 44.9)]))   # predicted
    assert np.all(np.isnan(out["x_m"][(t > 45.1) & (t < 47.0)]))       # track ended
    assert np.all(np.isfinite(out["x_m"][t >= 47.0]))                  # restarted


def test_streaming_and_blocks_give_the_same_answer(approach):
    _, batch, _ = approach
    n = 30_000
    part = MeasurementBatch({c: batch[c][:n] for c in batch.columns})
    params = TrackParams()
    whole = track_batch(part, params)
    chunks = [MeasurementBatch({c: part[c][i:i + 7_777] for c in part.columns})
              for i in range(0, n, 7_777)]
    blocks = MeasurementBatch.concat(list(iter_track(chunks, params, block_rows=4_096)))
    fwd_whole = track_batch(part, params, smooth=False)
    fwd_stream = MeasurementBatch.concat(list(iter_track(chunks, params, smooth=False)))
    for c in TRACK_COLUMNS:
        np.testing.assert_array_equal(blocks[c], whole[c], err_msg=c)
        np.testing.assert_array_equal(fwd_stream[c], fwd_whole[c], err_msg=c)
    # the smoother is more certain than the filter
    assert np.all(whole["x_sigma_m"][100:-1] < fwd_whole["x_sigma_m"][100:-1])
    assert whole["x_sigma_m"][-1] == fwd_whole["x_sigma_m"][-1]   # the last: filtered = smoothed


def test_missing_column_is_one_clear_error():
    from radar_io.errors import ConfigError

    with pytest.raises(ConfigError, match="sr_c_m"):
        track_batch(MeasurementBatch({"seq": np.zeros(3), "tod_s": np.zeros(3)}))


def test_bias_estimated_from_photo_fixes(capsys):
    """TR-861 table 5-7's biases, 18 photo fixes of σ 2 m: each within 3σ of the truth."""
    from tests.tracking.approach import photo_fixes

    truth = approach_truth()
    injected = (12.5, -0.334, -1.135)
    batch = measure(truth, seed=21, bias=injected)
    fixes = photo_fixes(truth, batch, 18)
    summary = TrackSummary()
    out = track_batch(batch, TrackParams(), fixes=fixes, estimate_bias=True, summary=summary)
    b = summary.bias
    got = (b.dsr_m, b.del_deg, b.daz_deg)
    with capsys.disabled():
        print("\nbias: " + ", ".join(f"{n} {g:+.4f} ± {s:.4f} (truth {t:+.3f}, {(g - t) / s:+.2f}σ)"
                                     for n, g, s, t in zip(("ΔSR m", "ΔEL°", "ΔAZ°"), got,
                                                           b.sigma, injected, strict=True))
              + f"; χ² {b.chi2:.1f} on {3 * (b.fixes_used - 1)} dof")
    for g, s, t in zip(got, b.sigma, injected, strict=True):
        assert abs(g - t) <= 3 * s and s > 0
    assert b.fixes_used == 18 and summary.fixes_used == 18
    # the track is the bias-corrected one: off by what the estimate's σ allows (0.5 m in
    # range, 0.0033° ≈ 0.7 m across at 12 km), not by the bias
    pos, vel, m = _errors(out, truth)
    assert _rms3(pos, m) < 3.0 and _rms3(vel, m) <= 0.5
    # without the estimate the same data leave a track hundreds of metres off
    plain = track_batch(batch, TrackParams())
    assert _rms3(_errors(plain, truth)[0], m) > 100.0
