"""Best estimate of trajectory: EKF + RTS smoother over decoded radar measurements.

:func:`track_batch` tracks one :class:`MeasurementBatch`; :func:`iter_track` streams the
batches of :func:`~radar_io.decoding.batch_decoder.iter_decode` (forward filter: row
batches as they come; smoother: after the last batch). Models and equations:
docs/tracking.md.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from radar_io.decoding.measurement import MeasurementBatch
from radar_io.errors import ConfigError

#: TR-861 table 2-1: range noise, 5 m rms
SPEC_SIGMA_RANGE_M = 5.0
#: TR-861 table 2-1: angle noise, 0.2 mil rms (6400 mil to the circle)
SPEC_SIGMA_ANGLE_DEG = 0.2 * 360.0 / 6400.0

#: the output columns, in order (one row per input frame)
TRACK_COLUMNS: tuple[str, ...] = (
    "seq", "tod_s", "x_m", "y_m", "h_m", "vx_mps", "vy_mps", "vh_mps",
    "x_sigma_m", "y_sigma_m", "h_sigma_m", "vx_sigma_mps", "vy_sigma_mps", "vh_sigma_mps",
    "cov_xy_m2", "cov_xh_m2", "cov_yh_m2", "gs_mps", "vs_mps", "track_deg", "fpa_deg",
    "nis", "outlier")
#: the decoded columns the tracker reads
INPUT_COLUMNS = ("seq", "tod_s", "sr_c_m", "el_c_deg", "az_c_deg", "rx_good")
MODELS = ("cv",)
#: rows per block of the smoother's second pass (memory: 6×6 float64 per row)
BLOCK = 1 << 16
_DAY_S = 86400.0


@dataclass(frozen=True)
class TrackParams:
    """Filter settings: CV model noise, measurement σ, gate and track limits.

    ``q_mps2``: spectral density of the white acceleration noise per axis (m²/s³);
    ``gate_nis``: a measurement whose normalised innovation squared exceeds this is an
    outlier (χ², 3 degrees of freedom: 30 ≈ 1.4·10⁻⁶ false alarms); ``max_gap_s``: with
    no measurement used for longer, the track ends and restarts at the next good one;
    ``v0_sigma_mps``: σ of each velocity component when a track starts; ``sigma_pa_m``: σ
    of an air-data pressure-altitude sample used as a height measurement.
    """

    q_mps2: float = 0.5
    sigma_range_m: float = SPEC_SIGMA_RANGE_M
    sigma_angle_deg: float = SPEC_SIGMA_ANGLE_DEG
    gate_nis: float = 30.0
    max_gap_s: float = 5.0
    v0_sigma_mps: float = 300.0
    sigma_pa_m: float = 3.0
    model: str = "cv"

    def __post_init__(self) -> None:
        for name in ("q_mps2", "sigma_range_m", "sigma_angle_deg", "gate_nis", "max_gap_s",
                     "v0_sigma_mps", "sigma_pa_m"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ConfigError(f"tracking parameter {name} must be a positive number, got {v!r}")
        if self.model not in MODELS:
            raise ConfigError(f"tracking model {self.model!r} unknown (known: {', '.join(MODELS)})")

    @classmethod
    def for_site(cls, site: Any = None, **overrides: Any) -> TrackParams:
        """Parameters with σ from the site file where it gives them, else the specification;
        ``overrides`` that are not None win."""
        base: dict[str, Any] = {}
        if site is not None:
            if getattr(site, "sigma_range_m", None) is not None:
                base["sigma_range_m"] = site.sigma_range_m
            if getattr(site, "sigma_angle_deg", None) is not None:
                base["sigma_angle_deg"] = site.sigma_angle_deg
        base.update({k: v for k, v in overrides.items() if v is not None})
        return cls(**base)

    def vector(self) -> np.ndarray:
        """The kernels' parameter vector [q, σ_range, σ_angle (rad), gate, max gap, v0 var]."""
        return np.array([self.q_mps2, self.sigma_range_m, math.radians(self.sigma_angle_deg),
                         self.gate_nis, self.max_gap_s, self.v0_sigma_mps ** 2])


