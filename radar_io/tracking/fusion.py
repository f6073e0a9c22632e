"""Photo fixes and the radar biases ΔSR, ΔEL, ΔAZ they make observable.

A photo fix is a resected camera position in the radar frame (X north, Y east, Z down, as
``radar-io calibrate`` uses) with its σ per axis, taken at a SYNC 0→1 edge of the input.
:func:`estimate_bias` compares each fix with the radar-only smoothed track at its edge, in
SR / EL / AZ, and solves for the constant bias by generalised least squares — every fix
weighted by the covariance of its difference (photo σ + the smoother's covariance, mapped
through the Jacobian of the spherical conversion). The biases use the calibration set's
convention: the value is added to the reading (``truth = reading + Δ``). Equations:
docs/tracking.md.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from radar_io.errors import AirborneError, CalibrationError, CalibrationInputError

FIX_COLUMNS = ("sync_index", "photo_x_m", "photo_y_m", "photo_z_m",
               "sigma_x_m", "sigma_y_m", "sigma_z_m")
METHOD = ("radar-io track: generalised least squares of photo − smoothed radar track in "
          "SR/EL/AZ at the SYNC edges, weighted by photo σ and the smoother covariance "
          "(docs/tracking.md)")


@dataclass(frozen=True)
class Fixes:
    """Photo fixes: SYNC edge index, position X, Y, H (m, H up) and σ per axis (m)."""

    sync_index: np.ndarray
    xyh_m: np.ndarray      #: (m, 3)
    sigma_m: np.ndarray    #: (m, 3)
    source: str = ""
    sha256: str = ""

    def __len__(self) -> int:
        return int(self.sync_index.size)


def read_fixes(path: str | os.PathLike[str]) -> Fixes:
    """Read a fixes CSV (:data:`FIX_COLUMNS`; Z down); one clear error naming file, line, column."""
    from radar_io.calibration.tables import read_table

    t = read_table(path, min_rows=1)
    t.require(*FIX_COLUMNS)
    idx = t.floats("sync_index")
    for v, line in zip(idx, t.lines, strict=True):
        if v < 0 or v != int(v):
            raise CalibrationInputError(f"{t.path}, line {line}, column sync_index: expected a "
                                        f"0-based integer, got {v!r}")
    sig = np.column_stack([t.floats(c) for c in ("sigma_x_m", "sigma_y_m", "sigma_z_m")])
    for row, line in zip(sig, t.lines, strict=True):
        for c, v in zip(("sigma_x_m", "sigma_y_m", "sigma_z_m"), row, strict=True):
            if not v > 0:
                raise CalibrationInputError(f"{t.path}, line {line}, column {c}: expected a "
                                            f"positive σ, got {v!r}")
    order = np.argsort(idx, kind="stable")
    ii = idx[order].astype(np.int64)
    if np.any(np.diff(ii) == 0):
        raise CalibrationInputError(f"{t.path}: sync_index {int(ii[np.diff(ii) == 0][0])} "
                                    "appears twice")
    xyh = np.column_stack([t.floats("photo_x_m"), t.floats("photo_y_m"), -t.floats("photo_z_m")])
    return Fixes(ii, xyh[order], sig[order], source=os.fspath(path), sha256=t.sha256)


def sync_edge_rows(sync: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows of the SYNC 0→1 edges, numbered as the service and ``calibrate`` do: a recording
    starting with SYNC high counts that event, but it is incomplete. Returns (rows, complete)."""
    s = np.asarray(sync).astype(np.int8)
    prev = np.concatenate(([-1], s[:-1])) if s.size else s
    rows = np.flatnonzero((s == 1) & (prev != 1))
    return rows, prev[rows] == 0


