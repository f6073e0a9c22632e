"""Serial devices and every pyserial URL (``/dev/ttyUSB0?baudrate=115200``, ``loop://``,
``socket://host:port``, ``rfc2217://…``): the default source for a URL with no scheme of
our own.

FTDI-style USB adapters hold received bytes up to their latency timer (16 ms by default)
before sending them to the host: the port is opened in low-latency mode where the driver
supports it (``deploy/99-radar.rules`` also sets the FTDI ``latency_timer`` to 1 ms)."""

from __future__ import annotations

import logging
import os
import urllib.parse
from typing import Any

from radar_io.errors import SourceError

log = logging.getLogger("radar_io.sources")

#: query parameters that set up the port (the rest stay with pyserial's URL handler)
_PORT_KEYS = {"baudrate": int, "bytesize": int, "stopbits": float, "parity": str,
              "rtscts": bool, "xonxoff": bool, "dsrdtr": bool}


def is_serial_target(target: str) -> bool:
    """True for a pyserial URL or a terminal device (serial port, pty), with or without a
    ``?baudrate=…`` query; False for files, ``/dev/null``, pipes."""
    if "://" in target:
        return True
    try:
        fd = os.open(target.split("?", 1)[0], os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK)
    except OSError:
        return False
    try:
        return os.isatty(fd)
    finally:
        os.close(fd)


def open_port(url: str, timeout_s: float = 0.05) -> Any:
    """An open pyserial port for a device path or pyserial URL with ``?baudrate=…`` etc."""
    import serial

    base, _, query = url.partition("?")
    pairs = urllib.parse.parse_qsl(query)
    setup: dict[str, Any] = {"baudrate": 115200}
    rest = []
    for k, v in pairs:
        typ = _PORT_KEYS.get(k)
        if typ is None:
            rest.append((k, v))
            continue
        try:
            if typ is bool:
                setup[k] = v.lower() in ("1", "true", "yes", "on")
            elif k == "parity":
                setup[k] = v.upper()[:1]
            else:
                setup[k] = typ(v)
        except ValueError as exc:
            raise SourceError(f"{url}: {k}={v!r} is not valid") from exc
    target = base + ("?" + urllib.parse.urlencode(rest) if rest else "")
    try:
        port = serial.serial_for_url(target, do_not_open=True)
        for k, v in setup.items():
            setattr(port, k, v)
        port.timeout = timeout_s
        port.open()
    except (serial.SerialException, OSError, ValueError) as exc:
        raise SourceError(f"cannot open {url}: {exc}") from exc
    request_low_latency(port, url)
    return port


def request_low_latency(port: Any, url: str) -> bool:
    """Ask the driver for low-latency reads (ASYNC_LOW_LATENCY; pyserial on Linux).

    True when granted. A port or platform without it (a pty, ``loop://``, ``socket://``,
    Windows) is not an error: one log line says so and the port is used as it is.
    """
    setter = getattr(port, "set_low_latency_mode", None)
    if setter is None:
        log.info("serial %s: low-latency mode not available for this port type", url)
        return False
    try:
        setter(True)
    except (ValueError, OSError, NotImplementedError) as exc:
        log.info("serial %s: low-latency mode not set (%s)", url, exc)
        return False
    log.info("serial %s: low-latency mode on", url)
    return True


class SerialSource:
    """A serial device or pyserial URL."""

    def __init__(self, url: str) -> None:
        self.url = url
        self._port: Any = None

    def open(self) -> None:
        self._port = open_port(self.url)

    def read(self, timeout_s: float) -> bytes:
        import serial

        port = self._port
        if port is None:
            raise SourceError(f"{self.url} is not open")
        try:
            port.timeout = timeout_s
            first = port.read(1)
            if not first:
                return b""
            waiting = port.in_waiting
            return first + (port.read(waiting) if waiting else b"")
        except (serial.SerialException, OSError, TypeError, AttributeError) as exc:
            raise SourceError(f"{self.url}: read failed: {exc}") from exc

    def write(self, data: bytes) -> None:
        """For loopback tests and the simulator's serial output."""
        if self._port is None:
            raise SourceError(f"{self.url} is not open")
        self._port.write(data)

    def close(self) -> None:
        if self._port is not None:
            try:
                self._port.close()
            except Exception:  # noqa: BLE001 - closing a dead port must never raise
                pass
            self._port = None
