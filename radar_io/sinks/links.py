"""Byte links: where encoded records go.

``target`` forms (:func:`make_link`):

* ``udp://HOST:PORT`` — one datagram per record (one TLM1 frame, one D/A sample, one
  ASTERIX data block);
* a serial device or pyserial URL (``/dev/ttyS0``, ``loop://``, ``socket://…``,
  ``?baudrate=…``; see :func:`radar_io.sources.serialport.open_port`);
* anything else — a file, created or truncated.
"""

from __future__ import annotations

import socket
import urllib.parse
from typing import Any

from radar_io.errors import SourceError, StorageError, UplinkError


class UdpLink:
    """One datagram per record of ``record_bytes`` (0: one datagram per write)."""

    kind = "udp"

    def __init__(self, target: str, record_bytes: int) -> None:
        parts = urllib.parse.urlsplit(target)
        try:
            port = parts.port
        except ValueError:
            port = None
        if not parts.hostname or port is None:
            raise UplinkError(f"{target}: expected udp://HOST:PORT")
        self.target, self.record_bytes = target, record_bytes
        self.addr = (parts.hostname, port)
        self.handle: Any = None
        self.bytes = 0

    def open(self) -> None:
        try:
            family = socket.getaddrinfo(*self.addr, type=socket.SOCK_DGRAM)[0][0]
            self.handle = socket.socket(family, socket.SOCK_DGRAM)
        except OSError as exc:
            raise UplinkError(f"cannot open {self.target}: {exc}") from exc

    def write(self, data: bytes) -> None:
        if self.handle is None:
            raise UplinkError(f"{self.target} is not open")
        n = self.record_bytes or len(data)
        try:
            for k in range(0, len(data), n):
                self.handle.sendto(data[k:k + n], self.addr)
        except OSError as exc:
            raise UplinkError(f"{self.target}: write failed: {exc}") from exc
        self.bytes += len(data)

    def close(self) -> None:
        if self.handle is not None:
            self.handle.close()
            self.handle = None


class SerialLink:
    """A serial device or pyserial URL."""

    kind = "serial"

    def __init__(self, target: str, record_bytes: int) -> None:
        self.target, self.record_bytes = target, record_bytes
        self.handle: Any = None
        self.bytes = 0

    def open(self) -> None:
        from radar_io.sources.serialport import open_port

        try:
            self.handle = open_port(self.target)
        except SourceError as exc:
            raise UplinkError(str(exc)) from exc

    def write(self, data: bytes) -> None:
        if self.handle is None:
            raise UplinkError(f"{self.target} is not open")
        try:
            if data:
                self.handle.write(data)
        except Exception as exc:  # noqa: BLE001 - pyserial raises several types
            raise UplinkError(f"{self.target}: write failed: {exc}") from exc
        self.bytes += len(data)

    def close(self) -> None:
        if self.handle is not None:
            try:
                self.handle.close()
            except Exception:  # noqa: BLE001 - closing a dead port must never raise
                pass
            self.handle = None


class FileLink:
    """A file, created or truncated; every write reaches the kernel at once (unbuffered)."""

    kind = "file"

    def __init__(self, target: str, record_bytes: int) -> None:
        self.target, self.record_bytes = target, record_bytes
        self.handle: Any = None
        self.bytes = 0

    def open(self) -> None:
        try:
            self.handle = open(self.target, "wb", buffering=0)
        except OSError as exc:
            raise UplinkError(f"cannot write {self.target}: {exc.strerror}") from exc

    def write(self, data: bytes) -> None:
        if self.handle is None:
            raise UplinkError(f"{self.target} is not open")
        view = memoryview(data)
        try:
            while view:  # a raw file may take fewer bytes than offered
                view = view[self.handle.write(view):]
        except OSError as exc:
            raise StorageError(f"{self.target}: write failed: {exc.strerror}",
                               errno=exc.errno) from exc
        self.bytes += len(data)

    def close(self) -> None:
        if self.handle is not None:
            try:
                self.handle.close()
            except OSError:
                pass
            self.handle = None


def make_link(target: str, record_bytes: int) -> UdpLink | SerialLink | FileLink:
    """The link for ``target`` (not yet opened); a malformed URL is refused here."""
    from radar_io.sources.serialport import is_serial_target

    if target.startswith("udp://"):
        return UdpLink(target, record_bytes)
    if is_serial_target(target):
        return SerialLink(target, record_bytes)
    return FileLink(target, record_bytes)
