"""The audit trail: one record per control request, allowed or refused.

The role dependency (:func:`~radar_io.service.routers.deps.require_role`) marks the request
(action, actor, role, parameters with secrets removed); this middleware adds the method,
path, remote address and the response status once the response has started (or 500 when
the route raised) and hands the record to the audit :class:`~radar_io.service.auth.JsonlLog`
— ``DATA_DIR/audit/audit.jsonl``, append-only, fsynced per batch, rotated by size. The
route never waits on that disk: a full queue drops the record and counts it
(``audit.dropped`` on the status).

Record: ``{"t_utc", "actor", "role", "action", "method", "path", "params", "remote",
"status"}`` (``actor``/``role`` null when no valid token was shown).
"""

from __future__ import annotations

import time
from typing import Any

from starlette.types import ASGIApp, Message, Receive, Scope, Send


def utc_now() -> str:
    """The wall clock as ISO 8601 UTC with milliseconds (a label)."""
    t_ns = time.time_ns()
    return time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(t_ns // 1_000_000_000)) \
        + f".{t_ns // 1_000_000 % 1000:03d}Z"


class AuditMiddleware:
    """Writes the audit record of every request the role dependency marked."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        scope.setdefault("state", {})
        status = [500]

        async def send_status(message: Message) -> None:
            if message["type"] == "http.response.start":
                status[0] = int(message["status"])
            await send(message)

        try:
            await self.app(scope, receive, send_status)
        finally:
            mark = scope["state"].get("audit") if isinstance(scope.get("state"), dict) else None
            if mark is not None:
                client = scope.get("client")
                scope["app"].state.service.audit.append({
                    "t_utc": utc_now(), "actor": mark["actor"], "role": mark["role"],
                    "action": mark["action"], "method": scope["method"], "path": scope["path"],
                    "params": mark["params"], "remote": client[0] if client else None,
                    "status": status[0]})


def audit_records(records: Any, since: str | None, limit: int) -> list[dict[str, Any]]:
    """Records with ``t_utc`` at or after ``since`` (ISO 8601 UTC; None: all), the oldest
    ``limit`` of them."""
    out: list[dict[str, Any]] = []
    for rec in records:
        if since is not None and str(rec.get("t_utc", "")) < since:
            continue
        out.append(rec)
        if len(out) >= limit:
            break
    return out


class ReadGuard:
    """``require_token_for_read``: GET/HEAD under ``/api/`` and the websockets need a valid
    token of any role (``Authorization: Bearer``, or ``?token=`` where a browser cannot set
    the header: websockets). The audit log and the control routes check their own role."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        path = scope.get("path", "")
        guarded = (scope["type"] == "websocket" and path.startswith("/ws/")) or (
            scope["type"] == "http" and scope["method"] in ("GET", "HEAD")
            and path.startswith("/api/") and path not in ("/api/audit", "/api/whoami"))
        state = scope["app"].state.service if guarded else None
        if state is None or not state.cfg.require_token_for_read:
            await self.app(scope, receive, send)
            return
        from urllib.parse import parse_qs

        from radar_io.service.routers.deps import principal_of

        token = ""
        for k, v in scope.get("headers", []):
            if k == b"authorization" and v[:7].lower() == b"bearer ":
                token = v[7:].decode("latin-1").strip()
        if not token:
            token = (parse_qs(scope.get("query_string", b"").decode("latin-1"))
                     .get("token") or [""])[0]
        who = await principal_of(state, token) if token and state.auth.enabled else None
        if who is not None:
            await self.app(scope, receive, send)
            return
        if scope["type"] == "websocket":
            await send({"type": "websocket.close", "code": 1008})
            return
        import json

        body = json.dumps({"detail": [{"loc": ["header", "Authorization"],
                                       "msg": "reading needs a token (require_token_for_read)",
                                       "type": "unauthorized"}]}).encode()
        await send({"type": "http.response.start", "status": 401,
                    "headers": [(b"content-type", b"application/json"),
                                (b"www-authenticate", b"Bearer"),
                                (b"content-length", str(len(body)).encode())]})
        await send({"type": "http.response.body", "body": body})
