"""Errors of the uplink outputs (telemetry and D/A recorder words)."""

from __future__ import annotations

from ..errors import RadarIOError


class UplinkError(RadarIOError):
    """An uplink output cannot be produced: a source column is missing, a sink cannot be opened."""
