"""Replay sessions (``service/sessions.py``): create (control), list, state, delete (control),
pause, resume, seek, step, speed (control), and ``/ws/replays/{id}`` (the live websocket
protocol on the session's own history and hub). The old single replay through the live
pipeline (``/api/replay*``) is gone: those routes answer 410 naming the new ones."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Body, Depends, HTTPException, Path, Query, WebSocket
from fastapi.responses import JSONResponse
from pydantic import BaseModel, Field

from radar_io.errors import NotFoundError
from radar_io.service.errors import error_response, responses
from radar_io.service.routers.deps import CONTROL, get_state, service_of
from radar_io.service.routers.live import serve_stream
from radar_io.service.sessions import ReplaySession, SessionLimit
from radar_io.service.state import ID_PATTERN, ServiceState

router = APIRouter(tags=["replay"])
_CONTROL_ERRORS = responses(401, 403, 404, 422)
SESSION_ID = Path(pattern=r"^[0-9a-f]{1,32}$", description="replay session id")

#: websocket close code for an unknown replay session
WS_CLOSE_UNKNOWN = 4404


class ReplayRequest(BaseModel):
    recording: str = Field(pattern=ID_PATTERN, description="recording id (file name without .rdrlog)")
    speed: float = Field(1.0, ge=0.0, le=1000.0, description="× recorded pace; 0 = as fast as possible")
    start_s: float = Field(0.0, ge=0.0, description="start this many seconds after the recording's "
                           "first chunk (monotonic receive time)")


class SeekRequest(BaseModel):
    position_s: float = Field(ge=0.0, description="seconds from the recording's start")


class StepRequest(BaseModel):
    n: int = Field(1, ge=1, le=100000, description="recorded chunks to deliver")


#: the body of a step request without one
ONE_STEP = StepRequest(n=1)


class SpeedRequest(BaseModel):
    speed: float = Field(ge=0.0, le=1000.0, description="× recorded pace; 0 = as fast as possible")


def _session(state: ServiceState, sid: str) -> ReplaySession:
    s = state.replays.get(sid)
    s.touch()  # a control call or a look at its state: someone is watching
    return s


@router.post("/api/replays", tags=["control"], dependencies=CONTROL, status_code=201,
             responses=responses(401, 403, 404, 422, 429))
def replay_create(req: ReplayRequest, state: ServiceState = Depends(get_state)) -> dict[str, Any]:
    """A replay session of a recording beside the live pipeline (which it never touches):
    ``{"id", "ws": "/ws/replays/{id}", …state}``. A recording still being written is replayed
    up to what is on disk now. 429 beyond ``max_replays`` sessions."""
    path = state.recording_path(req.recording)
    try:
        s = state.replays.create(req.recording, path, speed=req.speed, start_s=req.start_s,
                                 size_bytes=state.recorder.committed_bytes(req.recording))
    except SessionLimit as exc:
        raise HTTPException(429, str(exc), headers={"Retry-After": "10"}) from exc
    return s.state()


@router.get("/api/replays")
def replay_list(state: ServiceState = Depends(get_state)) -> list[dict[str, Any]]:
    """The running replay sessions and their state."""
    return [s.state() for s in state.replays.running()]


@router.get("/api/replays/{sid}", responses=responses(404, 422))
def replay_state(sid: str = SESSION_ID, state: ServiceState = Depends(get_state)) -> dict[str, Any]:
    """recording, position_s, duration_s, speed, paused, finished, chunk / chunks, frames,
    websocket clients, last_msg_seq."""
    return _session(state, sid).state()


@router.delete("/api/replays/{sid}", tags=["control"], dependencies=CONTROL,
               responses=_CONTROL_ERRORS)
def replay_delete(sid: str = SESSION_ID, state: ServiceState = Depends(get_state)) -> dict[str, Any]:
    """End the session (its websocket clients are closed); its last state."""
    s = state.replays.delete(sid)
    return s.state()


@router.post("/api/replays/{sid}/pause", tags=["control"], dependencies=CONTROL,
             responses=_CONTROL_ERRORS)
def replay_pause(sid: str = SESSION_ID, state: ServiceState = Depends(get_state)) -> dict[str, Any]:
    s = _session(state, sid)
    s.source.pause()
    return s.state()


@router.post("/api/replays/{sid}/resume", tags=["control"], dependencies=CONTROL,
             responses=_CONTROL_ERRORS)
def replay_resume(sid: str = SESSION_ID, state: ServiceState = Depends(get_state)) -> dict[str, Any]:
    s = _session(state, sid)
    s.source.resume()
    return s.state()


@router.post("/api/replays/{sid}/seek", tags=["control"], dependencies=CONTROL,
             responses=_CONTROL_ERRORS)
def replay_seek(req: SeekRequest, sid: str = SESSION_ID,
                state: ServiceState = Depends(get_state)) -> dict[str, Any]:
    """Jump to the first chunk received at or after ``position_s`` (monotonic time)."""
    s = _session(state, sid)
    s.source.seek(req.position_s)
    return s.state()


@router.post("/api/replays/{sid}/step", tags=["control"], dependencies=CONTROL,
             responses=_CONTROL_ERRORS)
def replay_step(req: StepRequest = Body(ONE_STEP), sid: str = SESSION_ID,
                state: ServiceState = Depends(get_state)) -> dict[str, Any]:
    """Pause and deliver the next ``n`` recorded chunks."""
    s = _session(state, sid)
    s.source.step(req.n)
    return s.state()


@router.post("/api/replays/{sid}/speed", tags=["control"], dependencies=CONTROL,
             responses=_CONTROL_ERRORS)
def replay_speed(req: SpeedRequest, sid: str = SESSION_ID,
                 state: ServiceState = Depends(get_state)) -> dict[str, Any]:
    s = _session(state, sid)
    s.source.set_speed(req.speed)
    return s.state()


@router.websocket("/ws/replays/{sid}")
async def ws_replay(ws: WebSocket, sid: str, from_: int | None = Query(None, alias="from", ge=0),
                    max_hz: float | None = Query(None, gt=0, le=1000),
                    batch: bool = Query(False, description="one JSON array per websocket frame"),
                    ) -> None:
    """A session's messages, in the live protocol (``from=``, ``max_hz``, ``batch=1``); each
    carries its recorded ``t_ns`` and ``"replay": id``. An unknown id: closed 4404."""
    state: ServiceState = service_of(ws)
    try:
        s = state.replays.get(sid)
    except NotFoundError as exc:
        await ws.accept()
        await ws.close(WS_CLOSE_UNKNOWN, str(exc))
        return
    s.touch()
    await serve_stream(ws, s.hub, s.history, from_, max_hz, batch)
    s.touch()  # idle from the moment its last client left


# -- the removed single replay through the live pipeline: 410 ------------------------------
_GONE = {
    ("POST", "/api/replay"): "POST /api/replays",
    ("GET", "/api/replay"): "GET /api/replays and GET /api/replays/{id}",
    ("POST", "/api/replay/stop"): "DELETE /api/replays/{id} (the live stream never stopped)",
    **{("POST", f"/api/replay/{op}"): f"POST /api/replays/{{id}}/{op}"
       for op in ("pause", "resume", "seek", "step", "speed")},
}


def _gone_route(method: str, path: str, new: str) -> None:
    text = (f"{method} {path} is gone: replays run as sessions beside the live pipeline; "
            f"use {new} (see /docs)")

    def gone() -> JSONResponse:
        return error_response(410, text)

    gone.__doc__ = f"Gone (410): use {new}."
    router.add_api_route(path, gone, methods=[method], status_code=410, response_model=None,
                         responses=responses(410), deprecated=True,
                         name=f"gone_{method.lower()}_{path.strip('/').replace('/', '_')}")


for (_method, _path), _new in _GONE.items():
    _gone_route(_method, _path, _new)
