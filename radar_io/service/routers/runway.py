"""Runway vision over HTTP (runway-vision.md): upload an image or a video, or send
operator-picked points, and get the pose; images come back with the detected lines drawn
on them.

Uploads need the control token (they cost minutes of CPU). The body is streamed to a
temporary file and refused with 413 as soon as it passes the limit (at once when the
declared Content-Length does). An image is processed on a worker thread and answered
directly; a video (``Content-Type: video/*``) becomes a job (202, see
:mod:`radar_io.service.runway_jobs`): ``GET /api/runway/jobs/ID`` for its state and,
when done, its result; ``DELETE`` cancels. OpenCV never runs on the event loop.
"""

from __future__ import annotations

import base64
import os
import threading
from pathlib import Path
from typing import Any

from fastapi import APIRouter, HTTPException, Query, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import JSONResponse
from pydantic import BaseModel, Field

from radar_io.service.errors import responses
from radar_io.service.routers.deps import ADMIN
from radar_io.service.runway_jobs import DEFAULT_TIMEOUT_S, MAX_FRAMES, RunwayJobs

MAX_BODY = 512 << 20   #: bytes accepted for one upload (config max_upload_mb)

__all__ = ["MAX_BODY", "MAX_FRAMES", "router"]


router = APIRouter(tags=["runway vision"])
_jobs_lock = threading.Lock()


def jobs_of(app: Any) -> RunwayJobs:
    """The service's runway job table, created on first use (config: runway_queue,
    runway_job_timeout_s); closed by the service's stop()."""
    state = app.state.service
    with _jobs_lock:
        if getattr(state, "runway_jobs", None) is None:
            cfg = state.cfg
            state.runway_jobs = RunwayJobs(max_queued=int(getattr(cfg, "runway_queue", 2)),
                                           timeout_s=float(getattr(cfg, "runway_job_timeout_s",
                                                                   DEFAULT_TIMEOUT_S)))
        return state.runway_jobs


def _max_body(request: Request) -> int:
    mb = getattr(request.app.state.service.cfg, "max_upload_mb", None)
    return int(mb) << 20 if mb else MAX_BODY


async def _spool(request: Request, path: Path, limit: int) -> int:
    """Stream the request body into ``path``; 413 as soon as it exceeds ``limit`` bytes."""
    declared = request.headers.get("content-length")
    if declared is not None and declared.isdigit() and int(declared) > limit:
        raise HTTPException(413, f"upload of {int(declared)} bytes is larger than the "
                            f"{limit} bytes allowed")
    size = 0
    try:
        with open(path, "wb") as f:
            async for piece in request.stream():
                size += len(piece)
                if size > limit:
                    raise HTTPException(413, f"upload larger than the {limit} bytes allowed")
                f.write(piece)  # page cache: microseconds per piece
    except BaseException:
        try:
            os.unlink(path)
        except OSError:
            pass
        raise
    return size


class PickedPoints(BaseModel):
    """Manual mode: pixel points (x right, y down) picked on the image, two or more per line."""

    points: dict[str, list[list[float]]] = Field(
        description="keys horizon, left_edge, right_edge: lists of [x_px, y_px]")
    focal_px: float = Field(gt=0)
    half_width_m: float = Field(gt=0, description="runway half-width d (width / 2)")
    principal_point: list[float] = Field(min_length=2, max_length=2,
                                         description="[cx, cy] in pixels (image centre usually)")


def _overlay_png(image: Any, res: Any) -> str:
    """The image with the horizon (green), edges (red/blue) and vanishing point, as base64 PNG."""
    import cv2
    import numpy as np

    img = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR) if image.ndim == 2 else image.copy()
    h, w = img.shape[:2]

    def draw(line: Any, color: tuple[int, int, int]) -> None:
        if line is None:
            return
        a, b, c = line
        pts = []
        if abs(b) > 1e-12:
            pts = [(0, -c / b), (w - 1, -(c + a * (w - 1)) / b)]
        if abs(a) > abs(b):
            pts = [(-c / a, 0), (-(c + b * (h - 1)) / a, h - 1)]
        (x0, y0), (x1, y1) = pts
        cv2.line(img, (round(x0), round(y0)), (round(x1), round(y1)), color, 2,
                 cv2.LINE_AA)

    draw(res.horizon_px, (80, 220, 80))
    draw(res.left_edge_px, (60, 60, 230))
    draw(res.right_edge_px, (230, 120, 40))
    if res.vanishing_point_px is not None:
        u, v = res.vanishing_point_px
        cv2.circle(img, (round(u), round(v)), 6, (0, 255, 255), 2)
    ok, png = cv2.imencode(".png", np.ascontiguousarray(img))
    return base64.b64encode(png.tobytes()).decode() if ok else ""


def _lines(res: Any) -> dict[str, Any]:
    return {k: (list(map(float, v)) if v is not None else None) for k, v in
            (("horizon", res.horizon_px), ("left_edge", res.left_edge_px),
             ("right_edge", res.right_edge_px))}


