"""Monte Carlo accuracy of a resection (calibration.md §9)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from radar_io.calibration.resection import PARAM_KEYS, ResectionResult, resect
from radar_io.errors import CalibrationError


@dataclass(frozen=True)
class MonteCarloResult:
    """Spread of the unknowns over the runs.

    ``std`` per unknown (m and deg; population std, ddof = 0, as everywhere in
    the spec); ``samples`` (M, 6) the solved unknowns of every run in the same
    units; ``sigma_mm`` the (σ_Px, σ_Py) noise used; ``seed`` the generator seed.
    """

    std: dict[str, float]
    samples: np.ndarray
    sigma_mm: tuple[float, float]
    runs: int
    seed: int


def monte_carlo(
    points_m: np.ndarray,
    focal_mm: float,
    solution: ResectionResult,
    *,
    runs: int = 20,
    seed: int | None = None,
    sigma_mm: tuple[float, float] | None = None,
    weights: np.ndarray | None = None,
    max_iterations: int = 20,
) -> MonteCarloResult:
    """Re-solve ``runs`` times from film points ``P̂ + σ·N(0, 1)``.

    P̂ are the solution's fitted film coordinates.  σ defaults to the population
    std of the solution's film residuals per axis (σ_Px, σ_Py).  Every run
    starts from the solved pose.  ``seed=None`` draws a fresh seed (reported).
    Note: the residuals' population std is smaller than the a-posteriori σ₀ of
    the covariance by about sqrt((2N − 6)/2N), and so is this spread.
    """
    if runs < 2:
        raise CalibrationError(f"Monte Carlo needs at least 2 runs, got {runs}")
    if seed is None:  # a fresh seed, kept below 2**32 so that it survives any JSON reader
        seed = int(np.random.SeedSequence().generate_state(1, np.uint32)[0])
    if seed < 0:
        raise CalibrationError(f"Monte Carlo seed must be ≥ 0, got {seed}")
    if sigma_mm is None:
        sx, sy = (float(v) for v in np.std(solution.residuals_mm, axis=0))
    else:
        sx, sy = (float(v) for v in sigma_mm)
    if not (np.isfinite(sx) and np.isfinite(sy) and sx >= 0 and sy >= 0):
        raise CalibrationError(f"Monte Carlo noise must be finite and ≥ 0, got {(sx, sy)}")
    rng = np.random.default_rng(seed)
    fitted = solution.fitted_mm
    ref = np.array([getattr(solution.pose, k) for k in PARAM_KEYS])
    samples = np.empty((runs, 6))
    for m in range(runs):
        film = fitted + np.array([sx, sy]) * rng.standard_normal(fitted.shape)
        try:
            r = resect(points_m, film, focal_mm, start=solution.pose, weights=weights,
                       max_iterations=max_iterations)
        except CalibrationError as exc:
            raise CalibrationError(f"Monte Carlo run {m + 1} of {runs} failed: {exc}") from exc
        samples[m] = [getattr(r.pose, k) for k in PARAM_KEYS]
    # angles: differences to the solution wrapped to (−180, 180] before taking the spread
    samples[:, 3:] = ref[3:] + (180.0 - np.mod(180.0 - (samples[:, 3:] - ref[3:]), 360.0))
    std = np.std(samples, axis=0)
    return MonteCarloResult(
        std={k: float(v) for k, v in zip(PARAM_KEYS, std, strict=True)},
        samples=samples,
        sigma_mm=(sx, sy),
        runs=runs,
        seed=seed,
    )
