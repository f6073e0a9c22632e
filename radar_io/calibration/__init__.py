"""Radar calibration by aerial photogrammetry (calibration.md; project issue 5).

Frames: ground/radar X north, Y east, Z down (H = −Z up), origin at the radar;
camera X_p forward, Y_p right, Z_p down the optical axis; film coordinates in mm.
Angles are degrees at this API (radians only in the maths primitives of
:mod:`.rotation` and :func:`.resection.residual_partials`).
"""

from __future__ import annotations

from radar_io.calibration.bias import bias_calibration, bias_statistics, photo_to_radar, wrap_deg
from radar_io.calibration.camera import (
    AxisCalibration,
    apply_distortion,
    calibrate_axis,
    fit_distortion,
    focal_lengths,
    scan_delta_theta,
)
from radar_io.calibration.digitizer import GridTransfer, digitised_to_film, film_from_grid
from radar_io.calibration.mapgrid import (
    LocalConversion,
    QuadraticModel,
    fit_quadratic_model,
    gauss_kruger_series,
    japan_zone_crs,
    map_to_local,
)
from radar_io.calibration.montecarlo import MonteCarloResult, monte_carlo
from radar_io.calibration.refraction import correct_refraction, refraction_delta, refraction_displacement_mm
from radar_io.calibration.resection import Pose, ResectionResult, project, resect, residual_partials
from radar_io.calibration.rotation import angles_from_matrix, rotation_matrix, rotation_partials
from radar_io.errors import CalibrationError, CalibrationInputError

__all__ = [
    "AxisCalibration",
    "CalibrationError",
    "CalibrationInputError",
    "GridTransfer",
    "LocalConversion",
    "MonteCarloResult",
    "Pose",
    "QuadraticModel",
    "ResectionResult",
    "angles_from_matrix",
    "apply_distortion",
    "bias_calibration",
    "bias_statistics",
    "calibrate_axis",
    "correct_refraction",
    "digitised_to_film",
    "film_from_grid",
    "fit_distortion",
    "fit_quadratic_model",
    "focal_lengths",
    "gauss_kruger_series",
    "japan_zone_crs",
    "map_to_local",
    "monte_carlo",
    "photo_to_radar",
    "project",
    "refraction_delta",
    "refraction_displacement_mm",
    "resect",
    "residual_partials",
    "rotation_matrix",
    "rotation_partials",
    "scan_delta_theta",
    "wrap_deg",
]