def _image_pose(path: Path, focal_px: float, half_width_m: float,
                pp: tuple[float, float] | None, overlay: bool) -> dict[str, Any]:
    """Decode the uploaded image and find the runway (runs on a worker thread)."""
    import cv2
    import numpy as np

    from radar_io.errors import VisionError
    from radar_io.vision.chain import find_runway

    img = cv2.imdecode(np.fromfile(str(path), np.uint8), cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise HTTPException(422, "cannot decode the image (PNG, JPEG, BMP, TIFF … expected)")
    try:
        res = find_runway(img, focal_px, half_width_m, pp)
    except VisionError as exc:
        raise HTTPException(422, str(exc)) from exc
    out = {**res.to_dict(), "lines": _lines(res),
           "image": {"width": int(img.shape[1]), "height": int(img.shape[0])}}
    if overlay:
        out["overlay_png_base64"] = _overlay_png(img, res)
    return out


_UPLOAD_BODY = {"requestBody": {"required": True, "description": "the image or video bytes",
                                 "content": {t: {"schema": {"type": "string", "format": "binary"}}
                                             for t in ("image/png", "image/jpeg", "video/mp4",
                                                       "application/octet-stream")}}}


@router.post("/api/runway", dependencies=ADMIN, status_code=200,
             openapi_extra=_UPLOAD_BODY,
             responses={202: {"description": "video accepted as a job: {job, status_url}"},
                        **responses(401, 403, 413, 422, 429)})
async def runway(request: Request, focal_px: float = Query(gt=0, description="focal length, px"),
                 half_width_m: float = Query(gt=0, description="runway half-width d, m"),
                 cx: float | None = Query(None, description="principal point x (default centre)"),
                 cy: float | None = Query(None, description="principal point y (default centre)"),
                 overlay: bool = True) -> Any:
    """Pose from one image (body: PNG/JPEG/... bytes): bank, pitch, yaw, height above and
    lateral offset from the runway, quality, and the detected lines (``A·x + B·y + C = 0``,
    pixels). A video (``Content-Type: video/*``) is queued as a job: 202
    ``{"job", "status_url"}``; 429 when the queue is full."""
    from radar_io.errors import VisionError
    from radar_io.service.runway_jobs import QueueFull
    from radar_io.vision.chain import RunwayTracker

    pp = (cx, cy) if cx is not None and cy is not None else None
    try:
        RunwayTracker(focal_px, half_width_m, pp)  # camera parameters checked before the upload
    except VisionError as exc:
        raise HTTPException(422, str(exc)) from exc
    jobs = jobs_of(request.app)
    video = request.headers.get("content-type", "").startswith("video/")
    if video and jobs.stats()["queued"] >= jobs.max_queued:
        raise HTTPException(429, "runway job queue full: try again later")
    path = jobs.new_spool_path()
    size = await _spool(request, path, _max_body(request))
    if size == 0:
        os.unlink(path)
        raise HTTPException(422, "empty body: send the image (or video) bytes")
    if not video:
        try:
            return await run_in_threadpool(_image_pose, path, focal_px, half_width_m, pp, overlay)
        finally:
            os.unlink(path)
    try:
        job = jobs.submit(path, focal_px, half_width_m, pp)
    except QueueFull as exc:
        os.unlink(path)
        raise HTTPException(429, str(exc)) from exc
    return JSONResponse({"job": job.id, "status_url": f"/api/runway/jobs/{job.id}"},
                        status_code=202)


@router.get("/api/runway/jobs/{job_id}", responses=responses(404))
def runway_job(request: Request, job_id: str) -> dict[str, Any]:
    """A video job: state (queued, running, done, failed, cancelled), frames_done,
    frames_total (null when the container does not say), result (when done: frames, found),
    error (when failed)."""
    from radar_io.errors import NotFoundError

    try:
        return jobs_of(request.app).get(job_id).as_dict()
    except NotFoundError as exc:
        raise HTTPException(404, str(exc)) from exc


@router.delete("/api/runway/jobs/{job_id}", dependencies=ADMIN,
               responses=responses(401, 403, 404))
def runway_job_cancel(request: Request, job_id: str) -> dict[str, Any]:
    """Cancel a video job (queued: at once; running: at its next frame)."""
    from radar_io.errors import NotFoundError

    try:
        return jobs_of(request.app).cancel(job_id).as_dict()
    except NotFoundError as exc:
        raise HTTPException(404, str(exc)) from exc


@router.post("/api/runway/manual", responses=responses(422))
def runway_manual(req: PickedPoints) -> dict[str, Any]:
    """Pose from points an operator picked on the image (claims 5–6: the same maths)."""
    from radar_io.errors import VisionError
    from radar_io.vision.manual import pose_from_points

    try:
        res = pose_from_points(req.points, req.focal_px, req.half_width_m,
                               (req.principal_point[0], req.principal_point[1]))
    except VisionError as exc:
        raise HTTPException(422, str(exc)) from exc
    return {**res.to_dict(), "lines": _lines(res)}