class TimeBase:
    """Unwraps TOD across midnight, across batches: seconds since the first day's midnight."""

    def __init__(self) -> None:
        self._last: float | None = None
        self._day = 0.0

    def __call__(self, tod_s: np.ndarray) -> np.ndarray:
        tod = np.asarray(tod_s, dtype=np.float64)
        if not tod.size:
            return tod.copy()
        prev = tod[0] if self._last is None else self._last
        wraps = np.cumsum(np.diff(tod, prepend=prev) < -_DAY_S / 2)
        t = tod + (self._day + wraps * _DAY_S)
        self._day += float(wraps[-1]) * _DAY_S
        self._last = float(tod[-1])
        return t


@dataclass
class TrackSummary:
    """What a run found: counts and NIS statistics (file metadata, the CLI's last line)."""

    rows: int = 0
    measurements: int = 0
    used: int = 0
    outliers: int = 0
    tracks: int = 0
    time_errors: int = 0
    nis_sum: float = 0.0
    nis_in_95: int = 0  #: NIS below χ²₃(0.95) = 7.815
    fixes_used: int = 0  #: photo fixes and pressure-altitude samples applied
    bias: Any = None    #: a :class:`~radar_io.tracking.fusion.BiasEstimate` with estimate_bias
    pressure_altitude: Any = None  #: a :class:`~radar_io.tracking.fusion.PressureAltitude`

    def add(self, nis: np.ndarray, flags: np.ndarray, good: np.ndarray) -> None:
        from radar_io.tracking import kernels as K

        self.rows += int(flags.size)
        self.measurements += int(np.count_nonzero(good))
        self.used += int(np.count_nonzero(flags & K.UPDATED))
        self.outliers += int(np.count_nonzero(flags & K.OUTLIER))
        v = nis[np.isfinite(nis) & ((flags & K.UPDATED) != 0)]
        self.nis_sum += float(v.sum())
        self.nis_in_95 += int(np.count_nonzero(v <= 7.815))

    def metadata(self) -> dict[str, str]:
        n = max(self.used - self.tracks, 1)  # the first sample of a track has no NIS
        meta = {"tracking.rows": str(self.rows), "tracking.measurements": str(self.measurements),
                "tracking.used": str(self.used), "tracking.outliers": str(self.outliers),
                "tracking.tracks": str(self.tracks), "tracking.time_errors": str(self.time_errors),
                "tracking.nis_mean": f"{self.nis_sum / n:.4f}",
                "tracking.nis_within_chi2_95": f"{self.nis_in_95 / n:.4f}",
                "tracking.fixes_used": str(self.fixes_used)}
        if self.bias is not None:
            b = self.bias
            for k, v, sd in zip(("dsr_m", "del_deg", "daz_deg"), (b.dsr_m, b.del_deg, b.daz_deg),
                                b.sigma, strict=True):
                meta[f"tracking.bias_{k}"] = f"{v:.6g} ± {sd:.3g}"
        pa = self.pressure_altitude
        if pa is not None:
            meta["tracking.pa_offset_m"] = f"{pa.offset_m:.4g} ± {pa.offset_sigma_m:.2g}"
            meta["tracking.pa_samples"] = str(pa.rows.size)
            meta["tracking.pa_clock_offset_s"] = f"{pa.clock_offset_s:.6f}"
            meta["tracking.pa_clock_drift_ppm"] = f"{pa.clock_drift_ppm:.3f}"
            meta["tracking.pa_matched_shutter_events"] = str(pa.matched_events)
        return meta


def params_metadata(params: TrackParams, smoothed: bool) -> dict[str, str]:
    meta = {f"tracking.{k}": str(v) for k, v in asdict(params).items()}
    meta["tracking.estimate"] = "rts_smoothed" if smoothed else "forward_filtered"
    return meta


def _measurements(cols: Any, t: np.ndarray) -> tuple[np.ndarray, ...]:
    missing = [c for c in INPUT_COLUMNS if c not in cols]
    if missing:
        raise ConfigError(f"tracking needs decoded column(s) {', '.join(missing)}")
    sr = np.asarray(cols["sr_c_m"], dtype=np.float64)
    el = np.deg2rad(np.asarray(cols["el_c_deg"], dtype=np.float64))
    az = np.deg2rad(np.asarray(cols["az_c_deg"], dtype=np.float64))
    good = ((np.asarray(cols["rx_good"]) != 0) & np.isfinite(sr) & np.isfinite(el)
            & np.isfinite(az) & (sr > 0)).astype(np.uint8)
    return t, sr, el, az, good


