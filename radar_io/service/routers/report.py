"""``GET /api/recordings/{id}/report?format=html|pdf``: the flight report of a recording
(:mod:`radar_io.analysis.report`), with the service's site, reference path and calibration."""

from __future__ import annotations

from typing import Literal

from fastapi import APIRouter, Depends, Path, Query
from fastapi.responses import Response

from radar_io.service.errors import responses
from radar_io.service.routers.deps import get_state
from radar_io.service.state import ID_PATTERN, ServiceState

router = APIRouter(tags=["recordings"])


@router.get("/api/recordings/{rec_id}/report",
            responses={200: {"content": {"text/html": {}, "application/pdf": {}}},
                       **responses(404, 422, 429, 503)})
async def report(rec_id: str = Path(pattern=ID_PATTERN, description="recording id"),
                 format: Literal["html", "pdf"] = Query("html"),
                 state: ServiceState = Depends(get_state)) -> Response:
    """Self-contained HTML (figures embedded) or a PDF, built on request (a few seconds for
    a 10-minute recording) in a worker process. At most ``max_reports`` at once (429 with
    Retry-After beyond)."""
    from radar_io.analysis.report import report_bytes

    path = state.recording_path(rec_id)
    body = await state.limits.run("reports", report_bytes, path, format, state.site,
                                  state.live.calibration, state.path, state.spec)
    if format == "pdf":
        return Response(body, media_type="application/pdf", headers={
            "Content-Disposition": f'attachment; filename="{rec_id}-report.pdf"'})
    return Response(body, media_type="text/html; charset=utf-8")
