"""Camera calibration (calibration.md §4)."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from radar_io.calibration import (
    CalibrationError,
    apply_distortion,
    calibrate_axis,
    focal_lengths,
    scan_delta_theta,
)

THETA = np.array([0.0, -20.0, -15.0, -10.0, -5.0, 5.0, 10.0, 15.0, 20.0, 25.0])


def _targets(dtheta_deg, focal, pc, k3=0.0, offset_deg=0.0):
    """Film x (mm) of a collimator target (a point at infinity straight ahead) seen by a camera
    turned by θ on the table, imaged by OpenCV: K = [[F, 0, P_c], [0, F, 0], [0, 0, 1]] and
    radial distortion k1 = k3·F² (OpenCV's x(1 + k1 x²) on normalised x is u + k3 u³ in mm)."""
    k = np.array([[focal, 0.0, pc], [0.0, focal, 0.0], [0.0, 0.0, 1.0]])
    dist = np.array([k3 * focal**2, 0.0, 0.0, 0.0])
    x = []
    for a in np.radians(THETA - dtheta_deg):
        img, _ = cv2.projectPoints(np.array([[0.0, 0.0, 1e9]]), np.array([0.0, a, 0.0]),
                                   np.zeros(3), k, dist)
        x.append(img[0, 0, 0])
    return THETA + offset_deg, np.array(x)


def test_focal_lengths_of_opencv_targets():
    """The per-target focal lengths (4-x) equal the F OpenCV imaged with, for several Δθ, P_c."""
    for dtheta, focal, pc in ((0.37, 40.25, 0.12), (-1.2, 150.0, -0.4), (0.0, 35.0, 0.0)):
        theta, film = _targets(dtheta, focal, pc)
        np.testing.assert_allclose(focal_lengths(theta, film, dtheta), focal, rtol=1e-9)
        # a wrong Δθ gives focal lengths that differ from target to target
        assert np.std(focal_lengths(theta, film, dtheta + 0.05)) > 1e-3


@pytest.mark.parametrize("offset", [0.0, 12.3])
def test_recovers_delta_theta_principal_point_and_focal_length(offset):
    theta, film = _targets(0.37, 40.25, 0.12, offset_deg=offset)
    c = calibrate_axis(theta, film, focal_nominal_mm=40.0)
    assert c.delta_theta_deg == pytest.approx(0.37, abs=1e-12)
    assert c.focal_mm == pytest.approx(40.25, abs=1e-9)
    assert c.focal_std_mm < 1e-9
    assert c.principal_point_mm == pytest.approx(0.12, abs=1e-9)
    # ideal = F_nom tan(θ − Δθ) = (F_nom/F)(P' − P_c): a0 = −(F_nom/F) P_c, a1 = F_nom/F
    np.testing.assert_allclose(c.distortion, [-0.12 * 40.0 / 40.25, 40.0 / 40.25, 0.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(c.ideal_mm, 40.0 * np.tan(np.radians(THETA - 0.37)), atol=1e-12)


def test_off_grid_delta_theta_lands_on_the_nearest_step():
    theta, film = _targets(-0.734, 40.0, -0.3)
    dtheta, f = scan_delta_theta(theta, film)
    assert dtheta == pytest.approx(-0.73, abs=1e-12)
    assert np.mean(f) == pytest.approx(40.0, rel=1e-4)


def test_distortion_cubic_maps_measured_to_ideal():
    theta, film = _targets(0.2, 40.0, 0.05, k3=2e-5)  # 0.16 mm at 20 mm from the centre
    c = calibrate_axis(theta, film)
    # (Δθ itself is biased by an uncorrected distortion: the scan only makes F_i most uniform)
    assert c.focal_std_mm > 1e-4  # distortion makes F_i differ
    ideal = c.focal_nominal_mm * np.tan(np.radians(THETA - c.delta_theta_deg))
    np.testing.assert_allclose(apply_distortion(c.distortion, film), ideal, atol=2e-3)
    assert np.sqrt(np.mean(c.distortion_residuals_mm**2)) < 1e-3
    assert c.distortion[3] != pytest.approx(0.0, abs=1e-7)


def test_bad_targets_raise():
    theta, film = _targets(0.37, 40.25, 0.12)
    with pytest.raises(CalibrationError, match="at least 4"):
        calibrate_axis(theta[:3], film[:3])
    with pytest.raises(CalibrationError, match="edge"):
        scan_delta_theta(theta, film, range_deg=0.2)
    with pytest.raises(CalibrationError, match="direction of E_0"):
        calibrate_axis(np.r_[theta, 0.0], np.r_[film, 1.0])
    assert math.isfinite(calibrate_axis(theta, film).focal_mm)
