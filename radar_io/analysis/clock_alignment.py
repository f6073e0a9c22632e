"""Time alignment of the airborne recorder to the radar (radar-interface.md §9).

Each camera-shutter closure is a ``SHUTTER_EVENT`` on the aircraft (DAU clock
time, 0.1 ms) and a SYNC 0→1 edge in the radar stream. The shutter closed
during the frame interval that ends at the edge frame, so the radar's event
time is taken as the edge frame's TOD minus half the (median) frame period;
the quantisation is then ±½ frame. An edge whose preceding frame is missing
(a gap of more than 1.5 frame periods) keeps its place in the count but is left
out of the fit.

The n-th radar edge is paired with the aircraft event numbered
``first ShutterCount + n + lag``. Integer lags in ``[-max_lag, max_lag]`` are
tried (a recorder may have missed an event at either end); each is fitted by
least squares ``tod = α + β·(t_ac − t_ref)`` (β = 1 without drift). A lag is
*consistent* when all its residuals are within one frame period; among the
consistent lags the one with the most pairs, then the smallest |lag|, wins;
if none is consistent the smallest RMS wins. With a perfectly periodic
shutter every lag fits equally well — the result is then flagged
``ambiguous`` and lag 0 (n-th to n-th) is kept.

Reported clock model: ``tod = t_ac + offset_s + (t_ac − t_ref)·(1/(1 + drift) − 1)``
with ``offset_s`` the radar TOD minus the DAU clock at ``t_ref`` (the first
paired aircraft event) and ``drift`` = drift_ppm·1e-6 the DAU clock's rate
error relative to the radar clock (+ = DAU fast).
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from radar_io.decoding.airdata import AircraftLog, load_dbc, read_can_log
from radar_io.decoding.measurement import MeasurementBatch
from radar_io.errors import AirborneError
from radar_io.simulation.aircraft import FT_M, expected_pa_minus_h

_DAY = 86400.0


@dataclass
class RadarTrack:
    """What alignment needs from a radar recording (TOD unwrapped past midnight)."""

    tod_s: np.ndarray
    h_m: np.ndarray
    x_m: np.ndarray
    y_m: np.ndarray
    valid: np.ndarray
    edge_s: np.ndarray        #: estimated shutter instants (TOD); NaN when timing is uncertain
    frame_period_s: float
    frames: int


def radar_track(batches: Iterable[MeasurementBatch]) -> RadarTrack:
    """Collect TOD, height, position and SYNC edges from decoded batches (in stream order)."""
    parts: dict[str, list[np.ndarray]] = {k: [] for k in ("tod_s", "sync", "rx_good", "h_m", "x_m", "y_m")}
    for b in batches:
        for k, v in parts.items():
            v.append(np.asarray(b[k]))
    cols = {k: np.concatenate(v) if v else np.empty(0) for k, v in parts.items()}
    tod = cols["tod_s"].astype(np.float64)
    if tod.size < 2:
        raise AirborneError("the radar recording holds fewer than 2 RDR1 frames")
    tod = tod + _DAY * np.cumsum(np.diff(tod, prepend=tod[0]) < -_DAY / 2)
    edge, period = shutter_instants(tod, cols["sync"])
    h = cols["h_m"].astype(np.float64)
    return RadarTrack(tod_s=tod, h_m=h, x_m=cols["x_m"].astype(np.float64),
                      y_m=cols["y_m"].astype(np.float64),
                      valid=(cols["rx_good"] == 1) & np.isfinite(h), edge_s=edge,
                      frame_period_s=period, frames=int(tod.size))


def shutter_instants(tod_s: np.ndarray, sync: np.ndarray) -> tuple[np.ndarray, float]:
    """Estimated shutter instants (unwrapped TOD) of the SYNC 0→1 edges, NaN where the frame
    before the edge is missing, and the median frame period (s); see the module doc."""
    if tod_s.size < 2:
        raise AirborneError("the radar recording holds fewer than 2 RDR1 frames")
    steps = np.diff(tod_s)
    period = float(np.median(steps))
    if not period > 0:
        raise AirborneError("cannot determine the radar frame period from TOD")
    s = np.asarray(sync).astype(bool)
    e = np.flatnonzero(s[1:] & ~s[:-1]) + 1
    edge = tod_s[e] - 0.5 * period
    edge[steps[e - 1] > 1.5 * period] = np.nan
    return edge, period


def read_radar_track(path: str | os.PathLike[str], spec: Any = None) -> RadarTrack:
    """Decode a ``.rdrlog`` (or raw capture) into a :class:`RadarTrack`."""
    from radar_io.decoding.batch_decoder import iter_decode
    from radar_io.recording.rdrlog import iter_payloads

    if not os.path.isfile(path):
        raise AirborneError(f"radar recording not found: {path}")
    return radar_track(iter_decode(iter_payloads(path), spec=spec))


@dataclass
class ClockFit:
    """Aircraft clock → radar TOD."""

    alpha: float               #: TOD at t_ref
    beta: float                #: radar seconds per aircraft second
    t_ref_s: float
    lag: int
    radar_index: np.ndarray    #: paired radar edges …
    aircraft_index: np.ndarray  #: … and aircraft events (indices into the inputs)
    residuals_s: np.ndarray
    drift_fitted: bool
    ambiguous: bool
    consistent: bool
    candidates: list[dict[str, Any]] = field(default_factory=list)

    @property
    def offset_s(self) -> float:
        return self.alpha - self.t_ref_s

    @property
    def drift_ppm(self) -> float:
        return (1.0 / self.beta - 1.0) * 1e6

    def to_radar(self, t_ac: Any) -> np.ndarray:
        """Radar TOD (unwrapped) of aircraft clock times."""
        return self.alpha + self.beta * (np.asarray(t_ac, dtype=np.float64) - self.t_ref_s)


def _fit(x: np.ndarray, y: np.ndarray, drift: bool) -> tuple[float, float, np.ndarray]:
    """y ≈ a + b·x by least squares (b = 1 without drift); returns a, b, residuals."""
    if drift:
        xm, ym = x.mean(), y.mean()
        b = float(np.sum((x - xm) * (y - ym)) / np.sum((x - xm) ** 2))
        a = float(ym - b * xm)
    else:
        b = 1.0
        a = float(np.mean(y - x))
    return a, b, y - (a + b * x)


def fit_clock(radar_edge_s: np.ndarray, event_time_s: np.ndarray, event_count: np.ndarray, *,
              drift: bool = True, max_lag: int = 2, frame_period_s: float = 1e-3) -> ClockFit:
    """Pair the n-th radar edges with the aircraft events and fit the clock (see the module doc)."""
    r = np.asarray(radar_edge_s, dtype=np.float64)
    order = np.argsort(event_count, kind="stable")
    counts = np.asarray(event_count)[order]
    need = 3 if drift else 2
    if r.size == 0 or counts.size == 0:
        raise AirborneError(f"no shutter events to match: {r.size} radar SYNC edges, "
                            f"{counts.size} aircraft SHUTTER_EVENTs")
    by_count = {int(c): i for i, c in enumerate(counts.tolist())}
    overlap = min(int(np.isfinite(r).sum()), counts.size)
    best: tuple[Any, ...] | None = None
    candidates = []
    for lag in range(-max_lag, max_lag + 1):
        ri, ai = [], []
        for i in range(r.size):
            j = by_count.get(int(counts[0]) + i + lag)
            if j is not None and math.isfinite(r[i]):
                ri.append(i)
                ai.append(order[j])
        if len(ri) < max(need, overlap - max_lag):
            continue
        ri_a, ai_a = np.array(ri), np.array(ai)
        t_ref = float(np.asarray(event_time_s, dtype=np.float64)[ai_a[0]])
        x = np.asarray(event_time_s, dtype=np.float64)[ai_a] - t_ref
        a, b, res = _fit(x, r[ri_a], drift)
        rms, worst = float(np.sqrt(np.mean(res ** 2))), float(np.max(np.abs(res)))
        ok = worst <= frame_period_s
        candidates.append({"lag": lag, "pairs": len(ri), "rms_ms": rms * 1e3,
                           "max_abs_ms": worst * 1e3, "consistent": ok})
        key = (0, -len(ri), abs(lag), lag) if ok else (1, rms, abs(lag), lag)
        if best is None or key < best[0]:
            best = (key, a, b, t_ref, lag, ri_a, ai_a, res, ok)
    if best is None:
        raise AirborneError(f"too few shutter events to align: {r.size} radar SYNC edges, "
                            f"{counts.size} aircraft events (need {need} pairs)")
    _, a, b, t_ref, lag, ri_a, ai_a, res, ok = best
    n_ok = sum(c["consistent"] for c in candidates)
    return ClockFit(alpha=a, beta=b, t_ref_s=t_ref, lag=lag, radar_index=ri_a, aircraft_index=ai_a,
                    residuals_s=res, drift_fitted=drift, ambiguous=n_ok > 1, consistent=ok,
                    candidates=candidates)


def compare_altitude(fit: ClockFit, log: AircraftLog, track: RadarTrack, *, max_gap_s: float = 0.05,
                     antenna_msl_m: float | None = None, qnh_hpa: float | None = None
                     ) -> dict[str, np.ndarray]:
    """Aircraft pressure altitude vs radar height at the aligned 8 Hz sample instants.

    Radar H, X, Y are interpolated linearly between the valid radar samples that
    bracket each aircraft sample (no more than ``max_gap_s`` apart). Returns
    per-sample arrays: ``tod_s``, ``pressure_altitude_m``, ``radar_h_m``,
    ``difference_m`` and, given the antenna's MSL height and QNH, ``expected_m``.
    """
    s = log.samples
    keep = np.isfinite(s["time_s"]) & np.isfinite(s["pressure_altitude_ft"])
    tod = fit.to_radar(s["time_s"][keep])
    pa = s["pressure_altitude_ft"][keep] * FT_M
    tv = track.tod_s[track.valid]
    j = np.searchsorted(tv, tod)
    inside = (j > 0) & (j < tv.size)
    jj = np.clip(j, 1, max(tv.size - 1, 1))
    if tv.size >= 2:
        inside &= (tv[jj] - tv[jj - 1]) <= max_gap_s
    else:
        inside[:] = False
    tod, pa = tod[inside], pa[inside]
    h, x, y = (np.interp(tod, tv, a[track.valid]) for a in (track.h_m, track.x_m, track.y_m))
    out = {"tod_s": tod, "pressure_altitude_m": pa, "radar_h_m": h, "difference_m": pa - h}
    if antenna_msl_m is not None and qnh_hpa is not None:
        out["expected_m"] = expected_pa_minus_h(x, y, h, antenna_msl_m, qnh_hpa)
    return out


def _stats(a: np.ndarray) -> dict[str, float | int | None]:
    if a.size == 0:
        return {"n": 0, "mean": None, "std": None, "min": None, "max": None}
    return {"n": int(a.size), "mean": float(a.mean()), "std": float(a.std()),
            "min": float(a.min()), "max": float(a.max())}


def align_files(radar_path: str | os.PathLike[str], can_log_path: str | os.PathLike[str], *,
                dbc: str | os.PathLike[str] | None = None, drift: bool = True, max_lag: int = 2,
                antenna_msl_m: float | None = None, qnh_hpa: float | None = None,
                spec: Any = None) -> dict[str, Any]:
    """Align an airborne CAN log to a radar recording; a JSON-ready report (see docs)."""
    track = read_radar_track(radar_path, spec)
    log = read_can_log(can_log_path, load_dbc(dbc))
    fit = fit_clock(track.edge_s, log.event_time_s, log.event_count, drift=drift,
                    max_lag=max_lag, frame_period_s=track.frame_period_s)
    alt = compare_altitude(fit, log, track, antenna_msl_m=antenna_msl_m, qnh_hpa=qnh_hpa)
    res_ms = fit.residuals_s * 1e3
    altitude: dict[str, Any] = {"pressure_altitude_minus_radar_h_m": _stats(alt["difference_m"])}
    if "expected_m" in alt:
        altitude["expected_m"] = _stats(alt["expected_m"])
        altitude["difference_minus_expected_m"] = _stats(alt["difference_m"] - alt["expected_m"])
    return {
        "radar": {"file": str(radar_path), "frames": track.frames,
                  "sync_edges": int(track.edge_s.size),
                  "frame_period_ms": track.frame_period_s * 1e3},
        "aircraft": {"file": str(can_log_path), "messages": log.messages,
                     "unknown_messages": log.unknown, "undecodable_messages": log.undecodable,
                     "shutter_events": int(log.event_count.size),
                     "samples": int(log.samples["time_s"].size)},
        "clock": {"offset_s": fit.offset_s, "drift_ppm": fit.drift_ppm if drift else 0.0,
                  "drift_fitted": drift, "t_ref_aircraft_s": fit.t_ref_s,
                  "tod_ref_s": fit.alpha % _DAY,
                  "model": "tod_s = t_ac_s + offset_s + (t_ac_s - t_ref_aircraft_s) * "
                           "(1 / (1 + drift_ppm * 1e-6) - 1)",
                  "lag": fit.lag, "matched_events": int(fit.radar_index.size),
                  "ambiguous": fit.ambiguous, "consistent": fit.consistent,
                  "candidates": fit.candidates},
        "residuals_ms": {"rms": float(np.sqrt(np.mean(res_ms ** 2))),
                         "max_abs": float(np.max(np.abs(res_ms))),
                         "values": [round(float(v), 4) for v in res_ms]},
        "altitude": {"samples": int(alt["difference_m"].size), **altitude},
    }
