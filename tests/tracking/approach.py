"""An approach with turns and a descent, made independently of radar_io's conversions.

The truth is integrated from a turn-rate and a vertical-speed profile; SR / EL / AZ come
from pymap3d's ENU → AER (east = radar Y, north = radar X, up = radar H), not from
``radar_io.coordinates``; noise is TR-861's (5 m rms range, 0.2 mil rms angle).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import pymap3d

from radar_io.decoding.measurement import MeasurementBatch

if TYPE_CHECKING:
    from radar_io.tracking.fusion import Fixes

SIGMA_RANGE_M = 5.0
SIGMA_ANGLE_DEG = 0.2 * 360.0 / 6400.0


def _ramp(t: np.ndarray, knots: list[tuple[float, float]]) -> np.ndarray:
    """Piecewise-linear profile through (time, value) knots."""
    ts, vs = zip(*knots, strict=True)
    return np.interp(t, ts, vs)


def _integrate(t: np.ndarray, rate: np.ndarray, start: float) -> np.ndarray:
    """Trapezoidal integral of ``rate`` over ``t`` from ``start``."""
    out = np.empty_like(rate)
    out[0] = start
    out[1:] = start + np.cumsum(0.5 * (rate[1:] + rate[:-1]) * np.diff(t))
    return out


def photo_fixes(truth: dict[str, np.ndarray], batch: MeasurementBatch, count: int,
                sigma_m: float = 2.0, seed: int = 5) -> Fixes:
    """``count`` photo fixes (σ ``sigma_m`` per axis) at the first SYNC 0→1 edges."""
    from radar_io.tracking.fusion import Fixes

    rng = np.random.default_rng(seed)
    s = batch["sync"].astype(np.int8)
    rows = np.flatnonzero((s == 1) & (np.concatenate(([0], s[:-1])) == 0))[:count]
    xyh = np.column_stack([truth[c][rows] for c in ("x_m", "y_m", "h_m")])
    return Fixes(np.arange(count), xyh + rng.normal(0.0, sigma_m, xyh.shape),
                 np.full((count, 3), sigma_m))


def approach_truth(rate_hz: float = 1000.0, duration_s: float = 120.0) -> dict[str, np.ndarray]:
    """Truth at ``rate_hz``: X (north), Y (east), H (up) and their rates (m, m/s).

    75 m/s heading 250°, a 3 s roll-in to a left rate-one turn of 90° (3°/s), roll-out,
    a right turn of 30° at 2°/s, and a descent at −3.9 m/s (≈ 3°) from t = 70 s.
    """
    t = np.arange(round(duration_s * rate_hz)) / rate_hz
    turn = np.radians(_ramp(t, [(0, 0), (20, 0), (23, -3), (50, -3), (53, 0), (80, 0),
                                (82, 2), (95, 2), (97, 0), (200, 0)]))
    heading = _integrate(t, turn, np.radians(250.0))
    speed = 75.0
    vx, vy = speed * np.cos(heading), speed * np.sin(heading)
    vh = _ramp(t, [(0, 0), (70, 0), (75, -3.9), (200, -3.9)])
    return {"t_s": t, "x_m": _integrate(t, vx, 9000.0), "y_m": _integrate(t, vy, 6000.0),
            "h_m": _integrate(t, vh, 900.0), "vx_mps": vx, "vy_mps": vy, "vh_mps": vh}


def measure(truth: dict[str, np.ndarray], seed: int = 11, tod_start_s: float = 86_340.0,
            ng: list[tuple[float, float]] | None = None, outliers: np.ndarray | None = None,
            bias: tuple[float, float, float] = (0.0, 0.0, 0.0),
            sync_every_s: float = 5.0) -> MeasurementBatch:
    """Noisy radar measurements of ``truth`` as decoded columns (TOD wraps at midnight).

    ``ng``: (start, end) seconds of NG; ``outliers``: sample indices whose range is 300 m
    off; ``bias``: ΔSR (m), ΔEL, ΔAZ (deg) in the calibration convention (truth = reading
    + Δ, so the readings are truth − Δ); SYNC is high for 20 ms every ``sync_every_s``
    from t = ``sync_every_s`` on.
    """
    rng = np.random.default_rng(seed)
    az, el, sr = pymap3d.enu2aer(truth["y_m"], truth["x_m"], truth["h_m"], deg=True)
    n = sr.size
    sr = sr - bias[0] + rng.normal(0.0, SIGMA_RANGE_M, n)
    el = el - bias[1] + rng.normal(0.0, SIGMA_ANGLE_DEG, n)
    az = np.mod(az - bias[2] + rng.normal(0.0, SIGMA_ANGLE_DEG, n), 360.0)
    t = truth["t_s"]
    sync = ((np.mod(t, sync_every_s) < 0.02) & (t >= sync_every_s)).astype(np.uint8)
    good = np.ones(n, dtype=np.uint8)
    for a, b in ng or []:
        good[(truth["t_s"] >= a) & (truth["t_s"] < b)] = 0
    if outliers is not None:
        sr[outliers] += 300.0
    sr, el, az = (np.where(good == 1, v, np.nan) for v in (sr, el, az))
    tod = np.round(np.mod(tod_start_s + truth["t_s"], 86400.0) / 1e-4) * 1e-4
    cols = {"seq": np.arange(n, dtype=np.int64) & 0xFFFF, "tod_s": tod, "sr_c_m": sr,
            "el_c_deg": el, "az_c_deg": az, "rx_good": good, "sync": sync}
    return MeasurementBatch(cols)