def fix_rows(fixes: Fixes, sync: np.ndarray, source: str = "fixes") -> np.ndarray:
    """The input row of each fix's SYNC edge; CalibrationInputError if an edge is missing."""
    rows, complete = sync_edge_rows(sync)
    for i in fixes.sync_index.tolist():
        if i >= rows.size:
            raise CalibrationInputError(f"{source}: sync_index {i} but the input has only "
                                        f"{rows.size} SYNC edges")
        if not complete[i]:
            raise CalibrationInputError(f"{source}: sync_index {i} is the edge the input "
                                        "starts in (its instant was not seen)")
    return rows[fixes.sync_index]


@dataclass
class BiasEstimate:
    """ΔSR (m), ΔEL, ΔAZ (deg) with their covariance, added to the readings."""

    dsr_m: float
    del_deg: float
    daz_deg: float
    covariance: np.ndarray          #: 3×3 in (m, deg, deg)
    fixes_used: int
    chi2: float                     #: weighted residual sum of squares, 3(n−1) degrees of freedom
    residuals: list[dict[str, float]] = field(default_factory=list)

    @property
    def sigma(self) -> tuple[float, float, float]:
        d = np.sqrt(np.diag(self.covariance))
        return float(d[0]), float(d[1]), float(d[2])

    def statistics(self, base: Any = None) -> dict[str, Any]:
        """The ``statistics`` of a calibration set: each bias ``{"estimate", "sigma"}``
        (``base``'s biases added: the totals to decode with) and the method."""
        b = (base.dsr_m, base.del_deg, base.daz_deg) if base is not None else (0.0, 0.0, 0.0)
        out: dict[str, Any] = {
            k: {"estimate": v + b0, "sigma": s} for k, v, b0, s in zip(
                ("dsr_m", "del_deg", "daz_deg"), (self.dsr_m, self.del_deg, self.daz_deg),
                b, self.sigma, strict=True)}
        out.update({"method": METHOD, "fixes": self.fixes_used, "chi2": self.chi2,
                    "chi2_dof": 3 * (self.fixes_used - 1),
                    "relative_to_calibration": base.id if base is not None else "none",
                    "correlation": np.round(_correlation(self.covariance), 4).tolist()})
        return out


def _correlation(c: np.ndarray) -> np.ndarray:
    d = np.sqrt(np.diag(c))
    return c / np.outer(d, d)


def estimate_bias(fixes: Fixes, state: np.ndarray, cov: np.ndarray) -> BiasEstimate:
    """GLS bias from the fixes and the radar-only smoothed track at their rows.

    ``state`` (m, 6) smoothed states at the fix rows, ``cov`` (m, 9) their 1σ and
    position cross-covariances (the tracker's columns).
    """
    ok = np.isfinite(state[:, 0])
    if ok.sum() < 2:
        raise CalibrationError(f"bias estimation needs at least 2 fixes on the track, got "
                               f"{int(ok.sum())}")
    info = np.zeros((3, 3))
    rhs = np.zeros(3)
    diffs, weights = [], []
    for k in np.flatnonzero(ok):
        p = state[k, :3]
        c = cov[k].astype(np.float64)
        C = np.array([[c[0] ** 2, c[6], c[7]], [c[6], c[1] ** 2, c[8]], [c[7], c[8], c[2] ** 2]])
        C += np.diag(fixes.sigma_m[k] ** 2)
        J = _sea_jacobian(p)
        d = _sea(fixes.xyh_m[k]) - _sea(p)
        d[2] = (d[2] + math.pi) % (2 * math.pi) - math.pi
        W = np.linalg.inv(J @ C @ J.T)
        info += W
        rhs += W @ d
        diffs.append(d)
        weights.append(W)
    cov_b = np.linalg.inv(info)
    b = cov_b @ rhs
    chi2 = float(sum((d - b) @ W @ (d - b) for d, W in zip(diffs, weights, strict=True)))
    scale = np.array([1.0, math.degrees(1.0), math.degrees(1.0)])
    residuals = [{"dsr_m": float(r[0]), "del_deg": math.degrees(r[1]),
                  "daz_deg": math.degrees(r[2])} for r in (d - b for d in diffs)]
    return BiasEstimate(float(b[0] * scale[0]), float(b[1] * scale[1]), float(b[2] * scale[2]),
                        cov_b * np.outer(scale, scale), int(ok.sum()), chi2, residuals)


