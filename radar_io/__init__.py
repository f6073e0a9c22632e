"""radar_io: ground tracking radar and airborne recorder interface for flight test."""

from __future__ import annotations

__version__ = "0.1.0"

from radar_io.decoding.biases import Calibration, load_calibration, save_calibration
from radar_io.decoding.decoders import MeasurementBatch, decode_bytes
from radar_io.errors import (
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
