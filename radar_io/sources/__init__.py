"""Byte sources, chosen by URL scheme (like pyserial's ``serial_for_url`` and python-can's
``BACKENDS``).

:data:`SOURCES` maps a scheme to ``"module:factory"``; the module is imported only when
a URL with that scheme is opened. A URL whose scheme is not in the registry (a device
path such as ``/dev/ttyUSB0?baudrate=115200`` or a pyserial URL such as ``loop://``,
``socket://host:port``, ``rfc2217://…``) goes to :data:`DEFAULT_SOURCE`, the serial port.
Any other scheme (``foo://x``) is a mistake, refused at once (:func:`check_source_url`)
rather than retried for ever.

A new source is one module implementing :class:`~radar_io.sources.base.ByteSource` and
one line here.
"""

from __future__ import annotations

import importlib
from typing import Any

from radar_io.errors import ConfigError, SourceError
from radar_io.sources.base import ByteSource

#: scheme → "module:callable(url) -> ByteSource"
SOURCES: dict[str, str] = {
    "sim": "radar_io.sources.sim:SimSource",
    "replay": "radar_io.sources.replay:replay_from_url",
}
#: everything else: serial devices and pyserial URLs
DEFAULT_SOURCE = "radar_io.sources.serialport:SerialSource"


def _load(target: str) -> Any:
    module, _, name = target.partition(":")
    return getattr(importlib.import_module(module), name)


def scheme_of(url: str) -> str:
    """The part before ``:`` when it looks like a URL scheme, else ``""``."""
    head, sep, _ = url.partition(":")
    return head.lower() if sep and head.isidentifier() else ""


def source_kind(url: str) -> str:
    """What kind of data a source URL gives: ``"sim"`` (the simulator), ``"replay"`` (a
    recording played back) or ``"serial"`` (a device or any pyserial URL: the radar)."""
    scheme = scheme_of(url)
    return scheme if scheme in ("sim", "replay") else "serial"


def _pyserial_protocol(scheme: str) -> bool:
    """Whether pyserial has a URL handler for ``scheme`` (serial/urlhandler/protocol_*.py)."""
    import importlib.util

    try:
        return importlib.util.find_spec(f"serial.urlhandler.protocol_{scheme}") is not None
    except ImportError:
        return False


def check_source_url(url: str) -> None:
    """ConfigError for a URL scheme that is neither registered (:data:`SOURCES`) nor a
    pyserial protocol (loop, socket, rfc2217, spy, hwgrep, alt, cp2110); a plain path (no
    scheme) is a serial device."""
    scheme = scheme_of(url)
    if scheme and scheme not in SOURCES and not _pyserial_protocol(scheme):
        raise ConfigError(f"source {url.split('?', 1)[0][:80]!r}: unknown URL scheme "
                          f"{scheme!r} (known: {', '.join(sorted(SOURCES))}, a pyserial URL "
                          "such as loop://, socket://, rfc2217://, or a device path)")


def open_source(url: str) -> ByteSource:
    """The source for ``url`` (not yet opened). Raises SourceError for an empty URL,
    ConfigError for an unknown scheme."""
    if not url:
        raise SourceError("empty source URL")
    check_source_url(url)
    factory = _load(SOURCES.get(scheme_of(url), DEFAULT_SOURCE))
    return factory(url)


__all__ = ["DEFAULT_SOURCE", "SOURCES", "ByteSource", "check_source_url", "open_source",
           "scheme_of", "source_kind"]
