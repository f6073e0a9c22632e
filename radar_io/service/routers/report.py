"""``GET /api/recordings/{id}/report?format=html|pdf``: the flight report of a recording
(:mod:`radar_io.analysis.report`), with the service's site, reference path and calibration."""

from __future__ import annotations

import io
import threading
from typing import Literal

from fastapi import APIRouter, Depends, Path, Query
from fastapi.responses import Response

from radar_io.service.errors import responses
from radar_io.service.routers.deps import get_state
from radar_io.service.state import ID_PATTERN, ServiceState

router = APIRouter(tags=["recordings"])
#: matplotlib's pyplot state is process-wide: one report is drawn at a time
_REPORT_LOCK = threading.Lock()


@router.get("/api/recordings/{rec_id}/report",
            responses={200: {"content": {"text/html": {}, "application/pdf": {}}},
                       **responses(404, 422)})
def report(rec_id: str = Path(pattern=ID_PATTERN, description="recording id"),
           format: Literal["html", "pdf"] = Query("html"),  # noqa: A002
           state: ServiceState = Depends(get_state)) -> Response:
    """Self-contained HTML (figures embedded) or a PDF, built on request (a few seconds for
    a 10-minute recording)."""
    from radar_io.analysis.report import write_report

    path = state.recording_path(rec_id)
    buf = io.BytesIO()
    with _REPORT_LOCK:
        write_report(path, buf, format, site=state.site, calibration=state.live.calibration,
                     ref_path=state.path, spec=state.spec)
    if format == "pdf":
        return Response(buf.getvalue(), media_type="application/pdf", headers={
            "Content-Disposition": f'attachment; filename="{rec_id}-report.pdf"'})
    return Response(buf.getvalue(), media_type="text/html; charset=utf-8")
