"""Errors of the airborne recorder tools."""

from __future__ import annotations

from ..errors import RadarIOError


class AirborneError(RadarIOError):
    """A CAN bus, CAN log, DBC file or time alignment problem (one clear line)."""
