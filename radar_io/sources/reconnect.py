"""Keep a byte source connected: open, read, and on any failure close and reopen with
back-off (0.1 s doubling to 5 s, reset once data flows again).

Used by the service's reader thread and by ``radar-io monitor``: a yanked cable or a
closed pty is a disconnect, never an exit.
"""

from __future__ import annotations

import logging
import threading

from radar_io.sources.base import ByteSource

log = logging.getLogger("radar_io.sources")


def describe(exc: BaseException) -> str:
    """One line for a failure: our own errors by their message, others with their type."""
    from radar_io.errors import RadarIOError

    return str(exc) if isinstance(exc, RadarIOError) else f"{type(exc).__name__}: {exc}"


class ReconnectingSource:
    """A :class:`~radar_io.sources.base.ByteSource` that never raises from :meth:`read`.

    ``read`` returns the bytes that arrived, or ``b""`` after a time-out or a failed
    (re)connection attempt, having waited the back-off (interrupted by ``stop``).
    ``connected``, ``reconnects`` and ``last_error`` describe the link.
    """

    def __init__(self, source: ByteSource, backoff_s: tuple[float, float] = (0.1, 5.0),
                 stop: threading.Event | None = None) -> None:
        self.source = source
        self.backoff_s = backoff_s
        self.stop = stop or threading.Event()
        self.connected = False
        self.reconnects = 0
        self.last_error: str | None = None
        self._delay = backoff_s[0]

    @property
    def url(self) -> str:
        return self.source.url

    def _down(self, exc: BaseException, logged: bool = False) -> None:
        why = describe(exc)
        if not logged and (self.connected or self.last_error != why):
            log.warning("source %s: %s", self.source.url, why)
        self.connected = False
        self.last_error = why
        self.stop.wait(self._delay)  # a port that opens but cannot be read must not spin
        self._delay = min(self._delay * 2, self.backoff_s[1])

    def read(self, timeout_s: float) -> bytes:
        if not self.connected:
            try:
                self.source.open()
            except Exception as exc:  # noqa: BLE001 - SourceError, OSError, driver bugs
                self._down(exc)
                return b""
            self.connected = True
            log.info("source %s open", self.source.url)
        try:
            data = self.source.read(timeout_s)
        except Exception as exc:  # noqa: BLE001
            # the reason first: a status read meanwhile never shows a drop without it
            self.last_error = describe(exc)
            log.warning("source %s: %s", self.source.url, self.last_error)
            self.close()
            self.reconnects += 1
            self._down(exc, logged=True)
            return b""
        if data:
            self._delay = self.backoff_s[0]
            self.last_error = None
        return data

    def close(self) -> None:
        """Close the source (never raises); the next read reopens it."""
        try:
            self.source.close()
        except Exception:  # closing a dead source must never stop the reader
            log.exception("closing %s failed", self.source.url)
        self.connected = False
