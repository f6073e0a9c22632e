"""Radar bias from photo-derived positions (calibration.md §8, eqs. 3-26 … 3-28).

Differences are photo − radar, so the corrected radar is ``SR^ = SR' + ΔSR``
(radar-interface.md §4 step 3); the radar readings must be the servo-lag
compensated values SR', EL', AZ' (before any calibration bias).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from radar_io.decoding.biases import Calibration, utc_now_iso
from radar_io.errors import CalibrationError

KEYS = ("dsr_m", "del_deg", "daz_deg")


def photo_to_radar(
    x_m: np.ndarray, y_m: np.ndarray, z_m: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """SR (m), EL (deg), AZ (deg, [0, 360)) of photo positions (X north, Y east, Z down; H = −Z)."""
    x, y, h = np.asarray(x_m, float), np.asarray(y_m, float), -np.asarray(z_m, float)
    sr = np.sqrt(x**2 + y**2 + h**2)
    if np.any(sr == 0):
        raise CalibrationError("a photo position coincides with the radar (SR = 0)")
    el = np.degrees(np.arcsin(h / sr))
    az = np.mod(np.degrees(np.arctan2(y, x)), 360.0)
    return sr, el, np.where(az >= 360.0, 0.0, az)


def wrap_deg(d: np.ndarray) -> np.ndarray:
    """Angle differences (deg) wrapped to (−180, 180]."""
    return 180.0 - np.mod(180.0 - np.asarray(d, dtype=float), 360.0)


def _stat(d: np.ndarray) -> dict[str, float]:
    return {"mean": float(np.mean(d)), "std": float(np.std(d))}


def bias_statistics(
    groups: Sequence[str],
    photo: Sequence[np.ndarray],
    radar: Sequence[np.ndarray],
) -> dict[str, Any]:
    """Per-group and combined ΔSR, ΔEL, ΔAZ (photo − radar; m, deg, deg).

    ``photo`` and ``radar`` are (SR, EL, AZ) arrays.  Per group: N, mean and
    population std; combined: N = total, mean of the group means and mean of
    the group stds (the source's definition).  Groups keep first-seen order.
    """
    if len(photo) != 3 or len(radar) != 3:
        raise CalibrationError("bias: photo and radar must each be three arrays (SR, EL, AZ)")
    g = np.asarray(list(groups), dtype=object)
    p = [np.asarray(v, dtype=float) for v in photo]
    r = [np.asarray(v, dtype=float) for v in radar]
    n = len(g)
    if n == 0:
        raise CalibrationError("bias: no photo/radar pairs")
    if any(v.shape != (n,) for v in (*p, *r)):
        raise CalibrationError("bias: groups, photo and radar arrays must have the same length")
    if not all(np.all(np.isfinite(v)) for v in (*p, *r)):
        raise CalibrationError("bias: non-finite photo or radar value")
    diffs = np.column_stack([p[0] - r[0], p[1] - r[1], wrap_deg(p[2] - r[2])])
    out: dict[str, Any] = {"groups": {}}
    for name in dict.fromkeys(g.tolist()):
        d = diffs[g == name]
        out["groups"][str(name)] = {"n": len(d), **{k: _stat(d[:, i]) for i, k in enumerate(KEYS)}}
    stats = list(out["groups"].values())
    out["combined"] = {
        "n": n,
        **{k: {"mean": float(np.mean([s[k]["mean"] for s in stats])),
               "std": float(np.mean([s[k]["std"] for s in stats]))} for k in KEYS},
    }
    return out


def bias_calibration(stats: dict[str, Any], *, cal_id: str, provenance: dict[str, Any]) -> Calibration:
    """The calibration set of a :func:`bias_statistics` result (biases = combined means)."""
    c = stats["combined"]
    return Calibration(
        dsr_m=c["dsr_m"]["mean"],
        del_deg=c["del_deg"]["mean"],
        daz_deg=c["daz_deg"]["mean"],
        id=cal_id,
        created_utc=utc_now_iso(),
        statistics=stats,
        provenance=provenance,
    )
