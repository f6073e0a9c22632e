"""Ground speed and track angle from radar positions, streaming across batches.

For each valid sample the velocity is the least-squares slope of X and Y
against TOD over the valid samples in the trailing window ``(t - window_s, t]``
(causal, so it can feed the uplink live; it lags the truth by about half the
window). Ground speed is ``hypot(vx, vy)``; track angle is
``atan2(vy, vx)`` in degrees, in (-180, 180], 0 = the frame's X axis (north in
the radar frame) and +90 = Y (east). Samples that are NG, or whose window holds
fewer than ``min_samples`` spanning less than ``min_span_s``, get NaN.
TOD wrapping at midnight is handled.
"""

from __future__ import annotations

import numpy as np

from radar_io.decoding.measurement import Columns

KINEMATIC_COLUMNS = ("ground_speed_mps", "track_deg")
_DAY = 86400.0


class Kinematics:
    """Streaming estimator; feed batches in time order with :meth:`update`."""

    #: samples processed per step (bounds the cumulative sums' magnitude)
    BLOCK = 1 << 16

    def __init__(self, window_s: float = 1.0, min_span_s: float = 0.5, min_samples: int = 10) -> None:
        if not window_s > 0 or min_span_s > window_s or min_samples < 2:
            raise ValueError("need window_s > 0, min_span_s <= window_s, min_samples >= 2")
        self.window_s, self.min_span_s, self.min_samples = window_s, min_span_s, min_samples
        self._t = np.empty(0)   # unwrapped times of the carried (trailing-window) valid samples
        self._x = np.empty(0)
        self._y = np.empty(0)
        self._last_tod: float | None = None
        self._day = 0.0          # days added so far (TOD unwrapping)

    def update(self, cols: Columns) -> dict[str, np.ndarray]:
        """``ground_speed_mps`` and ``track_deg`` for every row of a batch (NaN where unavailable)."""
        tod = np.asarray(cols["tod_s"], dtype=np.float64)
        x = np.asarray(cols["x_m"], dtype=np.float64)
        y = np.asarray(cols["y_m"], dtype=np.float64)
        n = tod.size
        gs, trk = np.full(n, np.nan), np.full(n, np.nan)
        t = self._unwrap(tod)
        ok = np.flatnonzero(np.isfinite(x) & np.isfinite(y))
        for k in range(0, ok.size, self.BLOCK):
            idx = ok[k:k + self.BLOCK]
            vx, vy = self._block(t[idx], x[idx], y[idx])
            gs[idx] = np.hypot(vx, vy)
            trk[idx] = np.degrees(np.arctan2(vy, vx))
        trk[trk == -180.0] = 180.0
        return {"ground_speed_mps": gs, "track_deg": trk}

    def _unwrap(self, tod: np.ndarray) -> np.ndarray:
        if not tod.size:
            return tod
        prev = tod[0] if self._last_tod is None else self._last_tod
        steps = np.diff(tod, prepend=prev)
        days = self._day + _DAY * np.cumsum(steps < -_DAY / 2)
        self._day = float(days[-1])
        self._last_tod = float(tod[-1])
        return tod + days

    def _block(self, t: np.ndarray, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        nc = self._t.size
        T = np.concatenate([self._t, t])
        X = np.concatenate([self._x, x])
        Y = np.concatenate([self._y, y])
        t0, x0, y0 = T[0], X[0], Y[0]       # references keep the sums small
        tr, xr, yr = T - t0, X - x0, Y - y0

        def csum(a: np.ndarray) -> np.ndarray:
            return np.concatenate([[0.0], np.cumsum(a)])

        st, sx, sy = csum(tr), csum(xr), csum(yr)
        stt, stx, sty = csum(tr * tr), csum(tr * xr), csum(tr * yr)
        i = np.arange(nc, T.size)
        j = np.searchsorted(tr, tr[i] - self.window_s, side="right")
        m = (i - j + 1).astype(np.float64)

        def win(c: np.ndarray) -> np.ndarray:
            return c[i + 1] - c[j]

        St = win(st)
        den = m * win(stt) - St * St
        with np.errstate(invalid="ignore", divide="ignore"):
            vx = (m * win(stx) - St * win(sx)) / den
            vy = (m * win(sty) - St * win(sy)) / den
        bad = (m < self.min_samples) | (tr[i] - tr[j] < self.min_span_s) | ~(den > 0)
        vx[bad] = np.nan
        vy[bad] = np.nan
        keep = tr > tr[-1] - self.window_s
        self._t, self._x, self._y = T[keep], X[keep], Y[keep]
        return vx, vy
