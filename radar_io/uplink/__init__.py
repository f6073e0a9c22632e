"""Outputs to the aircraft and the recorders: TLM1 telemetry (radar-interface.md §8) and
D/A recorder words (§7), with the ground speed / track kinematics they need."""

from __future__ import annotations

from .da import DAEncoder, DASpec, DAWords, decode_da_words, load_da_spec
from .errors import UplinkError
from .kinematics import KINEMATIC_COLUMNS, Kinematics
from .sinks import ByteSink, DASink, TelemetrySink
from .tlm import TelemetryDecoder, TelemetryEncoder, TelemetrySpec, load_tlm_spec

__all__ = ["ByteSink", "DAEncoder", "DASink", "DASpec", "DAWords", "KINEMATIC_COLUMNS",
           "Kinematics", "TelemetryDecoder", "TelemetryEncoder", "TelemetrySink", "TelemetrySpec",
           "UplinkError", "decode_da_words", "load_da_spec", "load_tlm_spec"]
