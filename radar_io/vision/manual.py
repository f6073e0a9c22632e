"""Manual mode (patent claims 5–6): the pose from points an operator picked on the image.

Points file (JSON), pixel coordinates ``[u, v]`` — ``u`` right, ``v`` down,
``(0, 0)`` the centre of the top-left pixel (OpenCV convention), two or more
points per line::

    {
      "horizon":    [[12.0, 201.5], [630.2, 240.0]],
      "left_edge":  [[300.0, 230.0], [120.5, 470.0]],
      "right_edge": [[330.0, 230.0], [520.0, 470.0]]
    }

Each line is fitted by orthogonal least squares, then the same maths as the
image chain (:func:`radar_io.vision.chain.pose_from_point_sets`).  Which edge is
left and which right is decided by the geometry (the right edge has the smaller
inverse slope in the bank-corrected image), so swapped labels do no harm.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from radar_io.errors import VisionError
from radar_io.textfiles import read_json
from radar_io.vision.chain import ChainParams, RunwayResult, pose_from_point_sets

__all__ = ["LINE_KEYS", "load_points", "pose_from_points"]

#: the three lines of a points file, in solving order
LINE_KEYS = ("horizon", "left_edge", "right_edge")


def _as_points(name: str, value: Any) -> NDArray[np.float64]:
    try:
        pts = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise VisionError(f"{name}: points must be a list of [x, y] pairs") from exc
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise VisionError(f"{name}: points must be a list of [x, y] pairs")
    if len(pts) < 2:
        raise VisionError(f"{name}: need at least two points, got {len(pts)}")
    if not np.all(np.isfinite(pts)):
        raise VisionError(f"{name}: points must be finite numbers")
    if float(np.max(np.ptp(pts, axis=0))) < 1.0:
        raise VisionError(f"{name}: points must span at least one pixel")
    return pts


def load_points(path: str | Path) -> dict[str, NDArray[np.float64]]:
    """Read and validate a points file; returns ``{key: (n, 2) array}`` for :data:`LINE_KEYS`."""
    p = Path(path)
    data = read_json(p, "points file", VisionError)
    if not isinstance(data, Mapping):
        raise VisionError(f"points file {p} must hold a JSON object with keys {', '.join(LINE_KEYS)}")
    missing = [k for k in LINE_KEYS if k not in data]
    if missing:
        raise VisionError(f"points file {p} lacks {', '.join(missing)}")
    return {k: _as_points(k, data[k]) for k in LINE_KEYS}


def pose_from_points(
    points: Mapping[str, ArrayLike],
    focal_px: float,
    half_width_m: float,
    principal_point: tuple[float, float],
    *,
    camera_offset_m: tuple[float, float, float] | None = None,
    params: ChainParams | None = None,
) -> RunwayResult:
    """Pose from operator-picked pixel points (see the module docstring for the keys).

    Raises :class:`VisionError` for malformed points or edge points picked above
    the horizon; a set of lines that does not close (edges meeting far from the
    horizon) comes back as ``found=False``.
    """
    missing = [k for k in LINE_KEYS if k not in points]
    if missing:
        raise VisionError(f"missing points for {', '.join(missing)}")
    pts = {k: _as_points(k, points[k]) for k in LINE_KEYS}
    hz = pts["horizon"]
    # the horizon as u -> v; every edge point must lie on the ground side (larger v)
    a, b = np.polyfit(hz[:, 0], hz[:, 1], 1) if float(np.ptp(hz[:, 0])) > 0 else (math.inf, 0.0)
    if not math.isfinite(a):
        raise VisionError("horizon: points must not lie on a vertical line")
    for key in ("left_edge", "right_edge"):
        e = pts[key]
        if np.any(e[:, 1] < a * e[:, 0] + b - 1.0):
            raise VisionError(f"{key}: points must lie below the horizon")
    sets = [(pts[k][:, 0], pts[k][:, 1]) for k in LINE_KEYS]
    return pose_from_point_sets(sets, focal_px, half_width_m, principal_point, camera_offset_m, params)
