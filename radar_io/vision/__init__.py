"""Runway vision: aircraft attitude, height and lateral offset from a nose-camera runway image.

Implements spec ``runway-vision.md``:

* :mod:`~radar_io.vision.pose_equations` — the pure, vectorised maths (§1–§3);
* :mod:`~radar_io.vision.chain` — the OpenCV image chain (§4): :func:`find_runway`,
  :class:`RunwayTracker` for sequences;
* :mod:`~radar_io.vision.manual` — the pose from operator-picked points;
* :mod:`~radar_io.vision.synth` — forward projector and synthetic image renderer;
* :mod:`~radar_io.benchmarks.runway` — the chain's frame-rate benchmark;
* :mod:`~radar_io.cli.runway` — the ``radar-io runway`` sub-command.

Names are imported lazily so that importing the package (which the main CLI does
for every command) does not load OpenCV.
"""

from __future__ import annotations

import importlib
from typing import Any

from radar_io.errors import VisionError

_LAZY = {
    "ChainParams": "chain",
    "RunwayResult": "chain",
    "RunwayTracker": "chain",
    "find_runway": "chain",
    "pose_from_pixel_lines": "chain",
    "pose_from_point_sets": "chain",
    "load_points": "manual",
    "pose_from_points": "manual",
    "solve_pose": "geometry",
    "RunwayPose": "synth",
    "RunwayScene": "synth",
    "render_runway": "synth",
    "bench_runway": "bench",
}

__all__ = ["VisionError", *sorted(_LAZY)]  # noqa: PLE0604 - the keys of _LAZY are names


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
