"""radar_io: ground tracking radar and airborne recorder interface for flight test."""

from __future__ import annotations

__version__ = "0.1.0"

from .calibration_set import Calibration, load_calibration, save_calibration
from .decoding import MeasurementBatch, decode_bytes
from .errors import (
    ConfigError,
    EncodeError,
    RadarIOError,
    RecordingError,
    SourceError,
    SpecError,
)

__all__ = [
    "Calibration",
    "MeasurementBatch",
    "decode_bytes",
    "ConfigError",
    "EncodeError",
    "RadarIOError",
    "RecordingError",
    "SourceError",
    "SpecError",
    "load_calibration",
    "save_calibration",
    "__version__",
]
