"""The radar_io exception tree.

Every error radar_io raises on purpose derives from :class:`RadarIOError`, so a
caller (the CLI, the service) can catch one type and print one clear line. The
branches say what kind of trouble it is, and the service answers by branch:

* :class:`ValidationError` — bad input: a file, a field, a request (HTTP 422;
  CLI exit code 2);
* :class:`NotFoundError` — the thing asked for does not exist (404);
* :class:`ConflictError` — the request clashes with the current state (409);
* :class:`UnavailableError` — a device, link or peer is not there right now:
  :class:`SourceError`, :class:`UplinkError` (503);
* :class:`StorageError` — the disk refused a write (no space: 507).

Wrapping code chains the cause (``raise ... from exc``).
"""

from __future__ import annotations


class RadarIOError(Exception):
    """Base class of every error radar_io raises deliberately."""


# --- bad input ---------------------------------------------------------------------------
class ValidationError(RadarIOError):
    """Bad input: a file, a field or a request cannot be used as given."""


class ConfigError(ValidationError):
    """A site, calibration, path, service config or other configuration file is malformed."""


class SpecError(ValidationError):
    """A firmware spec file (``firmware_specs/*``) is missing, malformed or inconsistent."""


class FrameError(ValidationError):
    """A frame or wire word cannot be built or parsed."""


class EncodeError(FrameError):
    """A value cannot be encoded into a wire word (out of range for its field)."""


class RecordingError(ValidationError):
    """A recording (``.rdrlog``) cannot be opened or parsed."""


class CalibrationError(ValidationError):
    """A calibration computation cannot give a trustworthy result (degenerate or diverging input)."""


class CalibrationInputError(CalibrationError):
    """A calibration input file or argument is missing or malformed (names file, line and column)."""


class VisionError(ValidationError):
    """Bad input to runway vision: unreadable image or video, bad camera parameters, bad points."""


class AirborneError(ValidationError):
    """A CAN log, DBC file or time-alignment problem."""


# --- state --------------------------------------------------------------------------------
class NotFoundError(RadarIOError):
    """The recording, job or other resource asked for does not exist."""


class ConflictError(RadarIOError):
    """The request clashes with the current state (already recording, nothing to replay, ...)."""


# --- peers and devices --------------------------------------------------------------------
class UnavailableError(RadarIOError):
    """A device, link or peer is not there right now; trying again later may work."""


class SourceError(UnavailableError):
    """A byte source (serial port, simulator, replay, CAN bus) cannot be opened or read."""


class UplinkError(UnavailableError):
    """An output link (TLM1, D/A, a publisher) cannot be opened or written."""


class StorageError(RadarIOError):
    """The disk refused a write or an fsync (no space, read-only, I/O error)."""

    def __init__(self, message: str, *, errno: int | None = None) -> None:
        super().__init__(message)
        self.errno = errno
