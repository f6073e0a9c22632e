"""Resection (calibration.md §1–§3): rotation, partials, agreement with OpenCV, degenerate input."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from radar_io.calibration import CalibrationError, Pose, project, resect, residual_partials
from radar_io.calibration.resection import collinearity
from radar_io.calibration.rotation import angles_from_matrix, rotation_matrix, rotation_partials
from radar_io.errors import RadarIOError

from .synthetic import FOCAL_MM, HALF_FILM_MM, aerial_photo


def _rx(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, s], [0, -s, c]])


def _ry(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, -s], [0, 1, 0], [s, 0, c]])


def _rz(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]])


def test_rotation_is_rx_ry_rz_and_round_trips():
    rng = np.random.default_rng(3)
    for _ in range(50):
        phi, psi = rng.uniform(-math.pi, math.pi, 2)
        theta = rng.uniform(-1.5, 1.5)
        c = rotation_matrix(phi, theta, psi)
        np.testing.assert_allclose(c, _rx(phi) @ _ry(theta) @ _rz(psi), atol=1e-15)
        np.testing.assert_allclose(c @ c.T, np.eye(3), atol=1e-15)
        assert np.linalg.det(c) == pytest.approx(1.0)
        np.testing.assert_allclose(angles_from_matrix(c), (phi, theta, psi), atol=1e-12)


def test_rotation_partials_match_finite_differences():
    angles = np.array([0.3, -0.2, 2.1])
    d = rotation_partials(*angles)
    h = 1e-6
    for j in range(3):
        e = np.zeros(3)
        e[j] = h
        fd = (rotation_matrix(*(angles + e)) - rotation_matrix(*(angles - e))) / (2 * h)
        np.testing.assert_allclose(d[j], fd, atol=1e-9)


def test_level_camera_sees_forward_as_positive_px():
    # heading north, level: a point ahead (north) of the nadir images at +P_x, a point to the
    # right (east) at +P_y
    pose = Pose(0.0, 0.0, -1000.0, 0.0, 0.0, 0.0)
    film = project(np.array([[100.0, 0.0, 0.0], [0.0, 100.0, 0.0]]), pose, 40.0)
    np.testing.assert_allclose(film, [[4.0, 0.0], [0.0, 4.0]], atol=1e-12)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_analytic_partials_match_finite_differences(seed):
    rng = np.random.default_rng(seed)
    pose, pts, _film = aerial_photo(rng, n=10, pose=Pose(5000.0, -3000.0, -850.0, 4.0, -6.0, 123.0))
    c = pose.to_vector()
    a = residual_partials(pts, c, FOCAL_MM)
    steps = np.array([1e-3, 1e-3, 1e-3, 1e-7, 1e-7, 1e-7])
    for k in range(6):
        e = np.zeros(6)
        e[k] = steps[k]
        # ε = measured − P̂, so ∂ε/∂C = −∂P̂/∂C
        fd = -(collinearity(pts, c + e, FOCAL_MM)[0] - collinearity(pts, c - e, FOCAL_MM)[0]) / (2 * steps[k])
        np.testing.assert_allclose(a[:, :, k], fd, rtol=1e-6, atol=1e-9 * np.max(np.abs(fd)))


def _solve_pnp(points, film, focal_mm):
    """OpenCV pose in the spec's terms.

    OpenCV's camera frame is x right, y down, z forward (optical axis); the
    spec's is X_p forward (flight direction), Y_p right, Z_p down the optical
    axis.  Both are right-handed with the third axis along the optical axis, so
    OpenCV (x, y, z) = spec (X_p, Y_p, Z_p): image u ↔ P_x, v ↔ P_y, and with
    K = diag(F, F, 1) (principal point 0) OpenCV's projection is exactly the
    spec's collinearity.  Film mm are scaled to µm "pixels" for OpenCV's
    tolerances.  OpenCV x_cam = R·X_w + t, so C_PE = R and X_0 = −Rᵀ t.
    """
    k = np.array([[focal_mm * 1000.0, 0, 0], [0, focal_mm * 1000.0, 0], [0, 0, 1.0]])
    ok, rvec, tvec = cv2.solvePnP(points, film * 1000.0, k, None, flags=cv2.SOLVEPNP_ITERATIVE)
    assert ok
    rvec, tvec = cv2.solvePnPRefineLM(points, film * 1000.0, k, None, rvec, tvec,
                                      criteria=(cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 100, 1e-12))
    r = cv2.Rodrigues(rvec)[0]
    return -r.T @ tvec.ravel(), np.degrees(angles_from_matrix(r))


def _angle_diff(a, b):
    return (np.asarray(a) - np.asarray(b) + 180.0) % 360.0 - 180.0


@pytest.mark.parametrize("seed", [10, 11, 12, 13])
def test_agrees_with_opencv_from_a_start_200m_and_5deg_away(seed):
    rng = np.random.default_rng(seed)
    truth = Pose(6000.0 + 500 * seed, 2500.0, -900.0, rng.uniform(-3, 3), rng.uniform(-3, 3),
                 rng.uniform(0, 360))
    pose, pts, film = aerial_photo(rng, n=int(rng.integers(10, 15)), pose=truth)
    off = rng.normal(size=3)
    off *= 200.0 / np.linalg.norm(off)
    start = Pose(pose.x0_m + off[0], pose.y0_m + off[1], pose.z0_m + off[2],
                 pose.phi_deg + 5.0, pose.theta_deg - 5.0, pose.psi_deg + 5.0)
    r = resect(pts, film, FOCAL_MM, start=start)
    x_cv, ang_cv = _solve_pnp(pts, film, FOCAL_MM)
    got = np.array([r.pose.x0_m, r.pose.y0_m, r.pose.z0_m])
    ang = np.array([r.pose.phi_deg, r.pose.theta_deg, r.pose.psi_deg])
    assert np.max(np.abs(got - x_cv)) <= 1e-3
    assert np.max(np.abs(_angle_diff(ang, ang_cv))) <= 1e-4
    assert r.iterations <= 8
    # and both are the truth
    assert np.max(np.abs(got - [truth.x0_m, truth.y0_m, truth.z0_m])) <= 1e-3
    assert np.max(np.abs(_angle_diff(ang, [truth.phi_deg, truth.theta_deg, truth.psi_deg]))) <= 1e-4
    assert r.rms_mm < 1e-9


def test_agrees_with_opencv_on_noisy_film():
    # both minimise the same unweighted film-plane residuals, so they agree on noisy data too
    rng = np.random.default_rng(21)
    _pose, pts, film = aerial_photo(rng, n=12)
    film = film + rng.normal(scale=0.07, size=film.shape)
    r = resect(pts, film, FOCAL_MM)
    x_cv, ang_cv = _solve_pnp(pts, film, FOCAL_MM)
    assert np.max(np.abs(np.array([r.pose.x0_m, r.pose.y0_m, r.pose.z0_m]) - x_cv)) <= 1e-3
    assert np.max(np.abs(_angle_diff([r.pose.phi_deg, r.pose.theta_deg, r.pose.psi_deg], ang_cv))) <= 1e-4
    assert 0.03 < r.rms_mm < 0.1


@pytest.mark.parametrize("n", [10, 12, 14])
def test_recovers_900m_40mm_55mm_geometry_without_a_start(n):
    rng = np.random.default_rng(100 + n)
    truth = Pose(7300.0, -1800.0, -900.0, -2.5, 1.7, rng.uniform(0, 360))
    _pose, pts, film = aerial_photo(rng, n=n, pose=truth)
    assert np.all(np.abs(film) <= HALF_FILM_MM)
    r = resect(pts, film, FOCAL_MM)
    assert abs(r.pose.x0_m - truth.x0_m) < 1e-6
    assert abs(r.pose.y0_m - truth.y0_m) < 1e-6
    assert abs(r.pose.z0_m - truth.z0_m) < 1e-6
    assert np.max(np.abs(_angle_diff([r.pose.phi_deg, r.pose.theta_deg, r.pose.psi_deg],
                                     [truth.phi_deg, truth.theta_deg, truth.psi_deg]))) < 1e-8
    assert r.iterations <= 8


def test_three_dimensional_points_use_the_dlt_start():
    # an oblique view of a strongly non-planar point set (depths 300 … 900 m along the rays)
    rng = np.random.default_rng(5)
    truth = Pose(-200.0, 300.0, -1000.0, 10.0, -25.0, 60.0)
    c = truth.to_vector()
    film = rng.uniform(-15.0, 15.0, size=(12, 2))
    depth = rng.uniform(300.0, 900.0, size=12)
    cam = np.column_stack([film / 35.0, np.ones(12)]) * depth[:, None]
    pts = c[:3] + cam @ rotation_matrix(*c[3:])
    s = np.linalg.svd(pts - pts.mean(axis=0), compute_uv=False)
    assert s[2] > 0.05 * s[0]  # really three-dimensional
    r = resect(pts, film, 35.0)
    np.testing.assert_allclose([r.pose.x0_m, r.pose.y0_m, r.pose.z0_m], [-200, 300, -1000], atol=1e-6)
    np.testing.assert_allclose([r.pose.phi_deg, r.pose.theta_deg, r.pose.psi_deg], [10, -25, 60], atol=1e-8)
    assert r.iterations <= 5


def test_weights_and_covariance():
    rng = np.random.default_rng(8)
    _pose, pts, film = aerial_photo(rng, n=12)
    noise = np.column_stack([rng.normal(scale=0.02, size=12), rng.normal(scale=0.2, size=12)])
    w = np.tile([1 / 0.02**2, 1 / 0.2**2], (12, 1))
    r_w = resect(pts, film + noise, FOCAL_MM, weights=w)
    r_u = resect(pts, film + noise, FOCAL_MM)
    # a-posteriori variance of unit weight ≈ 1 with correct weights; covariance symmetric, positive
    assert 0.4 < r_w.sigma0 < 1.8
    np.testing.assert_allclose(r_w.covariance, r_w.covariance.T, rtol=1e-10, atol=1e-18)
    assert np.all(np.linalg.eigvalsh(r_w.covariance) > 0)
    assert set(r_w.sigma) == {"x0_m", "y0_m", "z0_m", "phi_deg", "theta_deg", "psi_deg"}
    # the weighted and unweighted solutions differ (the weights are used)
    assert abs(r_w.pose.x0_m - r_u.pose.x0_m) > 1e-3
    np.testing.assert_allclose(r_u.residuals_mm, film + noise - r_u.fitted_mm)
    assert r_u.rms_mm == pytest.approx(float(np.sqrt(np.mean(r_u.residuals_mm**2))))


def test_three_points_solve_without_redundancy():
    rng = np.random.default_rng(2)
    pose, pts, film = aerial_photo(rng, n=3)
    start = Pose(pose.x0_m + 30, pose.y0_m - 20, pose.z0_m + 10, pose.phi_deg + 1, pose.theta_deg,
                 pose.psi_deg - 1)
    r = resect(pts, film, FOCAL_MM, start=start)
    assert abs(r.pose.z0_m - pose.z0_m) < 1e-6
    assert all(math.isnan(v) for v in r.sigma.values())


def test_degenerate_inputs_raise_clear_errors():
    rng = np.random.default_rng(4)
    pose, pts, film = aerial_photo(rng, n=8)
    assert issubclass(CalibrationError, RadarIOError)
    with pytest.raises(CalibrationError, match="at least 3"):
        resect(pts[:2], film[:2], FOCAL_MM)
    line = np.column_stack([np.linspace(5000, 7000, 6), np.linspace(2000, 3000, 6), np.zeros(6)])
    with pytest.raises(CalibrationError, match="collinear"):
        resect(line, film[:6], FOCAL_MM)
    with pytest.raises(CalibrationError, match="behind the camera"):
        resect(pts, film, FOCAL_MM, start=Pose(pose.x0_m, pose.y0_m, 500.0, 0, 0, 0))
    with pytest.raises(CalibrationError, match="did not converge"):
        resect(pts, film, FOCAL_MM,
               start=Pose(pose.x0_m + 300, pose.y0_m, pose.z0_m, 0, 0, pose.psi_deg + 20),
               max_iterations=1)
    with pytest.raises(CalibrationError, match="focal"):
        resect(pts, film, -40.0)
    with pytest.raises(CalibrationError, match="non-finite"):
        resect(np.where(np.arange(24).reshape(8, 3) == 4, np.nan, pts), film, FOCAL_MM)
    # three points with the camera on their circumscribed vertical cylinder (the "danger cylinder"):
    # the pose is not determined, the normal matrix is singular
    ang = np.radians([0.0, 120.0, 240.0])
    tri = np.column_stack([100 * np.cos(ang), 100 * np.sin(ang), np.zeros(3)])
    on_cylinder = Pose(50.0, 100 * math.sin(math.radians(60)), -500.0, 0.0, 0.0, 0.0)
    with pytest.raises(CalibrationError, match="singular"):
        resect(tri, project(tri, on_cylinder, FOCAL_MM), FOCAL_MM, start=on_cylinder)


def test_mirrored_film_axis_is_refused():
    # a film-axis sign error is explained by a mirror pose below the ground: refused, not returned
    rng = np.random.default_rng(6)
    _pose, pts, film = aerial_photo(rng, n=10)
    with pytest.raises(CalibrationError, match="below the control points"):
        resect(pts, film * np.array([-1.0, 1.0]), FOCAL_MM)
