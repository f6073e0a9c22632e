"""Atmospheric refraction (calibration.md §5)."""

from __future__ import annotations

import numpy as np
import pytest

from radar_io.calibration import (
    CalibrationError,
    Pose,
    correct_refraction,
    refraction_delta,
    refraction_displacement_mm,
    resect,
)

from .synthetic import FOCAL_MM, aerial_photo

FT = 0.3048


def test_delta_is_the_formula():
    ha, hi = 3000 * FT / 1000, 0.0  # km
    assert refraction_delta(3000 * FT, 0.0) == pytest.approx((1.2 * ha - 0.38 * ha**2) * 1e-3, rel=1e-14)
    ha, hi = 1.5, 0.2
    expected = (1 - 0.06 * hi) * (1.2 * (ha - hi) - 0.38 * (ha - hi) ** 2) * 1e-3
    assert refraction_delta(1500.0, 200.0) == pytest.approx(expected, rel=1e-14)


def test_points_move_inward_by_dr():
    film = np.array([[10.0, 0.0], [-12.0, 16.0], [0.0, 0.0], [27.5, -27.5]])
    delta = refraction_delta(900.0, 30.0)
    out = correct_refraction(film, FOCAL_MM, 900.0, 30.0)
    r = np.hypot(film[:, 0], film[:, 1])
    dr = r * (r**2 / FOCAL_MM**2 + 1) * delta
    np.testing.assert_allclose(refraction_displacement_mm(r, FOCAL_MM, delta), dr)
    np.testing.assert_allclose(r - np.hypot(out[:, 0], out[:, 1]), dr, atol=1e-15)
    np.testing.assert_allclose(out[2], [0.0, 0.0])
    # direction kept: the corrected point is on the same ray from the principal point
    np.testing.assert_allclose(film[:, 0] * out[:, 1] - film[:, 1] * out[:, 0], 0.0, atol=1e-12)
    assert dr[3] == pytest.approx(27.5 * np.sqrt(2) * (2 * 27.5**2 / 1600 + 1) * delta)


def test_correction_raises_the_solved_height_at_3000_ft():
    # same film, solved with and without the correction: the source saw heights rise by ≈ 2 m at 3000 ft
    rng = np.random.default_rng(3)
    pose, pts, film = aerial_photo(rng, n=12, pose=Pose(6000.0, 2000.0, -3000 * FT, 0.5, -0.5, 20.0), relief_m=0.0)
    plain = resect(pts, film, FOCAL_MM)
    corrected = resect(pts, correct_refraction(film, FOCAL_MM, 3000 * FT, 0.0), FOCAL_MM)
    rise = plain.pose.z0_m - corrected.pose.z0_m  # Z down: higher = more negative
    assert 0.5 < rise < 3.0, rise


def test_per_point_ground_heights_and_bad_heights():
    film = np.array([[10.0, 5.0], [20.0, -3.0]])
    out = correct_refraction(film, FOCAL_MM, 1000.0, np.array([0.0, 300.0]))
    one = correct_refraction(film[1:], FOCAL_MM, 1000.0, 300.0)
    np.testing.assert_allclose(out[1:], one)
    with pytest.raises(CalibrationError, match="above every ground point"):
        correct_refraction(film, FOCAL_MM, 100.0, 300.0)
    with pytest.raises(CalibrationError):
        refraction_delta(5000.0, 0.0)
