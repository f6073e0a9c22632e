"""Synthetic aerial photos for the calibration tests (ground X north, Y east, Z down; film mm).

Made with OpenCV, not with radar_io's own collinearity: C_PE from three ``cv2.Rodrigues``
frame rotations and the film coordinates from ``cv2.projectPoints`` (K = diag(F, F, 1)).
"""

from __future__ import annotations

import cv2
import numpy as np

from radar_io.calibration.resection import Pose

FOCAL_MM = 40.0
HALF_FILM_MM = 27.5  # 55 × 55 mm film


def aerial_photo(
    rng: np.random.Generator,
    *,
    n: int = 12,
    pose: Pose | None = None,
    focal_mm: float = FOCAL_MM,
    relief_m: float = 20.0,
    film_fill: float = 0.9,
) -> tuple[Pose, np.ndarray, np.ndarray]:
    """A camera pose, n ground control points (N, 3) m and their exact film coordinates (N, 2) mm.

    The points are drawn uniformly over ``film_fill`` of the 55 × 55 mm frame and
    put on ground of random height ±relief_m around the radar level (Z = 0).
    """
    if pose is None:
        pose = Pose(6200.0, 2800.0, -900.0, 1.2, -2.1, 37.0)
    c = pose.to_vector()
    r = c_pe(*c[3:])
    film = rng.uniform(-film_fill * HALF_FILM_MM, film_fill * HALF_FILM_MM, size=(n, 2))
    ray = np.column_stack([film, np.full(n, focal_mm)]) @ r  # camera → ground: Rᵀ·d
    z = rng.uniform(-relief_m, relief_m, size=n)
    t = (z - c[2]) / ray[:, 2]
    points = c[:3] + t[:, None] * ray
    film_cv, _ = cv2.projectPoints(points, cv2.Rodrigues(r)[0], -r @ c[:3],
                                   np.diag([focal_mm, focal_mm, 1.0]), None)
    return pose, points, film_cv[:, 0, :]


def c_pe(phi: float, theta: float, psi: float) -> np.ndarray:
    """Ground → camera C_PE = R_x(φ) R_y(θ) R_z(ψ) (frame rotations, radians) via cv2.Rodrigues."""
    rod = lambda v: cv2.Rodrigues(np.array(v, dtype=float))[0]  # noqa: E731 - active rotation
    return rod([-phi, 0, 0]) @ rod([0, -theta, 0]) @ rod([0, 0, -psi])
