"""Runway vision over HTTP (runway-vision.md): upload an image or a frame sequence, or
send operator-picked points, and get the pose; images come back with the detected lines
drawn on them. Analysis only (no state changes), so no token is needed.
"""

from __future__ import annotations

import base64
import os
import tempfile
from typing import Any

from fastapi import APIRouter, HTTPException, Query, Request
from pydantic import BaseModel, Field

MAX_BODY = 512 << 20   #: bytes accepted for one upload
MAX_FRAMES = 20000     #: frames processed from one uploaded sequence

router = APIRouter(tags=["runway vision"])


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
        cv2.line(img, (int(round(x0)), int(round(y0))), (int(round(x1)), int(round(y1))), color, 2,
                 cv2.LINE_AA)

    draw(res.horizon_px, (80, 220, 80))
    draw(res.left_edge_px, (60, 60, 230))
    draw(res.right_edge_px, (230, 120, 40))
    if res.vanishing_point_px is not None:
        u, v = res.vanishing_point_px
        cv2.circle(img, (int(round(u)), int(round(v))), 6, (0, 255, 255), 2)
    ok, png = cv2.imencode(".png", np.ascontiguousarray(img))
    return base64.b64encode(png.tobytes()).decode() if ok else ""


def _lines(res: Any) -> dict[str, Any]:
    return {k: (list(map(float, v)) if v is not None else None) for k, v in
            (("horizon", res.horizon_px), ("left_edge", res.left_edge_px),
             ("right_edge", res.right_edge_px))}


@router.post("/api/runway")
async def runway(request: Request, focal_px: float = Query(gt=0, description="focal length, px"),
                 half_width_m: float = Query(gt=0, description="runway half-width d, m"),
                 cx: float | None = Query(None, description="principal point x (default centre)"),
                 cy: float | None = Query(None, description="principal point y (default centre)"),
                 overlay: bool = True) -> dict[str, Any]:
    """Pose from one image (body: PNG/JPEG/... bytes) or a frame sequence (body: a video,
    ``Content-Type: video/*``): bank, pitch, yaw, height above and lateral offset from the
    runway, quality, and the detected lines (``A·x + B·y + C = 0``, pixels)."""
    import cv2
    import numpy as np

    from radar_io.vision.chain import RunwayTracker, find_runway
    from radar_io.errors import VisionError

    body = await request.body()
    if not body:
        raise HTTPException(422, "empty body: send the image (or video) bytes")
    if len(body) > MAX_BODY:
        raise HTTPException(413, f"upload larger than {MAX_BODY >> 20} MB")
    pp = (cx, cy) if cx is not None and cy is not None else None
    ctype = request.headers.get("content-type", "")
    try:
        if ctype.startswith("video/"):
            with tempfile.NamedTemporaryFile(suffix=".video", delete=False) as f:
                f.write(body)
            try:
                cap = cv2.VideoCapture(f.name)
                if not cap.isOpened():
                    raise HTTPException(422, "cannot decode the video")
                tracker = RunwayTracker(focal_px, half_width_m, pp)
                frames: list[dict[str, Any]] = []
                while len(frames) < MAX_FRAMES:
                    ok, img = cap.read()
                    if not ok:
                        break
                    gray = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
                    frames.append({"frame": len(frames), **tracker.process(gray).to_dict()})
                cap.release()
            finally:
                os.unlink(f.name)
            if not frames:
                raise HTTPException(422, "the video holds no frames")
            return {"frames": frames, "found": sum(1 for r in frames if r["found"])}
        img = cv2.imdecode(np.frombuffer(body, np.uint8), cv2.IMREAD_GRAYSCALE)
        if img is None:
            raise HTTPException(422, "cannot decode the image (PNG, JPEG, BMP, TIFF … expected)")
        res = find_runway(img, focal_px, half_width_m, pp)
    except VisionError as exc:
        raise HTTPException(422, str(exc)) from exc
    out = {**res.to_dict(), "lines": _lines(res),
           "image": {"width": int(img.shape[1]), "height": int(img.shape[0])}}
    if overlay:
        out["overlay_png_base64"] = _overlay_png(img, res)
    return out


@router.post("/api/runway/manual")
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
