"""Hostile pages and oversized requests, refused before any route runs (ASGI middleware).

* **Host** (DNS rebinding): a page at ``http://rebind.example:8000`` whose name an attacker
  re-points at 127.0.0.1 is same-origin with itself, so the Origin check alone lets it
  read the API. The ``Host`` header must therefore name the service: 127.0.0.1,
  localhost, [::1], the address it is bound to, any IP address when it is bound to all
  interfaces (0.0.0.0 / ::; a rebinding needs a DNS name), or a name in ``allowed_hosts``
  (``"*"`` switches the check off). Otherwise 421 (a websocket is refused before the
  handshake completes: HTTP 421). No ``Host`` (HTTP/1.0 clients) = not a browser: allowed.
* **Origin**: a browser page from another origin may neither call the API nor open
  ``/ws/live`` (cross-site websocket hijacking): a request whose ``Origin`` header is
  neither the service's own, allowed host (``Host``) nor in ``allowed_origins`` gets 403
  (a websocket likewise, before the handshake). No ``Origin`` header = a non-browser
  client (curl, scripts): allowed.
* **Header size**: all request headers together beyond ``max_header_bytes`` → 431.
* **Body size**: beyond the limit of the path (``Content-Length`` checked at once, a
  chunked body counted while it is read) → 413, on every route: the guard answers and the
  route sees the client gone.
"""

from __future__ import annotations

import ipaddress
import json
from collections.abc import Awaitable, Callable, Mapping
from typing import Any
from urllib.parse import urlsplit

Scope = dict[str, Any]
Receive = Callable[[], Awaitable[dict[str, Any]]]
Send = Callable[[dict[str, Any]], Awaitable[None]]


#: Host names always accepted (loopback)
LOOPBACK_HOSTS = frozenset({"127.0.0.1", "localhost", "::1"})
_WILDCARD_BINDS = frozenset({"0.0.0.0", "::", ""})


def _error(status: int, msg: str, kind: str, prefix: str = "http"
           ) -> tuple[dict[str, Any], dict[str, Any]]:
    """The two ASGI messages of an error answer (``prefix`` "websocket.http" for a websocket
    refused before its handshake)."""
    body = json.dumps({"detail": [{"loc": ["header" if status != 413 else "body"], "msg": msg,
                                   "type": kind}]}).encode()
    start = {"type": f"{prefix}.response.start", "status": status,
             "headers": [(b"content-type", b"application/json"),
                         (b"content-length", str(len(body)).encode()), (b"connection", b"close")]}
    return start, {"type": f"{prefix}.response.body", "body": body}


def host_name(authority: str) -> str:
    """The host of a ``Host`` header or URL authority, lower case, port and brackets
    removed (``[::1]:8000`` → ``::1``, ``Radar.local.:80`` → ``radar.local``)."""
    a = authority.strip().lower()
    if a.startswith("["):
        return a[1:a.find("]")] if "]" in a else a[1:]
    if a.count(":") == 1:
        a = a.split(":", 1)[0]
    return a.rstrip(".")


def _is_ip(name: str) -> bool:
    try:
        ipaddress.ip_address(name)
    except ValueError:
        return False
    return True


class HostPolicy:
    """Which ``Host`` names the service answers to (see the module doc)."""

    def __init__(self, allowed_hosts: list[str], bound_host: str = "127.0.0.1") -> None:
        names = {host_name(h) for h in allowed_hosts}
        self.any = "*" in names
        bound = host_name(bound_host)
        self.any_ip = bound in _WILDCARD_BINDS
        self.names = frozenset(LOOPBACK_HOSTS | names | ({bound} - _WILDCARD_BINDS))

    def allows(self, authority: str) -> bool:
        name = host_name(authority)
        return self.any or name in self.names or (self.any_ip and _is_ip(name))


def origin_allowed(origin: str, host: str | None, allowed: frozenset[str],
                   hosts: HostPolicy | None = None) -> bool:
    """Listed, or the same host (scheme ignored: a reverse proxy may terminate TLS) and that
    host allowed by ``hosts``."""
    origin = origin.strip().rstrip("/").lower()
    if origin in allowed or "*" in allowed:
        return True
    netloc = urlsplit(origin).netloc
    return (bool(netloc) and host is not None and netloc == host.strip().lower()
            and (hosts is None or hosts.allows(netloc)))


