"""The byte-source interface and the URL helpers every source module shares."""

from __future__ import annotations

import urllib.parse
from dataclasses import fields
from typing import Any, Protocol, runtime_checkable

from radar_io.errors import SourceError


@runtime_checkable
class ByteSource(Protocol):
    """Where raw radar bytes come from.

    ``open()`` connects (raises :class:`~radar_io.errors.SourceError` when it cannot),
    ``read(timeout_s)`` returns the bytes that arrived (``b""`` on time-out) and raises
    ``SourceError`` when the link is gone, ``close()`` never raises. The service's reader
    reopens a failed source with back-off (0.1 s doubling to 5 s).
    """

    url: str

    def open(self) -> None: ...
    def read(self, timeout_s: float) -> bytes: ...
    def close(self) -> None: ...


def parse_query(url: str) -> tuple[urllib.parse.SplitResult, dict[str, str]]:
    """The split URL and its query parameters (last value wins)."""
    parts = urllib.parse.urlsplit(url)
    return parts, {k: v[-1] for k, v in urllib.parse.parse_qs(parts.query).items()}


def typed_params(cls: type, params: dict[str, str], url: str) -> dict[str, Any]:
    """Query parameters converted to the types of dataclass ``cls``'s fields."""
    out: dict[str, Any] = {}
    known = {f.name for f in fields(cls)}
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
        except ValueError as exc:
            raise SourceError(f"{url}: parameter {k}={v!r} is not a number") from exc
    return out
