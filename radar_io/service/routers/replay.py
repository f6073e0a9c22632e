"""Replay a recording through the live pipeline: start, pause, resume, seek, step, speed,
stop (control), and its state."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Body, Depends
from pydantic import BaseModel, Field

from radar_io.errors import ConflictError
from radar_io.service.errors import responses
from radar_io.service.routers.deps import CONTROL, get_state
from radar_io.service.state import ID_PATTERN, ServiceState
from radar_io.sources.replay import ReplaySource

router = APIRouter(tags=["replay"])
_CONTROL_ERRORS = responses(401, 403, 409)


class ReplayRequest(BaseModel):
    recording: str = Field(pattern=ID_PATTERN, description="recording id (file name without .rdrlog)")
    speed: float = Field(1.0, ge=0.0, le=1000.0, description="× recorded pace; 0 = as fast as possible")


class SeekRequest(BaseModel):
    position_s: float = Field(ge=0.0, description="seconds from the recording's start")


class StepRequest(BaseModel):
    n: int = Field(1, ge=1, le=100000, description="recorded chunks to deliver")


class SpeedRequest(BaseModel):
    speed: float = Field(ge=0.0, le=1000.0, description="× recorded pace; 0 = as fast as possible")


def _replay(state: ServiceState) -> ReplaySource:
    if state.replay is None or state.acq.mode != "replay":
        raise ConflictError("no replay running")
    return state.replay


@router.post("/api/replay", tags=["control"], dependencies=CONTROL,
             responses=responses(401, 403, 404, 409, 422))
def replay_start(req: ReplayRequest, state: ServiceState = Depends(get_state)) -> dict[str, Any]:
    """Replay a recording through the live pipeline (the port is released meanwhile)."""
    path = state.recording_path(req.recording)
    if req.recording == state.recorder.current:
        raise ConflictError("that recording is still being written")
    ctl = ReplaySource(path, req.speed)  # a damaged file: RecordingError → 422
    state.recorder.stop()
    state.replay = ctl
    state.acq.switch_source(ctl, "replay")
    return ctl.state()


@router.get("/api/replay", responses=responses(409))
def replay_state(state: ServiceState = Depends(get_state)) -> dict[str, Any]:
    """Position, speed, paused, finished (409 when no replay runs)."""
    return _replay(state).state()


@router.post("/api/replay/pause", tags=["control"], dependencies=CONTROL, responses=_CONTROL_ERRORS)
def replay_pause(state: ServiceState = Depends(get_state)) -> dict[str, Any]:
    r = _replay(state)
    r.pause()
    return r.state()


@router.post("/api/replay/resume", tags=["control"], dependencies=CONTROL,
             responses=_CONTROL_ERRORS)
def replay_resume(state: ServiceState = Depends(get_state)) -> dict[str, Any]:
    r = _replay(state)
    r.resume()
    return r.state()


@router.post("/api/replay/seek", tags=["control"], dependencies=CONTROL, responses=_CONTROL_ERRORS)
def replay_seek(req: SeekRequest, state: ServiceState = Depends(get_state)) -> dict[str, Any]:
    r = _replay(state)
    r.seek(req.position_s)
    return r.state()


@router.post("/api/replay/step", tags=["control"], dependencies=CONTROL, responses=_CONTROL_ERRORS)
def replay_step(req: StepRequest = Body(StepRequest()),
                state: ServiceState = Depends(get_state)) -> dict[str, Any]:
    r = _replay(state)
    r.step(req.n)
    return r.state()


@router.post("/api/replay/speed", tags=["control"], dependencies=CONTROL,
             responses=_CONTROL_ERRORS)
def replay_speed(req: SpeedRequest, state: ServiceState = Depends(get_state)) -> dict[str, Any]:
    r = _replay(state)
    r.set_speed(req.speed)
    return r.state()


@router.post("/api/replay/stop", tags=["control"], dependencies=CONTROL, responses=_CONTROL_ERRORS)
def replay_stop(state: ServiceState = Depends(get_state)) -> dict[str, Any]:
    """Back to the live source."""
    _replay(state)
    from radar_io.sources import open_source

    state.acq.switch_source(open_source(state.cfg.source), "live")
    return {"mode": "live", "source": state.cfg.source}
