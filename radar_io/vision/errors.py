"""Errors of the runway-vision package."""

from __future__ import annotations

from ..errors import RadarIOError

__all__ = ["VisionError"]


class VisionError(RadarIOError):
    """Bad input to runway vision: missing/unreadable image or video, bad camera parameters, bad points file."""