def _sea(p: np.ndarray) -> np.ndarray:
    """SR (m), EL, AZ (rad) of a radar-frame point (X north, Y east, H up)."""
    g = math.hypot(p[0], p[1])
    return np.array([math.sqrt(g * g + p[2] ** 2), math.atan2(p[2], g), math.atan2(p[1], p[0])])


def _sea_jacobian(p: np.ndarray) -> np.ndarray:
    x, y, h = p
    g2 = x * x + y * y
    g = math.sqrt(g2)
    r2 = g2 + h * h
    r = math.sqrt(r2)
    return np.array([[x / r, y / r, h / r],
                     [-h * x / (r2 * g), -h * y / (r2 * g), g / r2],
                     [-y / g2, x / g2, 0.0]])


@dataclass
class PressureAltitude:
    """Air-data pressure altitude aligned to the radar frames (``radar-io align``'s clock fit)."""

    rows: np.ndarray        #: nearest radar frame of each sample
    pa_m: np.ndarray        #: pressure altitude (m)
    clock_offset_s: float
    clock_drift_ppm: float
    matched_events: int
    offset_m: float = math.nan   #: PA − (radar H + earth curvature), estimated
    offset_sigma_m: float = math.nan


def align_pressure_altitude(log: Any, t_s: np.ndarray, sync: np.ndarray,
                            source: str = "air data") -> PressureAltitude:
    """Fit the aircraft clock to the radar's SYNC edges and place each 8 Hz pressure-altitude
    sample at its nearest radar frame (within 1.5 frame periods)."""
    from radar_io.analysis.clock_alignment import fit_clock, shutter_instants
    from radar_io.simulation.aircraft import FT_M

    edge, period = shutter_instants(t_s, sync)
    fit = fit_clock(edge, log.event_time_s, log.event_count, frame_period_s=period)
    s = log.samples
    ok = np.isfinite(s["time_s"]) & np.isfinite(s["pressure_altitude_ft"])
    t_pa = fit.to_radar(s["time_s"][ok])
    j = np.clip(np.searchsorted(t_s, t_pa), 1, max(t_s.size - 1, 1))
    j -= (t_pa - t_s[j - 1]) < (t_s[j] - t_pa)
    near = np.abs(t_s[j] - t_pa) <= 1.5 * period
    if not near.any():
        raise AirborneError(f"{source}: no pressure-altitude sample falls inside the radar data")
    return PressureAltitude(j[near].astype(np.int64), s["pressure_altitude_ft"][ok][near] * FT_M,
                            fit.offset_s, fit.drift_ppm, int(fit.radar_index.size))


def pressure_altitude_heights(pa: PressureAltitude, state: np.ndarray, cov: np.ndarray,
                              sigma_pa_m: float) -> np.ndarray:
    """Estimate the constant offset PA − (H + curvature) against the radar track at the
    samples (``state`` / ``cov`` rows per sample; sets ``pa.offset_m`` and its σ) and return
    the radar-frame height each sample measures: PA − curvature − offset (NaN off the track)."""
    from radar_io.simulation.aircraft import altitude_msl_m

    x, y, h = state[:, 0], state[:, 1], state[:, 2]
    curvature = altitude_msl_m(x, y, h, 0.0) - h
    d = pa.pa_m - curvature - h
    ok = np.isfinite(d)
    if not ok.any():
        raise AirborneError("no pressure-altitude sample falls on the radar track")
    w = 1.0 / (sigma_pa_m ** 2 + cov[ok, 2].astype(np.float64) ** 2)
    pa.offset_m = float(np.sum(w * d[ok]) / np.sum(w))
    pa.offset_sigma_m = float(1.0 / math.sqrt(np.sum(w)))
    return np.asarray(pa.pa_m - curvature - pa.offset_m)
