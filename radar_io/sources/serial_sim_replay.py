"""Byte sources behind one small interface, chosen by URL (like pyserial's ``serial_for_url``).

* ``sim://?rate_hz=1000&seed=1&flip_rate=0&…`` — the built-in radar simulator, paced in real time;
* ``replay://PATH.rdrlog?speed=1.0`` — a recording, paced by its receive timestamps;
* anything else — a serial device or any pyserial URL (``/dev/ttyUSB0``, ``loop://``,
  ``socket://host:port``, ``rfc2217://…``) with ``?baudrate=…`` etc.

A source's :meth:`read` returns the bytes that arrived (``b""`` on time-out)
and raises :class:`~radar_io.errors.SourceError` when the link is gone; the
caller reopens it with back-off.
"""

from __future__ import annotations

import os
import time
import urllib.parse
from dataclasses import fields
from typing import Any, Protocol

from radar_io.errors import SourceError


class ByteSource(Protocol):
    url: str

    def open(self) -> None: ...
    def read(self, timeout_s: float) -> bytes: ...
    def close(self) -> None: ...


def _query(url: str) -> tuple[urllib.parse.SplitResult, dict[str, str]]:
    parts = urllib.parse.urlsplit(url)
    return parts, {k: v[-1] for k, v in urllib.parse.parse_qs(parts.query).items()}


def _typed(cls: type, params: dict[str, str], url: str) -> dict[str, Any]:
    """Convert query parameters to the types of ``cls``'s dataclass fields."""
    out: dict[str, Any] = {}
    known = {f.name: f for f in fields(cls)}
    for k, v in params.items():
        if k not in known:
            raise SourceError(f"{url}: unknown parameter {k!r}")
        default = getattr(cls(), k)
        try:
            if isinstance(default, bool):
                out[k] = v.lower() in ("1", "true", "yes", "on")
            elif isinstance(default, int):
                out[k] = int(v)
            else:
                out[k] = float(v)
        except ValueError:
            raise SourceError(f"{url}: parameter {k}={v!r} is not a number") from None
    return out


class SimSource:
    """The radar simulator as a real-time byte source (loops the flight forever by default)."""

    def __init__(self, url: str = "sim://") -> None:
        from radar_io.simulation.radar import FlightScript, RadarSimulator, SimConfig

        self.url = url
        _, q = _query(url)
        script_keys = {f.name for f in fields(FlightScript)}
        sq = {k: v for k, v in q.items() if k in script_keys}
        cq = {k: v for k, v in q.items() if k not in script_keys}
        cfg = SimConfig(loop=True, **_typed(SimConfig, cq, url))
        self.sim = RadarSimulator(FlightScript(**_typed(FlightScript, sq, url)), cfg)
        self._t0: float | None = None
        self._sent = 0

    def open(self) -> None:
        self._t0 = time.monotonic()
        self._sent = 0

    def read(self, timeout_s: float) -> bytes:
        if self._t0 is None:
            raise SourceError("sim source is not open")
        rate = self.sim.cfg.rate_hz
        due = int((time.monotonic() - self._t0) * rate) - self._sent
        if due <= 0:
            wait = min(timeout_s, (self._sent + 1) / rate - (time.monotonic() - self._t0))
            if wait > 0:
                time.sleep(wait)
            due = int((time.monotonic() - self._t0) * rate) - self._sent
            if due <= 0:
                return b""
        due = min(due, int(rate))  # never more than a second's worth at once
        data, _ = self.sim.generate(due)
        self._sent += due
        return self.sim.corrupt(data)

    def close(self) -> None:
        self._t0 = None


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
        except ValueError:
            raise SourceError(f"{url}: {k}={v!r} is not valid") from None
    target = base + ("?" + urllib.parse.urlencode(rest) if rest else "")
    try:
        port = serial.serial_for_url(target, do_not_open=True)
        for k, v in setup.items():
            setattr(port, k, v)
        port.timeout = timeout_s
        port.open()
    except (serial.SerialException, OSError, ValueError) as exc:
        raise SourceError(f"cannot open {url}: {exc}") from None
    return port


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
            raise SourceError(f"{self.url}: read failed: {exc}") from None

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


class ReplaySource:
    """A ``.rdrlog`` played back at ``speed`` × its recorded pace (``speed=0``: as fast as possible)."""

    def __init__(self, url: str) -> None:
        parts, q = _query(url)
        self.url = url
        self.path = urllib.parse.unquote(parts.netloc + parts.path)
        try:
            self.speed = float(q.get("speed", "1.0"))
        except ValueError:
            raise SourceError(f"{url}: speed must be a number") from None
        if self.speed < 0:
            raise SourceError(f"{url}: speed must be >= 0")
        self._it: Any = None
        self.finished = False

    def open(self) -> None:
        from radar_io.recording.rdrlog import RecordingReader

        self._reader = RecordingReader(self.path)
        self._it = iter(self._reader)
        self._t0_rec: int | None = None
        self._t0 = time.monotonic()
        self.finished = False

    def read(self, timeout_s: float) -> bytes:
        if self._it is None:
            raise SourceError(f"{self.url} is not open")
        chunk = next(self._it, None)
        if chunk is None:
            self.finished = True
            time.sleep(timeout_s)
            return b""
        if self._t0_rec is None:
            self._t0_rec = chunk.t_ns
        if self.speed > 0:
            due = self._t0 + (chunk.t_ns - self._t0_rec) / 1e9 / self.speed
            delay = due - time.monotonic()
            if delay > 0:
                time.sleep(delay)
        return chunk.data

    def close(self) -> None:
        if self._it is not None:
            self._reader.close()
            self._it = None


def open_source(url: str) -> ByteSource:
    """The source for a URL (not yet opened). Raises SourceError for an unknown scheme."""
    if not url:
        raise SourceError("empty source URL")
    if url.startswith("sim:"):
        return SimSource(url)
    if url.startswith("replay:"):
        return ReplaySource(url)
    return SerialSource(url)
