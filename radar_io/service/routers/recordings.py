"""Recordings: list, download, sync events; start and stop (control)."""

from __future__ import annotations

import os
from collections import OrderedDict
from typing import Any

from fastapi import APIRouter, Depends, HTTPException, Path, Query

from radar_io.errors import StorageError
from radar_io.service.errors import responses
from radar_io.service.limits import HeldFileResponse, HeldStreamingResponse, iterate_on
from radar_io.service.routers.deps import CONTROL, get_state
from radar_io.service.state import ID_PATTERN, ServiceState

router = APIRouter(tags=["recordings"])


@router.get("/api/recordings")
def recordings(state: ServiceState = Depends(get_state)) -> list[dict[str, Any]]:
    """Recordings in the data directory, newest first."""
    out = []
    for p in sorted(state.recorder.dir.glob("*.rdrlog"), reverse=True):
        st = p.stat()
        out.append({"id": p.stem, "size_bytes": st.st_size, "modified_unix_s": st.st_mtime,
                    "open": p.stem == state.recorder.current,
                    "download": f"/api/recordings/{p.stem}"})
    return out


@router.get("/api/recordings/{rec_id}", response_model=None,
            responses={200: {"content": {"application/octet-stream": {
                "schema": {"type": "string", "format": "binary"}}},
                "description": "the .rdrlog file"}, **responses(404, 422, 429)})
async def download(rec_id: str = Path(pattern=ID_PATTERN, description="recording id"),
                   state: ServiceState = Depends(get_state)) -> Any:
    """The .rdrlog file itself; one still being written comes as a snapshot up to its last
    whole chunk at request time (Content-Length = body, a prefix of the final file). At most
    ``max_downloads`` at once (429 with Retry-After beyond)."""
    p = state.recording_path(rec_id)
    release = state.limits.acquire("downloads")
    try:
        size = state.recorder.committed_bytes(rec_id)  # an open recording: its committed prefix
        resp: HeldFileResponse | HeldStreamingResponse
        if size is not None:
            from radar_io.recording.rdrlog import iter_prefix

            resp = HeldStreamingResponse(
                iterate_on(state.limits.pool, iter_prefix(p, size)),
                media_type="application/octet-stream",
                headers={"Content-Length": str(size),
                         "Content-Disposition": f'attachment; filename="{p.name}"'})
        else:
            resp = HeldFileResponse(p, media_type="application/octet-stream", filename=p.name)
    except BaseException:
        release()
        raise
    resp.release = release
    return resp


#: a recording's sync events by (path, size, mtime): a repeated query decodes nothing
_SYNC_CACHE: OrderedDict[tuple[str, int, int], list[dict[str, Any]]] = OrderedDict()
SYNC_CACHE_ENTRIES = 16


async def recording_sync_events(state: ServiceState, path: os.PathLike[str]
                                ) -> list[dict[str, Any]]:
    """The SYNC 0→1 edges of a recording file, decoded in a worker process (``sync`` limit)
    once per file version (on the loop: the cache needs no lock)."""
    from radar_io.calibration.sync_pairs import radar_at_sync_events

    st = os.stat(path)
    key = (str(path), st.st_size, st.st_mtime_ns)
    if key in _SYNC_CACHE:
        _SYNC_CACHE.move_to_end(key)
        return _SYNC_CACHE[key]
    events = await state.limits.run("sync", radar_at_sync_events, path, state.spec)
    _SYNC_CACHE[key] = events
    while len(_SYNC_CACHE) > SYNC_CACHE_ENTRIES:
        _SYNC_CACHE.popitem(last=False)
    return events


@router.get("/api/sync-events", responses=responses(404, 422, 429, 503))
async def sync_events(recording: str | None = Query(None, pattern=ID_PATTERN,
                                                    description="recording id; none = live"),
                      limit: int = Query(1000, ge=1, le=100000),
                      state: ServiceState = Depends(get_state)) -> list[dict[str, Any]]:
    """Sync (camera shutter) events: SYNC 0→1 edges. Live (no ``recording``): as seen,
    with SEQ, TOD, receive time and the recording that holds them. For a recording: its
    edges decoded from the file, numbered by ``sync_index`` — the numbering
    POST /api/calibration/bias uses — with the radar's SR'/EL'/AZ' at each (at most
    ``max_sync_queries`` decodes at once, 429 with Retry-After beyond; a file decoded
    once is answered from memory until it changes)."""
    if recording is not None:
        events = await recording_sync_events(state, state.recording_path(recording))
        return [{**e, "recording": recording} for e in events[:limit]]
    return [e.as_dict() for e in state.recorder.sync_events[-limit:]]


@router.post("/api/recordings/start", tags=["control"], dependencies=CONTROL,
             responses=responses(401, 403, 503, 507))
def rec_start(state: ServiceState = Depends(get_state)) -> dict[str, Any]:
    """Start a manual recording (507 when the disk has no room)."""
    try:
        return {"recording": state.recorder.start("manual")}
    except StorageError as exc:  # 507 no room (ENOSPC, EDQUOT, EFBIG), else 503
        raise HTTPException(state.recorder.http_status(exc), str(exc)) from exc


@router.post("/api/recordings/stop", tags=["control"], dependencies=CONTROL,
             responses=responses(401, 403))
def rec_stop(state: ServiceState = Depends(get_state)) -> dict[str, Any]:
    """Close the open recording (``closed``: its id, or null)."""
    return {"closed": state.recorder.stop()}
