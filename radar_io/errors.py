"""The radar_io exception hierarchy.

Every error radar_io raises on purpose derives from :class:`RadarIOError`, so a
caller (the CLI, the service) can catch one type and print one clear line.
"""

from __future__ import annotations


class RadarIOError(Exception):
    """Base class of every error radar_io raises deliberately."""


class SpecError(RadarIOError):
    """A firmware spec file (``firmware_specs/*.toml``) is missing, malformed or inconsistent."""


class ConfigError(RadarIOError):
    """A site, calibration or other configuration file is missing or malformed."""


class RecordingError(RadarIOError):
    """A recording (``.rdrlog``) cannot be opened, written or parsed."""


class SourceError(RadarIOError):
    """A byte source (serial port, simulator, replay) cannot be opened or read."""


class EncodeError(RadarIOError):
    """A value cannot be encoded into a wire word (out of range for its field)."""
