"""Camera maths (calibration.md §1-§3) against OpenCV, written independently of radar_io.

* C_PE = R_x(φ) R_y(θ) R_z(ψ) built from three ``cv2.Rodrigues`` frame rotations;
* collinearity (3-4 … 3-6) against ``cv2.projectPoints`` with K = diag(F, F, 1);
* the resected pose against ``cv2.solvePnP`` + ``cv2.solvePnPRefineLM`` on the same noisy
  film: both minimise the same unweighted sum of squared film residuals, so they must meet
  at the same minimum (to the solvers' convergence, not to the noise).
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from radar_io.calibration import Pose, project, resect
from radar_io.calibration.rotation import rotation_matrix, rotation_partials

from .synthetic import FOCAL_MM, aerial_photo, c_pe

K = np.diag([FOCAL_MM, FOCAL_MM, 1.0])


def opencv_pose(pose: Pose) -> tuple[np.ndarray, np.ndarray]:
    c = pose.to_vector()
    r = c_pe(*c[3:])
    return cv2.Rodrigues(r)[0], -r @ c[:3]


def test_rotation_matrix_is_three_rodrigues_rotations():
    rng = np.random.default_rng(5)
    for phi, theta, psi in rng.uniform([-np.pi, -1.5, -np.pi], [np.pi, 1.5, np.pi], (50, 3)):
        np.testing.assert_allclose(rotation_matrix(phi, theta, psi), c_pe(phi, theta, psi), atol=1e-15)


def test_rotation_partials_match_central_differences():
    rng = np.random.default_rng(6)
    h = 1e-6
    for a in rng.uniform(-1.2, 1.2, (20, 3)):
        d = rotation_partials(*a)
        for k in range(3):
            e = np.zeros(3)
            e[k] = h
            num = (c_pe(*(a + e)) - c_pe(*(a - e))) / (2 * h)
            np.testing.assert_allclose(d[k], num, atol=1e-9)   # O(h²) ≈ 1e-12 plus rounding


@pytest.mark.parametrize("seed", range(5))
def test_collinearity_matches_cv2_project_points(seed):
    rng = np.random.default_rng(seed)
    pose = Pose(*rng.uniform([3000, 0, -1500, -5, -5, 0], [8000, 4000, -500, 5, 5, 360]))
    _, pts, _ = aerial_photo(rng, n=15, pose=pose)
    rvec, tvec = opencv_pose(pose)
    img, _ = cv2.projectPoints(pts, rvec, tvec, K, None)
    np.testing.assert_allclose(project(pts, pose, FOCAL_MM), img[:, 0, :], atol=1e-10)  # 0.1 nm


@pytest.mark.parametrize("seed", range(4))
def test_resection_meets_opencv_solvepnp(seed):
    rng = np.random.default_rng(100 + seed)
    pose, pts, film = aerial_photo(rng, n=10)
    noisy = film + rng.normal(scale=0.07, size=film.shape)       # σ of the source's film reading
    sol = resect(pts, noisy, FOCAL_MM, tol_m=1e-9, tol_deg=1e-10, max_iterations=50)
    rvec, tvec = opencv_pose(Pose(6000.0, 2500.0, -800.0, 0.0, 0.0, 30.0))   # rough start
    ok, rvec, tvec = cv2.solvePnP(pts, noisy, K, None, rvec, tvec, useExtrinsicGuess=True,
                                  flags=cv2.SOLVEPNP_ITERATIVE)
    assert ok
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 200, 1e-15)
    rvec, tvec = cv2.solvePnPRefineLM(pts, noisy, K, None, rvec, tvec, crit)
    r_cv = cv2.Rodrigues(rvec)[0]
    c = sol.pose.to_vector()
    # the noise moved the pose by metres; the two solvers agree to a millimetre and 1 µrad
    assert np.linalg.norm(c[:3] - pose.to_vector()[:3]) > 0.05
    np.testing.assert_allclose(c[:3], -r_cv.T @ tvec.ravel(), atol=1e-3)
    np.testing.assert_allclose(rotation_matrix(*c[3:]), r_cv, atol=1e-6)
    res_cv = cv2.projectPoints(pts, rvec, tvec, K, None)[0][:, 0, :] - noisy
    np.testing.assert_allclose(sol.rms_mm, np.sqrt(np.mean(res_cv**2)), rtol=1e-6)
