"""The airborne recorder on CAN (radar-interface.md §9): DBC layout, python-can driver and
recorder, aircraft simulator, and time alignment to the radar's SYNC edges."""

from __future__ import annotations

from .align import ClockFit, RadarTrack, align_files, compare_altitude, fit_clock, radar_track, read_radar_track
from .canbus import CanRecorder, open_bus
from .dbc import AircraftLog, decode_messages, load_dbc, read_can_log
from .errors import AirborneError
from .sim import AircraftConfig, AircraftSimulator, expected_pa_minus_h, qnh_height_m

__all__ = ["AircraftConfig", "AircraftLog", "AircraftSimulator", "AirborneError", "CanRecorder",
           "ClockFit", "RadarTrack", "align_files", "compare_altitude", "decode_messages",
           "expected_pa_minus_h", "fit_clock", "load_dbc", "open_bus", "qnh_height_m",
           "radar_track", "read_can_log", "read_radar_track"]
