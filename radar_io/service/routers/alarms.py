"""Limit alarms over HTTP: ``GET /api/alarms`` and ``POST /api/alarms/{id}/ack`` (control
token). The engine is ``ServiceState.alarms`` (see :mod:`radar_io.service.alarms`)."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Depends

from radar_io.errors import NotFoundError
from radar_io.service.alarms import AlarmEngine, _clean
from radar_io.service.errors import responses
from radar_io.service.routers.deps import CONTROL, get_state
from radar_io.service.state import ServiceState

router = APIRouter(tags=["alarms"])


def _engine(state: ServiceState) -> AlarmEngine:
    engine = state.alarms
    if engine is None:
        raise NotFoundError("no alarm engine in this service")
    return engine


@router.get("/api/alarms", responses=responses(404))
def alarms(state: ServiceState = Depends(get_state)) -> dict[str, Any]:
    """Active alarms, oldest first: ``id, name, column, value, limit, since`` (s since the
    epoch), ``since_utc``, ``acknowledged``."""
    return {"alarms": [{k: _clean(v) for k, v in a.items()} for a in _engine(state).active()]}


@router.post("/api/alarms/{alarm_id}/ack", dependencies=CONTROL, tags=["control"],
             responses=responses(401, 403, 404))
def ack(alarm_id: str, state: ServiceState = Depends(get_state)) -> dict[str, Any]:
    """Acknowledge an active alarm (it stays listed until its cause clears); 404 when it is
    not active."""
    return {k: _clean(v) for k, v in _engine(state).acknowledge(alarm_id).items()}
