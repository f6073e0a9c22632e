"""Monte Carlo accuracy (calibration.md §9)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from radar_io.calibration import CalibrationError, Pose, monte_carlo, resect, residual_partials

from .synthetic import FOCAL_MM, aerial_photo

# the source's spreads (§9) at 750–920 m, 40 mm lens, 55 × 55 mm film, σ ≈ 0.04–0.11 mm, 8–14 points
SPEC_M = {"x0_m": (2.5, 2.9), "y0_m": (0.7, 1.3), "z0_m": (0.6, 0.8)}
SPEC_ANGLE_MRAD = (0.6, 2.6)


def _solved_photo(seed: int, n: int = 10, sigma: float = 0.07):
    rng = np.random.default_rng(seed)
    _pose, pts, film = aerial_photo(rng, n=n, pose=Pose(6000.0, 2000.0, -850.0, 1.0, -1.0, 20.0))
    return pts, resect(pts, film + rng.normal(scale=sigma, size=film.shape), FOCAL_MM)


@pytest.mark.parametrize("seed", [0, 1])
def test_spreads_are_of_the_order_the_source_reports(seed):
    pts, sol = _solved_photo(seed)
    mc = monte_carlo(pts, FOCAL_MM, sol, runs=100, seed=7)
    assert mc.samples.shape == (100, 6)
    # order of magnitude: within a factor 3 of the source's range
    for k, (lo, hi) in SPEC_M.items():
        assert lo / 3 <= mc.std[k] <= hi * 3, (k, mc.std[k])
    for k in ("phi_deg", "theta_deg", "psi_deg"):
        mrad = math.radians(mc.std[k]) * 1000
        assert SPEC_ANGLE_MRAD[0] / 3 <= mrad <= SPEC_ANGLE_MRAD[1] * 3, (k, mrad)


def test_noise_defaults_to_population_std_of_residuals_and_seed_reproduces():
    pts, sol = _solved_photo(3)
    a = monte_carlo(pts, FOCAL_MM, sol, runs=20, seed=42)
    b = monte_carlo(pts, FOCAL_MM, sol, runs=20, seed=42)
    c = monte_carlo(pts, FOCAL_MM, sol, runs=20, seed=43)
    np.testing.assert_allclose(a.sigma_mm, np.std(sol.residuals_mm, axis=0, ddof=0))
    np.testing.assert_array_equal(a.samples, b.samples)
    assert a.std == b.std
    assert not np.array_equal(a.samples, c.samples)
    np.testing.assert_allclose(list(a.std.values()), np.std(a.samples, axis=0))
    assert a.seed == 42 and a.runs == 20


@pytest.mark.slow
def test_spread_matches_linear_error_propagation():
    """With a known σ the Monte Carlo std must approach sqrt(diag(σ² (AᵀA)⁻¹)) (linear regime).

    The sample std of N runs has a relative standard error of 1/sqrt(2(N − 1)) = 1.8 % at
    N = 1500; the tolerance is 4.5 of those (8.2 %), where it was 12 % at N = 600 (5 of them)."""
    pts, sol = _solved_photo(4, n=12)
    sigma, runs = 0.05, 1500
    mc = monte_carlo(pts, FOCAL_MM, sol, runs=runs, seed=1, sigma_mm=(sigma, sigma))
    a = residual_partials(pts, sol.pose.to_vector(), FOCAL_MM).reshape(-1, 6)
    expected = np.sqrt(np.diag(np.linalg.inv(a.T @ a))) * sigma
    expected[3:] = np.degrees(expected[3:])
    got = np.array(list(mc.std.values()))
    np.testing.assert_allclose(got, expected, rtol=4.5 / math.sqrt(2 * (runs - 1)))


def test_rejects_too_few_runs():
    pts, sol = _solved_photo(5)
    with pytest.raises(CalibrationError):
        monte_carlo(pts, FOCAL_MM, sol, runs=1, seed=0)
