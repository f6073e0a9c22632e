"""Atmospheric refraction correction of film coordinates (calibration.md §5, eq. 3-24)."""

from __future__ import annotations

import numpy as np

from radar_io.errors import CalibrationError

#: height differences (km) over which the source's empirical δ is used; δ turns negative beyond ≈ 3.16 km
MAX_HEIGHT_DIFFERENCE_KM = 3.0


def refraction_delta(aircraft_height_m: float, ground_height_m: np.ndarray | float) -> np.ndarray:
    """δ(H_a, H_i) = (1 − 0.06 H_i){1.2 (H_a − H_i) − 0.38 (H_a − H_i)²}·10⁻³, heights in km (given in m).

    Heights are above mean sea level.  Raises unless 0 < H_a − H_i ≤ 3 km.
    """
    ha = float(aircraft_height_m) / 1000.0
    hi = np.asarray(ground_height_m, dtype=float) / 1000.0
    dh = ha - hi
    if not (np.isfinite(ha) and np.all(np.isfinite(hi))):
        raise CalibrationError("refraction: heights must be finite")
    if np.any(dh <= 0) or np.any(dh > MAX_HEIGHT_DIFFERENCE_KM):
        raise CalibrationError(
            "refraction: the aircraft must be above every ground point by at most "
            f"{MAX_HEIGHT_DIFFERENCE_KM:g} km (range of the source's formula 3-24); "
            f"got H_a = {aircraft_height_m} m, ground heights {np.min(hi) * 1000:g} … {np.max(hi) * 1000:g} m"
        )
    return (1.0 - 0.06 * hi) * (1.2 * dh - 0.38 * dh**2) * 1e-3


def refraction_displacement_mm(r_mm: np.ndarray, focal_mm: float, delta: np.ndarray | float) -> np.ndarray:
    """Outward radial displacement dr = r (r²/F² + 1) δ (mm) at radial distance r from the principal point."""
    r = np.asarray(r_mm, dtype=float)
    return r * (r**2 / focal_mm**2 + 1.0) * delta


def correct_refraction(
    film_mm: np.ndarray, focal_mm: float, aircraft_height_m: float, ground_height_m: np.ndarray | float
) -> np.ndarray:
    """Film coordinates (N, 2) mm moved inward by dr towards the principal point (one δ per point)."""
    film = np.asarray(film_mm, dtype=float)
    delta = np.broadcast_to(refraction_delta(aircraft_height_m, ground_height_m), film.shape[:1])
    r2 = np.sum(film**2, axis=1)
    # P·(1 − dr/r) with dr/r = (r²/F² + 1) δ
    return film * (1.0 - (r2 / focal_mm**2 + 1.0) * delta)[:, None]
