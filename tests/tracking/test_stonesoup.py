"""The tracker against Stone Soup's EKF and RTS smoother on the same 2 000 measurements.

Frames: radar X north, Y east, H up, azimuth clockwise from north; Stone Soup's bearing is
counter-clockwise from its x axis and its elevation from its xy plane. With Stone Soup's
(x, y, z) = (X, −Y, H), its bearing is −AZ and its elevation is EL.
"""

from __future__ import annotations

import datetime as dt
import math

import numpy as np
import pytest

from radar_io.decoding.measurement import MeasurementBatch
from radar_io.tracking.tracker import TrackParams, track_batch
from tests.tracking.approach import approach_truth, measure

pytest.importorskip("stonesoup")

Q = 0.5


def _stonesoup_track(batch: MeasurementBatch, p: TrackParams, x0: np.ndarray,
                     P0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Smoothed radar-frame means (n, 6: x y h vx vy vh) and covariances from Stone Soup."""
    from stonesoup.models.measurement.nonlinear import CartesianToElevationBearingRange
    from stonesoup.models.transition.linear import (
        CombinedLinearGaussianTransitionModel,
        ConstantVelocity,
    )
    from stonesoup.predictor.kalman import ExtendedKalmanPredictor
    from stonesoup.smoother.kalman import ExtendedKalmanSmoother
    from stonesoup.types.angle import Bearing, Elevation
    from stonesoup.types.array import CovarianceMatrix, StateVector
    from stonesoup.types.detection import Detection
    from stonesoup.types.hypothesis import SingleHypothesis
    from stonesoup.types.state import GaussianState
    from stonesoup.types.track import Track
    from stonesoup.updater.kalman import ExtendedKalmanUpdater

    # radar state [x y h vx vy vh] → Stone Soup [X, vX, −Y, −vY, H, vH]
    M = np.zeros((6, 6))
    for ss, (radar, sign) in enumerate([(0, 1), (3, 1), (1, -1), (4, -1), (2, 1), (5, 1)]):
        M[ss, radar] = sign
    transition = CombinedLinearGaussianTransitionModel([ConstantVelocity(Q)] * 3)
    sa = math.radians(p.sigma_angle_deg)
    meas_model = CartesianToElevationBearingRange(
        ndim_state=6, mapping=(0, 2, 4),
        noise_covar=CovarianceMatrix(np.diag([sa ** 2, sa ** 2, p.sigma_range_m ** 2])))
    predictor = ExtendedKalmanPredictor(transition)
    updater = ExtendedKalmanUpdater(meas_model)
    t0 = dt.datetime(2026, 11, 25)
    tod = batch["tod_s"]
    prior = GaussianState(StateVector(M @ x0), CovarianceMatrix(M @ P0 @ M.T),
                          timestamp=t0)
    track = Track([prior])
    for k in range(1, len(batch)):
        when = t0 + dt.timedelta(seconds=float(tod[k] - tod[0]))
        z = StateVector([Elevation(math.radians(batch["el_c_deg"][k])),
                         Bearing(-math.radians(batch["az_c_deg"][k])), batch["sr_c_m"][k]])
        pred = predictor.predict(track[-1], timestamp=when)
        det = Detection(z, timestamp=when, measurement_model=meas_model)
        track.append(updater.update(SingleHypothesis(pred, det)))
    smoothed = ExtendedKalmanSmoother(transition).smooth(track)
    xs = np.array([M.T @ np.asarray(s.state_vector, dtype=float).ravel() for s in smoothed])
    Ps = np.array([M.T @ np.asarray(s.covar, dtype=float) @ M for s in smoothed])
    return xs, Ps


def test_agrees_with_stonesoup_ekf_and_rts(capsys):
    truth = approach_truth(duration_s=20.0)
    full = measure(truth, seed=3, tod_start_s=43_200.0)
    batch = MeasurementBatch({c: full[c][::10] for c in full.columns})   # 2 000 at 100 Hz
    assert len(batch) == 2000
    p = TrackParams(q_mps2=Q, model="cv")
    ours = track_batch(batch, p)
    # the same prior: our track start (converted first measurement, velocity 0 ± 300 m/s)
    from radar_io.tracking import kernels as K

    x0, P0 = np.zeros(6), np.zeros((6, 6))
    K._init(x0, P0, batch["sr_c_m"][0], math.radians(batch["el_c_deg"][0]),
            math.radians(batch["az_c_deg"][0]), p.sigma_range_m, math.radians(p.sigma_angle_deg),
            p.v0_sigma_mps ** 2)
    xs, Ps = _stonesoup_track(batch, p, x0, P0)
    after = (batch["tod_s"] - batch["tod_s"][0]) > 5.0
    worst_pos, ratios = 0.0, []
    for i, a in enumerate(("x", "y", "h")):
        sigma = ours[f"{a}_sigma_m"][after]
        diff = np.abs(ours[f"{a}_m"][after] - xs[after, i]) / sigma
        worst_pos = max(worst_pos, float(diff.max()))
        ratios.append(sigma / np.sqrt(Ps[after, i, i]))
        vs = ours[f"v{a}_sigma_mps"][after]
        ratios.append(vs / np.sqrt(Ps[after, i + 3, i + 3]))
    r = np.concatenate(ratios)
    with capsys.disabled():
        print(f"\nStone Soup: largest position difference {worst_pos:.2e} σ, σ ratio "
              f"{r.min():.4f} … {r.max():.4f}")
    assert worst_pos <= 0.1
    assert r.min() >= 0.8 and r.max() <= 1.25