def _output(seq: np.ndarray, tod: np.ndarray, state: np.ndarray, cov: np.ndarray,
            nis: np.ndarray, flags: np.ndarray, site: Any, path: Any,
            stats: dict[str, int]) -> MeasurementBatch:
    from radar_io.tracking import kernels as K

    vx, vy, vh = state[:, 3], state[:, 4], state[:, 5]
    gs = np.hypot(vx, vy)
    cols: dict[str, np.ndarray] = {
        "seq": seq, "tod_s": np.asarray(tod, dtype=np.float64),
        "x_m": state[:, 0], "y_m": state[:, 1], "h_m": state[:, 2],
        "vx_mps": vx, "vy_mps": vy, "vh_mps": vh}
    for i, c in enumerate(TRACK_COLUMNS[8:17]):  # float32: σ to 7 digits, half the memory
        cols[c] = np.ascontiguousarray(cov[:, i], dtype=np.float32)
    cols["gs_mps"] = gs
    cols["vs_mps"] = vh
    cols["track_deg"] = np.mod(np.degrees(np.arctan2(vy, vx)), 360.0)
    cols["fpa_deg"] = np.degrees(np.arctan2(vh, gs))
    cols["nis"] = nis
    cols["outlier"] = ((flags & K.OUTLIER) != 0).astype(np.uint8)
    order = list(TRACK_COLUMNS)
    if site is not None:
        from radar_io.coordinates.transforms import geodetic, radar_sea, runway_xyh

        sr, el, az = radar_sea(state[:, 0], state[:, 1], state[:, 2])
        for c, v in zip(("xr_m", "yr_m", "hr_m"), runway_xyh(sr, el, az, site), strict=True):
            cols[c] = np.asarray(v)
        for c, v in zip(("lat_deg", "lon_deg", "hae_m"), geodetic(sr, el, az, site), strict=True):
            cols[c] = np.asarray(v)
        order += ["xr_m", "yr_m", "hr_m", "lat_deg", "lon_deg", "hae_m"]
    batch = MeasurementBatch(cols, stats, order)
    if path is not None:
        from radar_io.coordinates.reference_path import add_deviation

        batch = add_deviation(batch, path)
    return batch


