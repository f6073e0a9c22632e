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


# δ of calibration.md §5 worked out by hand (heights in km):
#   H_a 1.0, H_i 0.0: 1.2·1.0 − 0.38·1.0                      = 0.82      → 0.82e-3
#   H_a 1.5, H_i 0.2: (1 − 0.012)(1.2·1.3 − 0.38·1.69)         = 0.9067864 → 0.9067864e-3
#   H_a 2.0, H_i 0.5: (1 − 0.03)(1.2·1.5 − 0.38·2.25)          = 0.91665   → 0.91665e-3
#   H_a 3.0, H_i 0.0: 3.6 − 3.42                               = 0.18      → 0.18e-3
HAND = [(1000.0, 0.0, 0.82e-3), (1500.0, 200.0, 0.9067864e-3), (2000.0, 500.0, 0.91665e-3),
        (3000.0, 0.0, 0.18e-3)]


@pytest.mark.parametrize("ha, hi, delta", HAND)
def test_delta_matches_values_worked_by_hand(ha, hi, delta):
    assert refraction_delta(ha, hi) == pytest.approx(delta, rel=1e-12)


def test_displacement_is_the_first_order_shift_of_a_bent_ray():
    """Independent statement: a ray at angle θ off the axis (r = F tan θ) bent towards the axis
    by δ·tan θ lands at F tan(θ − δ tan θ); dr = r (r²/F² + 1) δ is that shift to first order
    in δ, so the two differ by O(δ² tan² θ) ≈ 2·10⁻³ of dr at most for δ ≈ 0.9·10⁻³, θ ≤ 45°."""
    delta = refraction_delta(1500.0, 200.0)
    r = np.linspace(0.5, FOCAL_MM, 40)                     # up to 45° off the axis
    theta = np.arctan(r / FOCAL_MM)
    exact = r - FOCAL_MM * np.tan(theta - delta * np.tan(theta))
    np.testing.assert_allclose(refraction_displacement_mm(r, FOCAL_MM, delta), exact, rtol=2.5e-3)
    # and correct_refraction moves each film point along its own ray to that radius
    ang = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    film = np.column_stack([r * np.cos(ang), r * np.sin(ang)])
    out = correct_refraction(film, FOCAL_MM, 1500.0, 200.0)
    np.testing.assert_allclose(np.hypot(out[:, 0], out[:, 1]), r - exact, rtol=1e-5)
    np.testing.assert_allclose(np.arctan2(out[:, 1], out[:, 0]), np.arctan2(film[:, 1], film[:, 0]),
                               atol=1e-12)
    np.testing.assert_allclose(correct_refraction(np.zeros((1, 2)), FOCAL_MM, 1500.0, 200.0), 0.0)


def test_correction_raises_the_solved_height_at_3000_ft():
    # same film, solved with and without the correction: the source saw heights rise by ≈ 2 m at 3000 ft
    rng = np.random.default_rng(3)
    _pose, pts, film = aerial_photo(rng, n=12, pose=Pose(6000.0, 2000.0, -3000 * FT, 0.5, -0.5, 20.0),
                                    relief_m=0.0)
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
