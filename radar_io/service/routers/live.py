"""The live stream: ``/api/track``, ``/ws/live``, and what is drawn around it
(``/api/site``, ``/api/path``, ``/api/airdata``)."""

from __future__ import annotations

import asyncio
from typing import Any

from fastapi import APIRouter, Depends, Query, WebSocket
from fastapi.responses import Response
from pydantic import BaseModel, Field
from starlette.websockets import WebSocketDisconnect

from radar_io.errors import NotFoundError
from radar_io.service.errors import responses
from radar_io.service.history import History
from radar_io.service.hub import Hub
from radar_io.service.routers.deps import get_state, service_of
from radar_io.service.state import ServiceState

router = APIRouter(tags=["live"])

#: websocket close code when the server has no room for another client ("try again later")
WS_CLOSE_FULL = 1013


class TrackPage(BaseModel):
    messages: list[dict[str, Any]] = Field(description="decode columns + msg_seq + t_ns, oldest first")
    last_msg_seq: int
    first_msg_seq: int


@router.get("/api/site")
def site(state: ServiceState = Depends(get_state)) -> dict[str, Any] | None:
    """The radar site (WGS-84 position, runway frame), or null when none is configured."""
    return state.site.to_dict() if state.site else None


@router.get("/api/path")
def path(state: ServiceState = Depends(get_state)) -> dict[str, Any] | None:
    """The reference path in the radar frame, sampled every 50 m (null when none)."""
    return state.path_polyline()


@router.get("/api/airdata", responses=responses(404))
def airdata(since: int = Query(0, ge=0), limit: int = Query(2000, ge=1, le=10000),
            state: ServiceState = Depends(get_state)) -> dict[str, Any]:
    """The aircraft's 8 Hz air data from CAN (SI units), with the radar ground range and
    height at arrival; ``samples`` after ``air_seq`` = since."""
    if state.air is None:
        raise NotFoundError("no CAN air-data source configured (--can interface:channel)")
    return {"samples": state.air.since(since, limit), **state.air.stats()}


@router.get("/api/track", response_model=None, responses={200: {"model": TrackPage}})
def track(since: int | None = Query(None, ge=0, description="return messages after this msg_seq"),
          limit: int = Query(1000, ge=1, le=20000),
          state: ServiceState = Depends(get_state)) -> Response:
    """Recent measurements (decode columns + msg_seq + t_ns), oldest first. The messages are
    the history's JSON texts, joined as they are (no re-encoding)."""
    h = state.history
    items = h.since(since, limit) if since is not None else h.latest(limit)
    body = ('{"messages":[' + ",".join(t for _, t in items) + f'],"last_msg_seq":{h.last_seq},'
            f'"first_msg_seq":{h.first_seq}}}')
    return Response(body, media_type="application/json")


async def serve_stream(ws: WebSocket, hub: Hub, history: History, from_: int | None,
                       max_hz: float | None, batch: bool) -> None:
    """The live websocket protocol on ``ws`` for one (history, hub): ``/ws/live`` and each
    ``/ws/replays/{id}``. Beyond the hub's ``max_clients``: closed 1013."""
    await ws.accept()
    if hub.full():
        hub.refused += 1
        await ws.close(WS_CLOSE_FULL, f"too many clients ({hub.max_clients}); try again later")
        return
    client = hub.register(ws, max_hz, batch)
    sender = asyncio.create_task(client.run(history, from_))
    try:
        while True:
            recv = asyncio.create_task(ws.receive())
            done, _ = await asyncio.wait({recv, sender}, return_when=asyncio.FIRST_COMPLETED)
            if sender in done:
                recv.cancel()
                break
            if recv.result().get("type") == "websocket.disconnect":
                break
    except (WebSocketDisconnect, RuntimeError, OSError):
        pass
    finally:
        hub.unregister(client)
        sender.cancel()
        try:
            await sender  # its exception (a client gone mid-send) is retrieved, not logged
        except BaseException:  # noqa: BLE001 - cancelled or the connection's error
            pass


@router.websocket("/ws/live")
async def ws_live(ws: WebSocket, from_: int | None = Query(None, alias="from", ge=0),
                  max_hz: float | None = Query(None, gt=0, le=1000),
                  batch: bool = Query(False, description="one JSON array per websocket frame"),
                  ) -> None:
    """Live messages: one JSON object per frame, or arrays with ``batch=1``; ``from=N``
    resumes after msg_seq N; ``max_hz`` decimates. Beyond ``ws_max_clients``: closed 1013."""
    state: ServiceState = service_of(ws)
    await serve_stream(ws, state.hub, state.history, from_, max_hz, batch)