class GuardMiddleware:
    """Host and Origin checks, header and body size limits (see the module doc)."""

    def __init__(self, app: Any, allowed_origins: list[str], max_header_bytes: int,
                 max_body_bytes: int, body_limits: Mapping[str, int] | None = None,
                 allowed_hosts: list[str] | None = None, bound_host: str = "127.0.0.1") -> None:
        self.app = app
        self.allowed = frozenset(o.strip().rstrip("/").lower() for o in allowed_origins)
        self.hosts = HostPolicy(allowed_hosts or [], bound_host)
        self.max_header_bytes = max_header_bytes
        self.max_body_bytes = max_body_bytes
        self.body_limits = dict(body_limits or {})  # exact path → bytes
        self.refused_origin = 0
        self.refused_host = 0

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
            refusal = (431, (f"request headers are {size} bytes, more than the "
                             f"{self.max_header_bytes} accepted"),
                       "request_header_fields_too_large")
        elif "host" in hdr and not self.hosts.allows(hdr["host"]):
            self.refused_host += 1
            refusal = (421, (f"Host {host_name(hdr['host'])[:100]!r} is not allowed (loopback, "
                             "the bound address or allowed_hosts)"), "host_not_allowed")
        elif "origin" in hdr and not origin_allowed(hdr["origin"], hdr.get("host"), self.allowed,
                                                    self.hosts):
            self.refused_origin += 1
            refusal = (403, (f"Origin {hdr['origin'][:100]!r} is not allowed (same host or "
                             "allowed_origins)"), "forbidden_origin")
        if refusal is not None:
            if kind == "websocket":
                await receive()  # websocket.connect
                if "websocket.http.response" in scope.get("extensions", {}):
                    for msg in _error(*refusal, prefix="websocket.http"):
                        await send(msg)
                else:  # the server answers 403 to a close before accept
                    await send({"type": "websocket.close", "code": 1008,
                                "reason": refusal[1][:120]})
                return
            for msg in _error(*refusal):
                await send(msg)
            return
        if kind == "websocket":
            return await self.app(scope, receive, send)
        limit = self._body_limit(scope.get("path", ""))
        try:
            declared = int(hdr.get("content-length", "0") or 0)
        except ValueError:
            declared = 0
        if declared > limit:
            for msg in _error(413, f"request body of {declared} bytes, more than the "
                              f"{limit} accepted", "payload_too_large"):
                await send(msg)
            return
        seen = 0
        started = False
        # the last body message (more_body false) or a disconnect was seen; only a chunked
        # body can be longer than the limit by now (a declared length was checked above)
        body_done = "chunked" not in hdr.get("transfer-encoding", "").lower()
        refused = False  # the guard answered 413: the route sees a disconnect, its answer goes

        async def counted_receive() -> dict[str, Any]:
            nonlocal seen, refused, body_done
            if refused:
                return {"type": "http.disconnect"}
            msg = await receive()
            if msg["type"] == "http.request":
                seen += len(msg.get("body", b""))
                body_done = not msg.get("more_body", False)
                if seen > limit:  # answer 413 (unless the route already answered) and stop
                    if not started:
                        for m in _error(413, f"request body more than the {limit} bytes "
                                        "accepted", "payload_too_large"):
                            await send(m)
                    refused = True
                    return {"type": "http.disconnect"}
            else:
                body_done = True
            return msg

        async def tracked_send(msg: dict[str, Any]) -> None:
            nonlocal started
            if msg["type"] == "http.response.start" and not refused:
                # a route that answers without reading a chunked body: the rest is read
                # (and dropped) here, so an oversized body is 413 on every route
                while not body_done and not refused:
                    await counted_receive()
                started = not refused
            if not refused:
                await send(msg)

        try:
            await self.app(scope, counted_receive, tracked_send)
        except Exception:
            if not refused:  # a route that fails on the disconnect: already answered 413
                raise
