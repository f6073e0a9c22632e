"""Look back over whole recordings without replaying them: decimated min/max series of any
column and the recording's events, from the recording's look-back index
(:mod:`radar_io.analysis.series`, docs/lookback.md)."""

from __future__ import annotations

import functools
import json
import time
from collections.abc import Callable
from typing import Any

from fastapi import APIRouter, Depends, Path, Query
from fastapi.responses import Response
from pydantic import BaseModel, ConfigDict, Field
from starlette.requests import HTTPConnection, Request

from radar_io.analysis.series import query_events, query_series
from radar_io.service.errors import responses
from radar_io.service.lookback import LookBack
from radar_io.service.routers.deps import service_of
from radar_io.service.state import ID_PATTERN

router = APIRouter(tags=["recordings"])

_ERRORS = responses(404, 422, 429, 503, 507)
COLUMNS_PATTERN = r"^[A-Za-z0-9_]+(,[A-Za-z0-9_]+)*$"


class MinMax(BaseModel):
    min: list[float | None] = Field(description="per bucket (or frame); null: no value")
    max: list[float | None]


class SeriesAnswer(BaseModel):
    start_s: float = Field(description="range used, s since the first chunk (clamped)")
    end_s: float
    decimated: bool = Field(description="true: `points` equal buckets; false: every frame")
    frames: int = Field(description="frames in the range")
    t_s: list[float] = Field(description="bucket starts, or each frame's time")
    columns: dict[str, MinMax]


class Event(BaseModel):
    model_config = ConfigDict(extra="allow")

    kind: str = Field(description="go (with edge: rise / fall), sync, or the event log's kind "
                      "(alarm, clock_step, …)")
    t_s: float | None = Field(description="s since the first chunk (monotonic receive time)")
    t_ns: int = Field(description="wall-clock receive time, ns since the Unix epoch (a label)")


class EventsAnswer(BaseModel):
    events: list[Event]


async def get_lookback(conn: HTTPConnection) -> LookBack:
    """The look-back indexes of the app serving this request."""
    return conn.app.state.lookback


async def _limited(conn: HTTPConnection, fn: Callable[..., dict[str, Any]],
                   **kwargs: Any) -> Response:
    """``fn(**kwargs)`` (plain, picklable data) within the expensive-request limit of kind
    "series" (429 + Retry-After beyond ``max_series_queries``; a worker process, never the
    loop or the pool the control routes use), as JSON with its wall time in a
    ``Server-Timing`` header (``total``, ms, index update included)."""
    t0 = time.perf_counter()
    doc = await service_of(conn).limits.run("series", functools.partial(fn, **kwargs))
    body = json.dumps(doc, separators=(",", ":"), allow_nan=False)
    timing = f"total;dur={(time.perf_counter() - t0) * 1e3:.2f}"
    return Response(body, media_type="application/json", headers={"Server-Timing": timing})


@router.get("/api/recordings/{rec_id}/series", response_model=None,
            responses={200: {"model": SeriesAnswer}, **_ERRORS})
async def series(request: Request, rec_id: str = Path(pattern=ID_PATTERN, description="recording id"),
           columns: str = Query(pattern=COLUMNS_PATTERN, max_length=2000,
                                description="comma-separated column names, e.g. h_m,dy_m"),
           start_s: float | None = Query(None, ge=0.0, allow_inf_nan=False,
                                         description="range start, s (default: 0)"),
           end_s: float | None = Query(None, ge=0.0, allow_inf_nan=False,
                                       description="range end, s (default: the last frame)"),
           points: int = Query(1000, ge=1, le=10000, description="buckets"),
           lookback: LookBack = Depends(get_lookback)) -> Response:
    """Min / max of columns over a time range of a recording (closed, or still being written:
    up to its last whole chunk). Time: seconds since the recording's first chunk on the
    monotonic receive time; each frame has the time of the chunk that completed it. More
    than `points` frames in the range: `points` equal buckets (numpy.histogram's: each
    [start, next start), the last one closed), `t_s` their starts, min / max over the
    non-null samples of each (null: no value). Otherwise every frame (min = max). The
    first query of a recording builds its index (docs/lookback.md)."""
    return await _limited(request, query_series, columns=columns.split(","), start_s=start_s,
                          end_s=end_s, points=points, **lookback.request(rec_id))


@router.get("/api/recordings/{rec_id}/events", response_model=None,
            responses={200: {"model": EventsAnswer}, **_ERRORS})
async def events(request: Request, rec_id: str = Path(pattern=ID_PATTERN, description="recording id"),
           lookback: LookBack = Depends(get_lookback)) -> Response:
    """GO edges (`go`, `edge` rise / fall) and SYNC 0→1 edges (`sync`), each with `seq` and
    `tod_s`, found in the recording's frames, and the other records of its event log
    (alarms, clock steps, annotations), by time on the series' axis."""
    return await _limited(request, _events_doc, **lookback.request(rec_id))


def _events_doc(**kwargs: Any) -> dict[str, Any]:
    """``{"events": [...]}`` of :func:`query_events` (module level: it runs in a worker)."""
    return {"events": query_events(**kwargs)}
