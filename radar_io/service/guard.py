"""Hostile pages and oversized requests, refused before any route runs (ASGI middleware).

* **Origin**: a browser page from another origin may neither call the API nor open
  ``/ws/live`` (cross-site websocket hijacking): a request whose ``Origin`` header is
  neither the service's own host (``Host``) nor in ``allowed_origins`` gets 403 (a
  websocket is closed before the handshake completes: HTTP 403). No ``Origin`` header
  = a non-browser client (curl, scripts): allowed.
* **Header size**: all request headers together beyond ``max_header_bytes`` → 431.
* **Body size**: beyond the limit of the path (``Content-Length`` checked at once, a
  chunked body counted while it is read) → 413.
"""

from __future__ import annotations

import json
from collections.abc import Awaitable, Callable, Mapping
from typing import Any
from urllib.parse import urlsplit

Scope = dict[str, Any]
Receive = Callable[[], Awaitable[dict[str, Any]]]
Send = Callable[[dict[str, Any]], Awaitable[None]]


class _BodyTooLarge(Exception):
    pass


def _error(status: int, msg: str, kind: str) -> tuple[dict[str, Any], dict[str, Any]]:
    body = json.dumps({"detail": [{"loc": ["header" if status != 413 else "body"], "msg": msg,
                                   "type": kind}]}).encode()
    start = {"type": "http.response.start", "status": status,
             "headers": [(b"content-type", b"application/json"),
                         (b"content-length", str(len(body)).encode()), (b"connection", b"close")]}
    return start, {"type": "http.response.body", "body": body}


def origin_allowed(origin: str, host: str | None, allowed: frozenset[str]) -> bool:
    """Same host (scheme ignored: a reverse proxy may terminate TLS) or listed."""
    origin = origin.strip().rstrip("/").lower()
    if origin in allowed or "*" in allowed:
        return True
    netloc = urlsplit(origin).netloc
    return bool(netloc) and host is not None and netloc == host.strip().lower()


class GuardMiddleware:
    """Origin check, header and body size limits (see the module doc)."""

    def __init__(self, app: Any, allowed_origins: list[str], max_header_bytes: int,
                 max_body_bytes: int, body_limits: Mapping[str, int] | None = None) -> None:
        self.app = app
        self.allowed = frozenset(o.strip().rstrip("/").lower() for o in allowed_origins)
        self.max_header_bytes = max_header_bytes
        self.max_body_bytes = max_body_bytes
        self.body_limits = dict(body_limits or {})  # exact path → bytes
        self.refused_origin = 0

    def _body_limit(self, path: str) -> int:
        return self.body_limits.get(path.rstrip("/"), self.max_body_bytes)

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        kind = scope["type"]
        if kind not in ("http", "websocket"):
            return await self.app(scope, receive, send)
        headers = scope.get("headers", [])
        size = sum(len(k) + len(v) + 4 for k, v in headers)
        hdr = {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in headers}
        refusal: tuple[int, str, str] | None = None
        if size > self.max_header_bytes:
            refusal = (431, f"request headers are {size} bytes, more than the "
                       f"{self.max_header_bytes} accepted", "request_header_fields_too_large")
        elif "origin" in hdr and not origin_allowed(hdr["origin"], hdr.get("host"), self.allowed):
            self.refused_origin += 1
            refusal = (403, f"Origin {hdr['origin']!r} is not allowed (same host or "
                       "allowed_origins)", "forbidden_origin")
        if refusal is not None:
            if kind == "websocket":
                await receive()  # websocket.connect
                await send({"type": "websocket.close", "code": 1008, "reason": refusal[1][:120]})
                return
            start, body = _error(*refusal)
            await send(start)
            await send(body)
            return
        if kind == "websocket":
            return await self.app(scope, receive, send)
        limit = self._body_limit(scope.get("path", ""))
        try:
            declared = int(hdr.get("content-length", "0") or 0)
        except ValueError:
            declared = 0
        if declared > limit:
            start, body = _error(413, f"request body of {declared} bytes, more than the "
                                 f"{limit} accepted", "payload_too_large")
            await send(start)
            await send(body)
            return
        seen = 0
        started = False

        async def counted_receive() -> dict[str, Any]:
            nonlocal seen
            msg = await receive()
            if msg["type"] == "http.request":
                seen += len(msg.get("body", b""))
                if seen > limit:
                    raise _BodyTooLarge
            return msg

        async def tracked_send(msg: dict[str, Any]) -> None:
            nonlocal started
            if msg["type"] == "http.response.start":
                started = True
            await send(msg)

        try:
            await self.app(scope, counted_receive, tracked_send)
        except _BodyTooLarge:
            if started:
                raise
            start, body = _error(413, f"request body more than the {limit} bytes accepted",
                                 "payload_too_large")
            await send(start)
            await send(body)
