"""``GET /api/status``: source, link state, framer counters, rate, lamps, recording,
websocket clients, uplinks and air data."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Depends

from radar_io.service.routers.deps import get_state
from radar_io.service.state import ServiceState

router = APIRouter(tags=["live"])


@router.get("/api/status")
async def status(state: ServiceState = Depends(get_state)) -> dict[str, Any]:
    """Source, link state, framer counters, rate, lamps, recording, websocket clients and
    history, uplinks (``uplink.<name>``: connected, reconnects, last_error) and air data;
    ``calibration_error`` / ``calibration_last_good`` when ``active.json`` was unreadable
    at start."""
    return state.status()
