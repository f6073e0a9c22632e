"""Where uplink bytes go: a serial port / pyserial URL, a UDP address or a file.

``target`` forms (:func:`open_byte_sink`):

* ``udp://HOST:PORT`` — one datagram per record (one TLM1 frame, one D/A sample);
* a pyserial device or URL (``/dev/ttyS0``, ``loop://``, ``socket://…``,
  ``?baudrate=…``; see :func:`radar_io.sources.serial_sim_replay.open_port`);
* anything else — a file, created or truncated.

:class:`TelemetrySink` and :class:`DASink` pair a sink with an encoder:
``sink.send(batch)`` encodes and writes one measurement batch.
"""

from __future__ import annotations

import socket
import urllib.parse
from collections.abc import Mapping
from typing import Any

import numpy as np

from radar_io.errors import SourceError
from radar_io.sources.serial_sim_replay import is_serial_target, open_port
from radar_io.encoding.da import DAEncoder
from radar_io.errors import UplinkError
from radar_io.encoding.tlm1 import TelemetryEncoder


class ByteSink:
    """A byte destination; :attr:`handle` is the open serial port, socket or file."""

    def __init__(self, target: str, record_bytes: int) -> None:
        self.target, self.record_bytes = target, record_bytes
        self.bytes = 0
        self._udp: tuple[str, int] | None = None
        if target.startswith("udp://"):
            parts = urllib.parse.urlsplit(target)
            try:
                port = parts.port
            except ValueError:
                port = None
            if not parts.hostname or port is None:
                raise UplinkError(f"{target}: expected udp://HOST:PORT")
            self._udp = (parts.hostname, port)
            try:
                family = socket.getaddrinfo(parts.hostname, port, type=socket.SOCK_DGRAM)[0][0]
                self.handle: Any = socket.socket(family, socket.SOCK_DGRAM)
            except OSError as exc:
                raise UplinkError(f"cannot open {target}: {exc}") from None
            self.kind = "udp"
        elif is_serial_target(target):

            try:
                self.handle = open_port(target)
            except SourceError as exc:
                raise UplinkError(str(exc)) from None
            self.kind = "serial"
        else:
            try:  # unbuffered: every write (whole records) reaches the file at once
                self.handle = open(target, "wb", buffering=0)
            except OSError as exc:
                raise UplinkError(f"cannot write {target}: {exc.strerror}") from None
            self.kind = "file"

    def write(self, data: bytes) -> None:
        """Write whole records (UDP: one datagram each)."""
        try:
            if self._udp is not None:
                n = self.record_bytes
                for k in range(0, len(data), n):
                    self.handle.sendto(data[k:k + n], self._udp)
            elif self.kind == "file":
                view = memoryview(data)
                while view:  # a raw file may take fewer bytes than offered
                    view = view[self.handle.write(view):]
            elif data:
                self.handle.write(data)
        except Exception as exc:  # noqa: BLE001 - serial, socket and file errors alike
            raise UplinkError(f"{self.target}: write failed: {exc}") from None
        self.bytes += len(data)

    def close(self) -> None:
        try:
            self.handle.close()
        except Exception:  # noqa: BLE001 - closing a dead port must never raise
            pass


class _EncodingSink:
    def __init__(self, target: str, encoder: Any, record_bytes: int) -> None:
        self.encoder = encoder
        self.sink = ByteSink(target, record_bytes)

    def send(self, batch: Mapping[str, np.ndarray]) -> int:
        """Encode one MeasurementBatch and write it; returns the bytes written."""
        data = self.encoder.encode_batch(batch)
        self.sink.write(data)
        return len(data)

    def close(self) -> None:
        self.sink.close()

    def __enter__(self) -> Any:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class TelemetrySink(_EncodingSink):
    """TLM1 frames of measurement batches to a serial URL, ``udp://HOST:PORT`` or a file."""

    def __init__(self, target: str, encoder: TelemetryEncoder | None = None) -> None:
        encoder = encoder or TelemetryEncoder()
        super().__init__(target, encoder, encoder.spec.length)


class DASink(_EncodingSink):
    """D/A recorder words (big-endian u16) of measurement batches to a serial URL or a file."""

    def __init__(self, target: str, encoder: DAEncoder | None = None) -> None:
        encoder = encoder or DAEncoder()
        super().__init__(target, encoder, 2 * len(encoder.spec.channels))
