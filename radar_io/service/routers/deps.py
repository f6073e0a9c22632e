"""Dependencies shared by the routers: the service state and the role a route needs.

Both are ``async def``: FastAPI runs a plain ``def`` dependency on the default thread pool,
so under load even ``/api/status`` would wait for a free thread; these run on the loop."""

from __future__ import annotations

import json
from typing import Any

from fastapi import Depends, HTTPException, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from starlette.requests import HTTPConnection

from radar_io.service.auth import Principal
from radar_io.service.config import TOKEN_ENV
from radar_io.service.state import ServiceState

AUDIT_BODY_BYTES = 16 << 10  #: a JSON body up to this size is logged (secrets removed)
AUTH_THREADS = 2             #: scrypt checks at once (the rest wait, off the loop)


def service_of(conn: HTTPConnection) -> ServiceState:
    """The :class:`ServiceState` of the app serving this request or websocket."""
    state: ServiceState = conn.app.state.service
    return state


async def get_state(conn: HTTPConnection) -> ServiceState:
    """:func:`service_of` as a dependency (on the loop)."""
    return service_of(conn)


#: declared in the OpenAPI as the "HTTPBearer" security scheme of the control endpoints
bearer = HTTPBearer(auto_error=False, description="a token of the tokens file (viewer / "
                    "operator / admin) or RADAR_IO_TOKEN / token_file (admin)")

#: body and query fields never put in the audit log
_SECRET_PARAM = ("token", "password", "secret", "key", "authorization")


async def _params(request: Request) -> dict[str, Any]:
    """The request's path, query and JSON-body parameters for the audit log, secrets
    removed (a body that is not small JSON is summarised by its size)."""
    out: dict[str, Any] = {**request.path_params, **request.query_params}
    if request.method in ("POST", "PUT", "PATCH", "DELETE"):
        ctype = request.headers.get("content-type", "")
        size = int(request.headers.get("content-length") or 0)
        if ctype.startswith("application/json") and size <= AUDIT_BODY_BYTES:
            try:
                body = json.loads(await request.body() or b"null")
            except ValueError:
                body = None
            if isinstance(body, dict):
                out.update(body)
            elif body is not None:
                out["body"] = body
        elif size:
            out["body_bytes"] = size
    return {k: ("(withheld)" if any(w in k.lower() for w in _SECRET_PARAM) else v)
            for k, v in out.items()}


def require_role(role: str) -> Any:
    """A dependency: the request needs a token of ``role`` or above. 401 without a token,
    403 with a wrong one or a lesser role, 403 when no token is configured. Every call,
    allowed or refused, is marked for the audit log (written once the response is known,
    by :class:`~radar_io.service.audit.AuditMiddleware`)."""

    async def dep(request: Request, credentials: HTTPAuthorizationCredentials | None
                  = Depends(bearer)) -> Principal:
        state = service_of(request)
        route = request.scope.get("route")
        mark: dict[str, Any] = {"action": getattr(route, "name", request.url.path),
                                "actor": None, "role": None, "params": await _params(request)}
        request.state.audit = mark
        if not state.auth.enabled:
            raise HTTPException(403, f"control is disabled: no token configured (set "
                                f"{TOKEN_ENV}, token_file or tokens_file)")
        if credentials is None or credentials.scheme.lower() != "bearer":
            raise HTTPException(401, "control needs 'Authorization: Bearer <token>'",
                                headers={"WWW-Authenticate": "Bearer"})
        who = await principal_of(state, credentials.credentials.strip())
        if who is None:
            raise HTTPException(403, "wrong token")
        mark["actor"], mark["role"] = who.actor, who.role
        if not who.allows(role):
            raise HTTPException(403, f"{who.role} {who.actor!r} may not do this: it needs "
                                f"the {role} role")
        return who

    dep.__name__ = f"require_{role}"
    return dep


async def principal_of(state: ServiceState, token: str) -> Principal | None:
    """Who holds ``token`` (None: nobody): from the cache on the loop, else one scrypt on
    a worker thread (at most :data:`AUTH_THREADS` at once, per service)."""
    who = state.auth.cached(token)
    if who is not None or state.auth.file is None:
        return who
    import anyio
    import anyio.to_thread

    if state.auth.limiter is None:  # created on the service's own event loop
        state.auth.limiter = anyio.CapacityLimiter(AUTH_THREADS)
    return await anyio.to_thread.run_sync(state.auth.verify, token, limiter=state.auth.limiter)


OPERATOR_DEP = require_role("operator")
ADMIN_DEP = require_role("admin")
#: ``dependencies=CONTROL`` on a route: an operator (record, replay, annotate, acknowledge)
CONTROL = [Depends(OPERATOR_DEP)]
#: calibration, runway, tokens, the audit log
ADMIN = [Depends(ADMIN_DEP)]
