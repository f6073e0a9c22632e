"""The flight report's best-estimate-of-trajectory (BET) page, in bounded memory.

A second pass over the recording (as the air-data page does) keeps every ``stride``-th
frame's measurement (``stride`` chosen from the frame count so that at most
:data:`MAX_ROWS` are kept: a 1-h, 1 kHz recording keeps every 60th frame, ~1 MB), and the
tracker's EKF + RTS smoother (:func:`~radar_io.tracking.tracker.track_batch`) runs over
that decimated set with the site's σ. Its σ are therefore those of the decimated
measurements (√stride larger than a full-rate smoother's, roughly); the shapes, NIS and
outliers are the same kind. Figures: the smoothed height, ground speed and vertical speed
with ±3σ bands; the measurement residuals (SR, EL, AZ minus the smoothed track's) with the
measurement's ±3σ; NIS over time with the χ²₃ bounds and the gate. Tables: the
parameters and results (biases of the calibration in use, with σ when the set carries
them), and the outliers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from radar_io.analysis.flight_digest import FlightDigest

#: measurements kept for the smoother (every stride-th frame)
MAX_ROWS = 60_000
#: χ² with 3 degrees of freedom: 95 % and 99.73 % (3σ) points
CHI2_95, CHI2_3SIGMA = 7.815, 14.16
#: outliers listed in the table (all are counted)
MAX_OUTLIER_ROWS = 50
_INPUT = ("seq", "tod_s", "sr_c_m", "el_c_deg", "az_c_deg", "rx_good")


@dataclass
class BetPage:
    """What the page shows: decimation, parameters, results, figures' data."""

    stride: int
    params: Any
    summary: dict[str, Any]
    t_s: np.ndarray
    track: Any  #: the smoothed MeasurementBatch (decimated rows)
    residuals: dict[str, np.ndarray]  #: sr_m, el_deg, az_deg: measured − smoothed
    outliers: list[tuple[float, int, float]] = field(default_factory=list)  #: t_s, SEQ, NIS


def build_bet(d: FlightDigest, max_rows: int = MAX_ROWS) -> BetPage | None:
    """Decimate, smooth and reduce; None when the recording has no good measurement."""
    from radar_io.coordinates.transforms import radar_sea
    from radar_io.decoding.batch_decoder import iter_decode
    from radar_io.decoding.measurement import MeasurementBatch
    from radar_io.recording.rdrlog import iter_payloads
    from radar_io.tracking.tracker import TimeBase, TrackParams, TrackSummary, track_batch

    stride = max(1, math.ceil(d.n_frames / max_rows))
    keep: dict[str, list[np.ndarray]] = {c: [] for c in _INPUT}
    seen = 0
    for batch in iter_decode(iter_payloads(d.source), **d.decode_options):
        n = len(batch)
        if not n:
            continue
        rows = np.arange((-seen) % stride, n, stride)
        seen += n
        for c in _INPUT:
            keep[c].append(np.asarray(batch[c])[rows])
    cols = {c: np.concatenate(v) if v else np.empty(0) for c, v in keep.items()}
    if not np.any(cols["rx_good"] != 0):
        return None
    params = TrackParams.for_site(d.site)
    summary = TrackSummary()
    trk = track_batch(MeasurementBatch(cols), params, summary=summary)
    t = TimeBase()(cols["tod_s"])
    t_s = t - t[0]
    sr, el, az = radar_sea(trk["x_m"], trk["y_m"], trk["h_m"])
    good = cols["rx_good"] != 0
    res = {"sr_m": np.where(good, cols["sr_c_m"] - sr, np.nan),
           "el_deg": np.where(good, cols["el_c_deg"] - el, np.nan),
           "az_deg": np.where(good, (cols["az_c_deg"] - az + 180.0) % 360.0 - 180.0, np.nan)}
    out = np.flatnonzero(np.asarray(trk["outlier"]) != 0)
    outliers = [(float(t_s[i]), int(cols["seq"][i]), float(trk["nis"][i]))
                for i in out[:MAX_OUTLIER_ROWS]]
    info = {"stride": stride, "rows": len(trk), **summary.metadata()}
    for k, v in res.items():
        v = v[good & (np.asarray(trk["outlier"]) == 0)]
        v = v[np.isfinite(v)]
        info[f"residual_{k}_rms"] = float(np.sqrt(np.mean(v * v))) if v.size else math.nan
    return BetPage(stride, params, info, t_s, trk, res, outliers)


