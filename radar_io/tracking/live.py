"""The forward filter beside live decoding: one :class:`LiveTracker` per pipeline.

Each chunk's messages get the filtered velocity with its σ (:data:`LIVE_FIELDS`), from
the same compiled kernels as ``radar-io track --forward-only`` (identical numbers for the
same frames). NG frames are predictions (the track's predicted velocity, σ growing); a
frame with no track (before the first good measurement, after a gap of more than
``max_gap_s``) carries nulls. Models and equations: docs/tracking.md.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from radar_io.tracking import kernels as K
from radar_io.tracking.tracker import TrackParams

#: the fields added to every message, in order
LIVE_FIELDS: tuple[str, ...] = K.VELOCITY_COLUMNS
_HALF_DAY_S = 43_200.0


def warm_up() -> float:
    """Compile (or load from numba's cache) the kernels the live filter calls, on a few
    synthetic frames; returns the seconds it took. Call at service start so that the
    first frame does not pay for the compilation."""
    t0 = time.perf_counter()
    tr = LiveTracker(TrackParams())
    n = 4
    ones = np.ones(n, dtype=np.uint8)
    # every path a live stream can take: a start, an NG frame, NG only, a gap that restarts
    # the track, the TOD wrapping at midnight
    for t0_s, good in ((0.0, np.array([1, 1, 0, 1], dtype=np.uint8)), (0.004, 0 * ones),
                       (60.0, ones), (86_399.999, ones)):
        t = (t0_s + 0.001 * np.arange(n)) % 86_400.0
        tr.columns(t, np.full(n, 1.0e4), np.full(n, 0.05), np.full(n, 0.3), good)
    return time.perf_counter() - t0


class LiveTracker:
    """Forward EKF state carried across chunks; ``tracker(msgs)`` adds :data:`LIVE_FIELDS`.

    Reads ``tod_s``, ``sr_c_m``, ``el_c_deg``, ``az_c_deg``, ``rx_good`` of each message
    (the decoder's compensated, calibrated measurement). Buffers are kept between chunks
    (grown when a chunk is larger), so a chunk costs one compiled call and no array
    allocation. Not thread-safe: the reader thread of one pipeline calls it.
    """

    def __init__(self, params: TrackParams) -> None:
        self.params = params
        self._vec = params.vector()
        self._no_rows = np.empty(0, dtype=np.int64)
        self._no_fixes = np.empty((0, 6))
        self._grow(64)
        self.reset()

    def reset(self) -> None:
        """Forget the track and the time base (a replay seek: the stream jumped)."""
        self._x = np.zeros(6)
        self._P = np.zeros((6, 6))
        self._carry = np.zeros(K.CARRY_LEN)
        self._last_tod: float | None = None
        self._day_s = 0.0
        self.frames = 0
        self.outliers = 0

    def _grow(self, n: int) -> None:
        self._cap = n
        self._meas = np.empty((4, n))
        self._good = np.empty(n, dtype=np.uint8)
        self._nis, self._flags = np.empty(n), np.empty(n, dtype=np.uint8)
        self._fx, self._fP = np.empty((n, 6)), np.empty((n, 6, 6))
        self._out = np.empty((n, len(LIVE_FIELDS)))

    @property
    def tracks(self) -> int:
        """Tracks started since the last reset."""
        return int(self._carry[3])

    def _run(self, n: int) -> np.ndarray:
        m = self._meas
        self.outliers += K.live_chunk(m[0], m[1], m[2], m[3], self._good, n, self._x,
                                      self._P, self._carry, self._vec, self._nis,
                                      self._flags, self._fx, self._fP, self._out,
                                      self._no_rows, self._no_fixes)
        self.frames += n
        return self._out[:n]

    def columns(self, t: np.ndarray, sr: np.ndarray, el: np.ndarray, az: np.ndarray,
                good: np.ndarray) -> np.ndarray:
        """Filter frames at unwrapped times ``t`` (s) with SR (m), EL, AZ (rad) and
        ``good`` (0/1); returns a copy of (n, len(LIVE_FIELDS)), NaN without a track."""
        n = len(t)
        if n > self._cap:
            self._grow(n)
        for i, v in enumerate((t, sr, el, az)):
            self._meas[i, :n] = v
        self._good[:n] = good
        return self._run(n).copy()

    def __call__(self, msgs: list[dict[str, Any]]) -> None:
        n = len(msgs)
        if not n:
            return
        if n > self._cap:
            self._grow(max(n, 2 * self._cap))
        t, sr, el, az = self._meas
        good = self._good
        rad = math.radians
        for i, m in enumerate(msgs):
            tod = m["tod_s"]
            if self._last_tod is not None and tod < self._last_tod - _HALF_DAY_S:
                self._day_s += 2 * _HALF_DAY_S  # midnight
            self._last_tod = tod
            t[i] = tod + self._day_s
            s, e, a = m["sr_c_m"], m["el_c_deg"], m["az_c_deg"]
            if m["rx_good"] and s is not None and e is not None and a is not None and s > 0.0:
                sr[i], el[i], az[i] = s, rad(e), rad(a)
                good[i] = 1
            else:
                sr[i] = el[i] = az[i] = math.nan
                good[i] = 0
        for m, row in zip(msgs, self._run(n).tolist(), strict=True):
            m.update(zip(LIVE_FIELDS, [None if v != v else v for v in row], strict=True))