class _Forward:
    """The forward filter's state carried across batches."""

    def __init__(self, params: TrackParams) -> None:
        from radar_io.tracking import kernels as K

        self.K = K
        self.params = params
        self.vec = params.vector()
        self.x = np.zeros(6)
        self.P = np.zeros((6, 6))
        self.carry = np.zeros(K.CARRY_LEN)
        self.none_x = np.empty((0, 6))
        self.none_P = np.empty((0, 6, 6))
        self.fix_rows = np.empty(0, dtype=np.int64)
        self.fixes = np.empty((0, 6))

    def run(self, m: tuple[np.ndarray, ...], i0: int, i1: int, nis: np.ndarray,
            flags: np.ndarray, out_x: np.ndarray | None = None,
            out_P: np.ndarray | None = None) -> None:
        self.K.forward(*m, i0, i1, self.x, self.P, self.carry, self.vec, nis, flags,
                       self.none_x if out_x is None else out_x,
                       self.none_P if out_P is None else out_P, self.fix_rows, self.fixes)

    def checkpoint(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self.x.copy(), self.P.copy(), self.carry.copy()

    def restore(self, cp: tuple[np.ndarray, np.ndarray, np.ndarray]) -> None:
        self.x[:], self.P[:], self.carry[:] = cp


def iter_track(batches: Iterable[MeasurementBatch], params: TrackParams | None = None, *,
               smooth: bool = True, site: Any = None, path: Any = None,
               summary: TrackSummary | None = None, block_rows: int = BLOCK,
               fixes: Any = None, estimate_bias: bool = False, airdata: Any = None
               ) -> Iterator[MeasurementBatch]:
    """Track decoded batches (in time order); yields batches of :data:`TRACK_COLUMNS`.

    ``smooth=False``: the forward filter, one output batch per input batch as it comes
    (live use). ``smooth=True``: keeps the measurement columns of every row, filters,
    smooths backwards block by block (the block's filtered covariances are recomputed from
    a checkpoint, so memory is ~140 B/row in all, not 6×6 float64 per row) and yields the
    result in blocks of ``block_rows`` rows. ``summary`` collects counts and NIS statistics.

    ``fixes`` (:class:`~radar_io.tracking.fusion.Fixes`, smoother only): photo positions
    at SYNC edges, fused as position measurements. ``estimate_bias``: first the radar-only
    track gives ΔSR, ΔEL, ΔAZ against the fixes (``summary.bias``); the measurements are
    then corrected by it and tracked with the fixes fused. ``airdata``
    (:class:`~radar_io.decoding.airdata.AircraftLog`, smoother only): the aircraft clock is
    fitted to the SYNC edges, the offset of pressure altitude from the radar height (plus
    earth curvature) is estimated against the radar track, and each sample then measures
    the height with σ ``params.sigma_pa_m``.
    """
    params = params or TrackParams()
    summary = summary if summary is not None else TrackSummary()
    fwd = _Forward(params)
    tb = TimeBase()
    stats: dict[str, int] = {}
    if (fixes is not None or estimate_bias or airdata is not None) and not smooth:
        raise ConfigError("photo fixes, air data and bias estimation need the smoother "
                          "(not forward-only)")
    if estimate_bias and fixes is None:
        raise ConfigError("bias estimation needs photo fixes")
    if not smooth:
        for b in batches:
            stats = b.stats
            m = _measurements(b, tb(b["tod_s"]))
            n = len(m[0])
            nis, flags = np.empty(n), np.empty(n, dtype=np.uint8)
            fx, fP = np.empty((n, 6)), np.empty((n, 6, 6))
            fwd.run(m, 0, n, nis, flags, fx, fP)
            cov = np.empty((n, 9), dtype=np.float32)
            fwd.K.covariance_columns(fP, np.arange(n), cov)
            summary.add(nis, flags, m[4])
            yield _output(b["seq"], b["tod_s"], fx, cov, nis, flags, site, path, stats)
        summary.tracks, summary.time_errors = int(fwd.carry[3]), int(fwd.carry[4])
        return
    fused = fixes is not None or airdata is not None
    names = ("seq", "tod_s", "t", "sr", "el", "az", "good") + (("sync",) if fused else ())
    keep: dict[str, list[np.ndarray]] = {c: [] for c in names}
    for b in batches:
        stats = b.stats
        t, sr, el, az, good = _measurements(b, tb(b["tod_s"]))
        for c, v in (("seq", b["seq"]), ("tod_s", b["tod_s"]), ("t", t), ("sr", sr),
                     ("el", el), ("az", az), ("good", good)):
            keep[c].append(np.array(v, copy=True))
        if fused:
            keep["sync"].append(np.array(b["sync"], copy=True))
    cols = {}
    for c in names:  # one column at a time: the pieces go as their column is made
        parts = keep.pop(c)
        cols[c] = np.concatenate(parts) if parts else np.empty(0)
        del parts
    if fused:
        fwd.fix_rows, fwd.fixes = _position_measurements(cols, params, summary, block_rows,
                                                         fixes, estimate_bias, airdata)
    for batch in smooth_arrays(cols, fwd, summary, block_rows, release=True):
        state, cov, nis, flags, lo, hi = batch
        yield _output(cols["seq"][lo:hi], cols["tod_s"][lo:hi], state, cov, nis, flags,
                      site, path, stats)


def _position_measurements(cols: dict[str, np.ndarray], params: TrackParams,
                           summary: TrackSummary, block_rows: int, fixes: Any,
                           estimate_bias: bool, airdata: Any) -> tuple[np.ndarray, np.ndarray]:
    """Rows (ascending) and [x, y, h, σx, σy, σh] of the photo fixes and pressure-altitude
    heights (σ ∞: that axis is not measured); with ``estimate_bias`` the radar columns in
    ``cols`` are corrected by the estimate first."""
    from radar_io.tracking import fusion

    sync = cols.pop("sync")
    rows_parts, meas_parts = [], []
    if fixes is not None:
        rows = fusion.fix_rows(fixes, sync, fixes.source or "fixes")
        if estimate_bias:
            summary.bias = bias = fusion.estimate_bias(fixes, *_at_rows(cols, params, rows,
                                                                         block_rows))
            cols["sr"] += bias.dsr_m
            cols["el"] += math.radians(bias.del_deg)
            cols["az"] += math.radians(bias.daz_deg)
        rows_parts.append(rows)
        meas_parts.append(np.hstack([fixes.xyh_m, fixes.sigma_m]))
    if airdata is not None:
        pa = fusion.align_pressure_altitude(airdata, cols["t"], sync)
        h = fusion.pressure_altitude_heights(pa, *_at_rows(cols, params, pa.rows, block_rows),
                                             params.sigma_pa_m)
        ok = np.isfinite(h)
        pa.rows, pa.pa_m = pa.rows[ok], pa.pa_m[ok]
        summary.pressure_altitude = pa
        n = int(ok.sum())
        rows_parts.append(pa.rows)
        meas_parts.append(np.column_stack([np.zeros(n), np.zeros(n), h[ok], np.full(n, np.inf),
                                           np.full(n, np.inf), np.full(n, params.sigma_pa_m)]))
    rows = np.concatenate(rows_parts).astype(np.int64)
    order = np.argsort(rows, kind="stable")
    return np.ascontiguousarray(rows[order]), np.ascontiguousarray(np.vstack(meas_parts)[order])


def _at_rows(cols: dict[str, np.ndarray], params: TrackParams, rows: np.ndarray,
             block_rows: int) -> tuple[np.ndarray, np.ndarray]:
    """The radar-only smoothed state and covariance columns at ``rows``."""
    st, cv = np.full((rows.size, 6), np.nan), np.full((rows.size, 9), np.nan)
    for state, cov, _, _, lo, hi in smooth_arrays(cols, _Forward(params), TrackSummary(),
                                                  block_rows):
        sel = (rows >= lo) & (rows < hi)
        st[sel], cv[sel] = state[rows[sel] - lo], cov[rows[sel] - lo]
    return st, cv


def smooth_arrays(cols: dict[str, np.ndarray], fwd: _Forward, summary: TrackSummary,
                  block_rows: int = BLOCK, release: bool = False
                  ) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int, int]]:
    """Filter and RTS-smooth whole columns; yields (state, cov, nis, flags, lo, hi) per block.

    ``release``: drop the measurement columns from ``cols`` once smoothed (before the first
    yield), so their memory is free while the output is written."""
    K = fwd.K
    m: tuple[np.ndarray, ...] = (cols["t"], cols["sr"], cols["el"], cols["az"], cols["good"])
    n = len(m[0])
    nis, flags = np.empty(n), np.empty(n, dtype=np.uint8)
    B = max(1, int(block_rows))
    starts = list(range(0, n, B))
    checkpoints = []
    for lo in starts:  # pass 1: filter, keep the state at each block start
        checkpoints.append(fwd.checkpoint())
        fwd.run(m, lo, min(lo + B, n), nis, flags)
    summary.add(nis, flags, m[4])
    summary.tracks, summary.time_errors = int(fwd.carry[3]), int(fwd.carry[4])
    summary.fixes_used = int(fwd.carry[6])
    state = np.empty((n, 6))
    cov = np.empty((n, 9), dtype=np.float32)
    fx, fP = np.empty((B, 6)), np.empty((B, 6, 6))
    xs, Ps = np.zeros(6), np.zeros((6, 6))
    has_next = False
    for lo, cp in zip(reversed(starts), reversed(checkpoints), strict=True):  # pass 2: refilter, smooth
        hi = min(lo + B, n)
        fwd.restore(cp)
        fwd.run(m, lo, hi, nis, flags, fx[:hi - lo], fP[:hi - lo])
        has_next = bool(K.smooth(m[0], flags, lo, hi, fx, fP, xs, Ps, has_next,
                                 fwd.params.q_mps2, state, cov))
    del fx, fP
    if release:
        m = ()
        for c in ("t", "sr", "el", "az", "good"):
            del cols[c]
    for lo in starts:
        hi = min(lo + B, n)
        yield state[lo:hi], cov[lo:hi], nis[lo:hi], flags[lo:hi], lo, hi


def track_batch(batch: MeasurementBatch, params: TrackParams | None = None, *,
                smooth: bool = True, site: Any = None, path: Any = None,
                summary: TrackSummary | None = None, fixes: Any = None,
                estimate_bias: bool = False, airdata: Any = None) -> MeasurementBatch:
    """Track one decoded batch: one row per input row, :data:`TRACK_COLUMNS` (+ runway,
    geodetic and path deviation with ``site`` / ``path``); ``fixes``, ``estimate_bias`` and
    ``airdata`` as :func:`iter_track`."""
    out = list(iter_track([batch], params, smooth=smooth, site=site, path=path,
                          summary=summary, block_rows=max(len(batch), 1), fixes=fixes,
                          estimate_bias=estimate_bias, airdata=airdata))
    if len(out) == 1:
        return out[0]
    return MeasurementBatch.concat(out) if out else _output(
        np.empty(0, dtype=np.int64), np.empty(0), np.empty((0, 6)), np.empty((0, 9), dtype=np.float32),
        np.empty(0), np.empty(0, dtype=np.uint8), site, path, batch.stats)
