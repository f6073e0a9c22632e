"""TLM1 telemetry frames (radar-interface.md §8) and D/A recorder words (§7) as sinks:
an encoder in front of a byte link (file, serial URL, ``udp://HOST:PORT``)."""

from __future__ import annotations

from radar_io.encoding.da import DAEncoder
from radar_io.encoding.tlm1 import TelemetryEncoder
from radar_io.sinks.base import EncoderSink


class TelemetrySink(EncoderSink):
    """TLM1 frames of measurement batches; one UDP datagram per frame."""

    def __init__(self, target: str, encoder: TelemetryEncoder | None = None) -> None:
        encoder = encoder or TelemetryEncoder()
        super().__init__(target, encoder, encoder.spec.length)


class DASink(EncoderSink):
    """D/A recorder words (big-endian u16) of measurement batches; one datagram per sample."""

    def __init__(self, target: str, encoder: DAEncoder | None = None) -> None:
        encoder = encoder or DAEncoder()
        super().__init__(target, encoder, 2 * len(encoder.spec.channels))
