"""Who is signed in (``GET /api/whoami``) and the audit trail (``GET /api/audit``, admin)."""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any

from fastapi import APIRouter, Depends, Query, Request

from radar_io.service.audit import audit_records
from radar_io.service.auth import ROLES
from radar_io.service.errors import responses
from radar_io.service.routers.deps import ADMIN_DEP, get_state, principal_of
from radar_io.service.state import ServiceState

router = APIRouter(tags=["access"])

#: what each role may do, as the dashboard shows it (the routes check the role themselves)
CAN = {"viewer": ["read"],
       "operator": ["read", "record", "replay", "annotate", "acknowledge"],
       "admin": ["read", "record", "replay", "annotate", "acknowledge", "calibrate",
                 "runway", "audit"]}


@router.get("/api/whoami")
async def whoami(request: Request, state: ServiceState = Depends(get_state)) -> dict[str, Any]:
    """The token's holder: ``actor``, ``role`` (null without a valid token), ``can`` (what
    the role allows: read, record, replay, annotate, acknowledge, calibrate, runway,
    audit), ``roles`` and whether control is enabled at all."""
    who = None
    scheme, _, token = request.headers.get("authorization", "").partition(" ")
    if scheme.lower() == "bearer" and token.strip() and state.auth.enabled:
        who = await principal_of(state, token.strip())
    return {"actor": who.actor if who else None, "role": who.role if who else None,
            "can": CAN[who.role] if who else ([] if state.cfg.require_token_for_read
                                              else ["read"]),
            "roles": list(ROLES), "control_enabled": state.auth.enabled}


def _since(t: datetime | None) -> str | None:
    """``since`` as the audit log writes times (ISO 8601 UTC, milliseconds)."""
    if t is None:
        return None
    if t.tzinfo is None:
        t = t.replace(tzinfo=UTC)
    t = t.astimezone(UTC)
    return t.isoformat(timespec="milliseconds").replace("+00:00", "Z")


@router.get("/api/audit", tags=["control"], responses=responses(401, 403, 422))
def audit(since: datetime | None = Query(None, description="ISO 8601 time (UTC unless it "
                                         "says otherwise): records at or after it"),
          limit: int = Query(1000, ge=1, le=100_000),
          _who: Any = Depends(ADMIN_DEP),
          state: ServiceState = Depends(get_state)) -> dict[str, Any]:
    """The audit trail (admin): ``records``, oldest first from ``since``, at most ``limit``;
    each ``{t_utc, actor, role, action, method, path, params, remote, status}``. Records
    queued when the request came are written first."""
    start = _since(since)
    state.audit.flush(2.0)
    return {"records": audit_records(state.audit.read(), start, limit)}
