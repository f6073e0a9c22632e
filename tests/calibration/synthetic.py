"""Synthetic aerial photos for the calibration tests (ground X north, Y east, Z down; film mm)."""

from __future__ import annotations

import numpy as np

from radar_io.calibration.resection import Pose, project
from radar_io.calibration.rotation import rotation_matrix

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
    r = rotation_matrix(*c[3:])
    film = rng.uniform(-film_fill * HALF_FILM_MM, film_fill * HALF_FILM_MM, size=(n, 2))
    ray = np.column_stack([film, np.full(n, focal_mm)]) @ r  # camera → ground: Rᵀ·d
    z = rng.uniform(-relief_m, relief_m, size=n)
    t = (z - c[2]) / ray[:, 2]
    points = c[:3] + t[:, None] * ray
    return pose, points, project(points, pose, focal_mm)
