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


class _Link:
    """What every link shares: its target, record size, open handle and byte count."""

    kind = ""

    def __init__(self, target: str, record_bytes: int) -> None:
        self.target, self.record_bytes = target, record_bytes
        self.handle: Any = None
        self.bytes = 0

    def _handle(self) -> Any:
        if self.handle is None:
            raise UplinkError(f"{self.target} is not open")
        return self.handle

    def close(self) -> None:
        """Release the handle; never raises (closing a dead port or socket)."""
        if self.handle is not None:
            try:
                self.handle.close()
            except Exception:  # noqa: BLE001 - closing a dead link must never raise
                pass
            self.handle = None


class UdpLink(_Link):
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
        super().__init__(target, record_bytes)
        self.addr = (parts.hostname, port)

    def open(self) -> None:
        try:
            family = socket.getaddrinfo(*self.addr, type=socket.SOCK_DGRAM)[0][0]
            self.handle = socket.socket(family, socket.SOCK_DGRAM)
        except OSError as exc:
            raise UplinkError(f"cannot open {self.target}: {exc}") from exc

    def write(self, data: bytes) -> None:
        sock = self._handle()
        n = self.record_bytes or len(data)
        try:
            for k in range(0, len(data), n):
                sock.sendto(data[k:k + n], self.addr)
        except OSError as exc:
            raise UplinkError(f"{self.target}: write failed: {exc}") from exc
        self.bytes += len(data)


class SerialLink(_Link):
    """A serial device or pyserial URL."""

    kind = "serial"

    def open(self) -> None:
        from radar_io.sources.serialport import open_port

        try:
            self.handle = open_port(self.target)
        except SourceError as exc:
            raise UplinkError(str(exc)) from exc

    def write(self, data: bytes) -> None:
        port = self._handle()
        try:
            if data:
                port.write(data)
        except Exception as exc:  # pyserial raises several types
            raise UplinkError(f"{self.target}: write failed: {exc}") from exc
        self.bytes += len(data)


class FileLink(_Link):
    """A file, created or truncated; every write reaches the kernel at once (unbuffered)."""

    kind = "file"

    def open(self) -> None:
        try:
            self.handle = open(self.target, "wb", buffering=0)  # noqa: SIM115 - the link owns it
        except OSError as exc:
            raise UplinkError(f"cannot write {self.target}: {exc.strerror}") from exc

    def write(self, data: bytes) -> None:
        f = self._handle()
        view = memoryview(data)
        try:
            while view:  # a raw file may take fewer bytes than offered
                view = view[f.write(view):]
        except OSError as exc:
            raise StorageError(f"{self.target}: write failed: {exc.strerror}",
                               errno=exc.errno) from exc
        self.bytes += len(data)


def make_link(target: str, record_bytes: int) -> UdpLink | SerialLink | FileLink:
    """The link for ``target`` (not yet opened); a malformed URL is refused here."""
    from radar_io.sources.serialport import is_serial_target

    if target.startswith("udp://"):
        return UdpLink(target, record_bytes)
    if is_serial_target(target):
        return SerialLink(target, record_bytes)
    return FileLink(target, record_bytes)
