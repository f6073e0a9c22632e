"""Dependencies shared by the routers: the service state and the control token.

Both are ``async def``: FastAPI runs a plain ``def`` dependency on the default thread pool,
so under load even ``/api/status`` would wait for a free thread; these run on the loop."""

from __future__ import annotations

import secrets

from fastapi import Depends, HTTPException, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from starlette.requests import HTTPConnection

from radar_io.service.config import TOKEN_ENV
from radar_io.service.state import ServiceState


def service_of(conn: HTTPConnection) -> ServiceState:
    """The :class:`ServiceState` of the app serving this request or websocket."""
    state: ServiceState = conn.app.state.service
    return state


async def get_state(conn: HTTPConnection) -> ServiceState:
    """:func:`service_of` as a dependency (on the loop)."""
    return service_of(conn)


#: declared in the OpenAPI as the "HTTPBearer" security scheme of the control endpoints
bearer = HTTPBearer(auto_error=False, description="the control token (RADAR_IO_TOKEN or token_file)")


async def require_token(request: Request, credentials: HTTPAuthorizationCredentials | None
                        = Depends(bearer)) -> None:
    """Control endpoints: 403 when no token is configured or it is wrong, 401 without one."""
    token = service_of(request).token
    if token is None:
        raise HTTPException(403, f"control is disabled: no token configured (set {TOKEN_ENV} "
                            "or token_file)")
    if credentials is None or credentials.scheme.lower() != "bearer":
        raise HTTPException(401, "control needs 'Authorization: Bearer <token>'",
                            headers={"WWW-Authenticate": "Bearer"})
    if not secrets.compare_digest(credentials.credentials.strip().encode(), token.encode()):
        raise HTTPException(403, "wrong token")


#: ``dependencies=CONTROL`` on a route or router: the token is required
CONTROL = [Depends(require_token)]
