"""``GET /api/recordings/{id}/report?format=html|pdf``: the flight report of a recording
(:mod:`radar_io.analysis.report`), with the service's site, reference path and calibration."""

from __future__ import annotations

import io
from typing import Literal

from fastapi import APIRouter, Query, Request
from fastapi.responses import Response

router = APIRouter(tags=["recordings"])


@router.get("/api/recordings/{rec_id}/report")
def report(rec_id: str, request: Request,
           format: Literal["html", "pdf"] = Query("html")) -> Response:  # noqa: A002
    """Self-contained HTML (figures embedded) or a PDF; built on request (a few seconds for
    a 10-minute recording)."""
    from radar_io.analysis.report import write_report

    svc = request.app.state.service
    path = svc.recording_path(rec_id)
    buf = io.BytesIO()
    write_report(path, buf, format, site=svc.site, calibration=svc.acq.calibration,
                 ref_path=svc.path, spec=svc.spec)
    if format == "pdf":
        return Response(buf.getvalue(), media_type="application/pdf", headers={
            "Content-Disposition": f'attachment; filename="{rec_id}-report.pdf"'})
    return Response(buf.getvalue(), media_type="text/html; charset=utf-8")