def figures(p: BetPage) -> list[tuple[str, Any]]:
    """(title, matplotlib Figure) of the page."""
    from radar_io.analysis.flight_digest import decimate_index
    from radar_io.analysis.report import _plt

    plt = _plt()
    i = decimate_index(p.t_s.size, 6000)
    t, k = p.t_s[i], p.track
    gs = np.asarray(k["gs_mps"])[i]
    vx, vy = np.asarray(k["vx_mps"])[i], np.asarray(k["vy_mps"])[i]
    sx, sy = (np.asarray(k[c], dtype=float)[i] for c in ("vx_sigma_mps", "vy_sigma_mps"))
    with np.errstate(invalid="ignore", divide="ignore"):
        gs_sigma = np.sqrt((vx * vx * sx * sx + vy * vy * sy * sy) / (gs * gs))
    fig1, ax = plt.subplots(3, 1, figsize=(10, 8), sharex=True)
    for a, (v, s, label) in zip(ax, (
            (np.asarray(k["h_m"])[i], np.asarray(k["h_sigma_m"], dtype=float)[i], "H [m]"),
            (gs, gs_sigma, "ground speed [m/s]"),
            (np.asarray(k["vs_mps"])[i], np.asarray(k["vh_sigma_mps"], dtype=float)[i],
             "vertical speed [m/s]")), strict=True):
        a.fill_between(t, v - 3 * s, v + 3 * s, color="tab:blue", alpha=0.25, lw=0,
                       label="±3σ")
        a.plot(t, v, lw=0.8, color="tab:blue", label="smoothed")
        a.set_ylabel(label)
        a.grid(alpha=0.3)
    ax[0].legend(fontsize=8, loc="best")
    ax[0].set_title(f"Best estimate of trajectory (RTS smoother, 1 frame in {p.stride}): "
                    "±3σ bands")
    ax[-1].set_xlabel("time from first frame [s]")
    fig1.tight_layout()

    prm = p.params
    out = np.asarray(k["outlier"])[i] != 0
    fig2, ax2 = plt.subplots(3, 1, figsize=(10, 7), sharex=True)
    for a, (c, sig, label) in zip(ax2, (("sr_m", prm.sigma_range_m, "SR [m]"),
                                        ("el_deg", prm.sigma_angle_deg, "EL [deg]"),
                                        ("az_deg", prm.sigma_angle_deg, "AZ [deg]")),
                                    strict=True):
        r = p.residuals[c][i]
        a.plot(t[~out], r[~out], ".", ms=1.5, color="tab:blue", rasterized=True)
        if out.any():
            a.plot(t[out], r[out], "x", ms=5, color="tab:red", label="outlier")
        for s in (-3 * sig, 3 * sig):
            a.axhline(s, color="tab:red", lw=0.8, ls="--")
        a.set_ylabel(f"{label} − smoothed")
        a.grid(alpha=0.3)
    ax2[0].set_title("Measurement residuals against the smoothed track, with the measurement "
                     "noise's ±3σ")
    ax2[-1].set_xlabel("time from first frame [s]")
    fig2.tight_layout()

    nis = np.asarray(k["nis"])
    fig3, a3 = plt.subplots(figsize=(10, 4))
    ok = np.isfinite(nis[i]) & ~out
    a3.semilogy(t[ok], nis[i][ok], ".", ms=1.5, color="tab:blue", rasterized=True,
                label="NIS (used)")
    if out.any():
        a3.semilogy(t[out], nis[i][out], "x", ms=5, color="tab:red", label="outlier (not used)")
    for v, ls, lab in ((CHI2_95, ":", "χ²₃ 95 %"), (CHI2_3SIGMA, "--", "χ²₃ 99.73 %"),
                       (prm.gate_nis, "-", "gate")):
        a3.axhline(v, color="k", lw=0.8, ls=ls, label=lab)
    a3.set_xlabel("time from first frame [s]")
    a3.set_ylabel("NIS")
    a3.set_title("Normalised innovation squared over time")
    a3.grid(alpha=0.3, which="both")
    a3.legend(fontsize=8, loc="upper right")
    return [("BET: smoothed track with ±3σ", fig1),
            ("BET: residuals with ±3σ", fig2), ("BET: NIS over time", fig3)]


def summary_rows(p: BetPage, calibration: Any = None) -> list[tuple[str, ...]]:
    """The page's table: decimation, model, results, the biases in use."""
    s, prm = p.summary, p.params
    rows: list[tuple[str, ...]] = [
            ("measurements smoothed", f"{s['rows']} (1 frame in {p.stride})"),
            ("model", f"CV, q {prm.q_mps2:g} m²/s³, σ range {prm.sigma_range_m:g} m, "
                      f"σ angle {prm.sigma_angle_deg:g}°, gate NIS {prm.gate_nis:g}"),
            ("tracks", s["tracking.tracks"]),
            ("outliers (not used)", s["tracking.outliers"]),
            ("NIS mean (3 expected)", s["tracking.nis_mean"]),
            ("NIS within χ²₃ 95 %", s["tracking.nis_within_chi2_95"]),
            ("residual RMS SR / EL / AZ", f"{s['residual_sr_m_rms']:.3g} m / "
             f"{s['residual_el_deg_rms']:.3g}° / {s['residual_az_deg_rms']:.3g}°")]
    if calibration is not None:
        st = getattr(calibration, "statistics", {}) or {}

        def pm(key: str, v: float, unit: str) -> str:
            e = st.get(key)
            sd = e.get("sigma") if isinstance(e, dict) else None
            return f"{v:+.4g}{unit}" + (f" ± {sd:.2g}{unit}" if sd is not None else "")

        rows.append((f"biases applied (calibration {calibration.id})",
                     f"ΔSR {pm('dsr_m', calibration.dsr_m, ' m')}, "
                     f"ΔEL {pm('del_deg', calibration.del_deg, '°')}, "
                     f"ΔAZ {pm('daz_deg', calibration.daz_deg, '°')}"))
    return rows


OUTLIER_HEAD = ("t [s]", "SEQ", "NIS")


def outlier_rows(p: BetPage) -> list[tuple[str, ...]]:
    return [(f"{t:.3f}", str(seq), f"{nis:.1f}") for t, seq, nis in p.outliers]
