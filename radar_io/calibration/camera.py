"""Camera calibration from targets at known angles (calibration.md §4, eqs. 3-17 … 3-23).

One axis at a time: targets E_0 … E_n on a plane, θ_i the angle from the camera
to E_i measured from the direction of E_0 (positive towards increasing film
coordinate), P'_i the film coordinate (mm) of E_i from the mechanical centre.
The optical axis is off the direction of E_0 by Δθ, so
``P'_i = P_c + F tan(θ_i − Δθ)`` with P_c the principal point.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from radar_io.errors import CalibrationError

SCAN_STEP_DEG = 0.01


@dataclass(frozen=True)
class AxisCalibration:
    """Result for one film axis (mm, deg).

    ``principal_point_mm`` is P_c from the mechanical centre;
    ``ideal_mm`` the ideal coordinates F_nom tan(θ_i − Δθ) from the principal point;
    ``distortion`` (a0, a1, a2, a3) maps measured P' to ideal P (3-22, 3-23).
    """

    delta_theta_deg: float
    focal_mm: float
    focal_std_mm: float
    focal_per_point_mm: np.ndarray
    principal_point_mm: float
    focal_nominal_mm: float
    ideal_mm: np.ndarray
    distortion: np.ndarray
    distortion_residuals_mm: np.ndarray


def _relative_angles(theta_deg: np.ndarray, film_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    theta = np.asarray(theta_deg, dtype=float)
    film = np.asarray(film_mm, dtype=float)
    if theta.ndim != 1 or theta.shape != film.shape:
        raise CalibrationError(
            "camera calibration: angles and film coordinates must be 1-D arrays of equal length")
    if len(theta) < 4:
        raise CalibrationError(
            f"camera calibration needs at least 4 targets per axis (E_0 … E_3), got {len(theta)}")
    if not (np.all(np.isfinite(theta)) and np.all(np.isfinite(film))):
        raise CalibrationError("camera calibration: non-finite angle or film coordinate")
    rel = np.radians(theta - theta[0])
    if np.any(np.abs(rel[1:]) < 1e-9):
        raise CalibrationError("camera calibration: a target other than E_0 lies in the direction of E_0")
    return rel, film


def focal_lengths(
    theta_deg: np.ndarray, film_mm: np.ndarray, delta_theta_deg: np.ndarray | float
) -> np.ndarray:
    """F_i = (P'_i − P'_0)/(tan(θ_i − Δθ) + tan Δθ) for i ≥ 1 (3-19); shape (..., n) for Δθ of shape (...)."""
    rel, film = _relative_angles(theta_deg, film_mm)
    dt = np.radians(np.asarray(delta_theta_deg, dtype=float))[..., None]
    # tan(a − b) + tan b = sin a / (cos(a − b) cos b): no division by a vanishing difference
    return (film[1:] - film[0]) * np.cos(rel[1:] - dt) * np.cos(dt) / np.sin(rel[1:])


def scan_delta_theta(
    theta_deg: np.ndarray, film_mm: np.ndarray, *, range_deg: float = 5.0, step_deg: float = SCAN_STEP_DEG
) -> tuple[float, np.ndarray]:
    """Δθ (deg) on a ``step_deg`` grid within ±``range_deg`` minimising the population std of F_i (3-20).

    Returns (Δθ, F_i at Δθ).  Raises if the minimum lies on the edge of the scan range.
    """
    k = round(range_deg / step_deg)
    if k < 1:
        raise CalibrationError("camera calibration: the scan range must cover at least one step")
    grid = np.arange(-k, k + 1) * step_deg
    f = focal_lengths(theta_deg, film_mm, grid)
    best = int(np.argmin(np.std(f, axis=1)))
    if best in (0, len(grid) - 1):
        raise CalibrationError(
            "camera calibration: the std of F_i is smallest at the edge of the Δθ scan "
            f"(±{range_deg:g} deg); widen the range or check the target angles"
        )
    return round(float(grid[best]), 10), f[best]


def fit_distortion(measured_mm: np.ndarray, ideal_mm: np.ndarray) -> np.ndarray:
    """Least-squares cubic (a0, a1, a2, a3) with ideal ≈ a0 + a1 P' + a2 P'² + a3 P'³ (3-22, 3-23)."""
    x = np.asarray(measured_mm, dtype=float)
    y = np.asarray(ideal_mm, dtype=float)
    if len(x) < 4:
        raise CalibrationError("distortion fit needs at least 4 points")
    scale = max(float(np.max(np.abs(x))), 1e-12)
    v = np.vander(x / scale, 4, increasing=True)
    if np.linalg.matrix_rank(v) < 4:
        raise CalibrationError("distortion fit: fewer than 4 distinct film coordinates")
    a = np.linalg.lstsq(v, y, rcond=None)[0]
    return a / scale ** np.arange(4)


def apply_distortion(coefficients: np.ndarray, measured_mm: np.ndarray) -> np.ndarray:
    """Ideal coordinate a0 + a1 P' + a2 P'² + a3 P'³ (mm) of measured film coordinates P' (mm)."""
    a = np.asarray(coefficients, dtype=float)
    x = np.asarray(measured_mm, dtype=float)
    return a[0] + x * (a[1] + x * (a[2] + x * a[3]))


def calibrate_axis(
    theta_deg: np.ndarray,
    film_mm: np.ndarray,
    *,
    focal_nominal_mm: float | None = None,
    range_deg: float = 5.0,
    step_deg: float = SCAN_STEP_DEG,
) -> AxisCalibration:
    """Δθ scan, per-point focal lengths, principal point and distortion cubic for one axis.

    ``focal_nominal_mm`` is F_nom of (3-21); defaults to this axis's fitted F (mean of F_i).
    """
    rel, film = _relative_angles(theta_deg, film_mm)
    dtheta, f_i = scan_delta_theta(theta_deg, film_mm, range_deg=range_deg, step_deg=step_deg)
    focal = float(np.mean(f_i))
    if not focal > 0:
        raise CalibrationError(
            "camera calibration: the fitted focal length is not positive (check angle signs)")
    f_nom = focal if focal_nominal_mm is None else float(focal_nominal_mm)
    tan_dt = math.tan(math.radians(dtheta))
    ideal = f_nom * np.tan(rel - math.radians(dtheta))
    coeffs = fit_distortion(film, ideal)
    return AxisCalibration(
        delta_theta_deg=dtheta,
        focal_mm=focal,
        focal_std_mm=float(np.std(f_i)),
        focal_per_point_mm=f_i,
        principal_point_mm=float(film[0] + focal * tan_dt),
        focal_nominal_mm=f_nom,
        ideal_mm=ideal,
        distortion=coeffs,
        distortion_residuals_mm=ideal - apply_distortion(coeffs, film),
    )
