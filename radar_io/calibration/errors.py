"""Errors of the calibration toolkit."""

from __future__ import annotations

from ..errors import RadarIOError


class CalibrationError(RadarIOError):
    """A calibration computation cannot give a trustworthy result (degenerate or diverging input)."""


class CalibrationInputError(CalibrationError):
    """A calibration input file or argument is missing or malformed (names file, line and column)."""
