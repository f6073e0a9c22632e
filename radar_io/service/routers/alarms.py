"""Limit alarms over HTTP: ``GET /api/alarms`` and ``POST /api/alarms/{id}/ack`` (control
token). The engine is ``app.state.service.alarms`` (see :mod:`radar_io.service.alarms`)."""

from __future__ import annotations

import secrets
from typing import Any

from fastapi import APIRouter, Depends, Header, HTTPException, Request

from radar_io.errors import NotFoundError
from radar_io.service.alarms import _clean

router = APIRouter(tags=["alarms"])


def require_token(request: Request, authorization: str | None = Header(None)) -> None:
    """The control token check (same rules and messages as the service's other control routes)."""
    from radar_io.service.config import TOKEN_ENV

    token = request.app.state.service.token
    if token is None:
        raise HTTPException(403, f"control is disabled: no token configured (set {TOKEN_ENV} "
                            "or token_file)")
    if not authorization or not authorization.startswith("Bearer "):
        raise HTTPException(401, "control needs 'Authorization: Bearer <token>'",
                            headers={"WWW-Authenticate": "Bearer"})
    if not secrets.compare_digest(authorization[7:].strip().encode(), token.encode()):
        raise HTTPException(403, "wrong token")


def _engine(request: Request) -> Any:
    engine = getattr(request.app.state.service, "alarms", None)
    if engine is None:
        raise HTTPException(404, "no alarm engine in this service")
    return engine


@router.get("/api/alarms")
def alarms(request: Request) -> dict[str, Any]:
    """Active alarms, oldest first: ``id, name, column, value, limit, since`` (s since the
    epoch), ``since_utc``, ``acknowledged``."""
    return {"alarms": [{k: _clean(v) for k, v in a.items()} for a in _engine(request).active()]}


@router.post("/api/alarms/{alarm_id}/ack", dependencies=[Depends(require_token)],
             tags=["control"])
def ack(alarm_id: str, request: Request) -> dict[str, Any]:
    """Acknowledge an active alarm (it stays listed until its cause clears)."""
    try:
        a = _engine(request).acknowledge(alarm_id)
    except NotFoundError as exc:
        raise HTTPException(404, str(exc)) from exc
    return {k: _clean(v) for k, v in a.items()}
