"""The runway image chain (spec §4): image → horizon + runway edges → pose.

Grab frame → threshold (Otsu) → light/dark boundaries → Hough transform →
select the horizon and the two runway edges that meet on it → refine the three
lines to sub-pixel accuracy on the grey image → vanishing point by least
squares → attitude, height and lateral offset (:func:`geometry.solve_pose`).

Use :func:`find_runway` for one image and :class:`RunwayTracker` for a sequence
(it searches a region of interest around the previous vanishing point first).
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, replace
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from radar_io.errors import VisionError
from radar_io.vision import pose_equations as g
from radar_io.vision.lines import RefinedLine, binary_edges, hough_candidates, refine_line

__all__ = [
    "ChainParams",
    "RunwayResult",
    "RunwayTracker",
    "find_runway",
    "pose_from_pixel_lines",
    "pose_from_point_sets",
    "quality_from_misclosure",
]


@dataclass(frozen=True)
class ChainParams:
    """Tuning of the image chain (defaults suit 640×480 … 1920×1080 nose-camera frames).

    ``threshold``: None for Otsu, else a fixed grey level 0..255.
    ``detect_max_width``: frames wider than this are downscaled for the Hough stage
    only (refinement always runs at full resolution).
    ``hough_theta_deg``, ``min_votes_frac``: Hough angle resolution and vote threshold
    (fraction of the searched area's smaller side); ``max_candidates``: lines refined.
    ``min_contrast``: minimum grey step across a line (grey levels).
    ``max_horizon_tilt_deg``: horizon candidates steeper than this are ignored (bank limit).
    ``max_misclosure_deg``: the edges must meet within this angle (seen from the
    camera) of the horizon to be taken for a runway.
    ``min_edge_length_frac``: each runway edge must be supported over at least this
    fraction of the image diagonal (shorter edges give no trustworthy slope).
    ``vp_margin``: the vanishing point may lie outside the frame by this fraction of its size.
    ``quality_scale_deg``: misclosure at which the quality figure is 0.5.
    ``roi_half_size``: ROI half-width/height as fractions of the frame (sequences).
    ``concurrent_fit``: re-fit the three lines through their common (vanishing)
    point before solving (:func:`geometry.fit_concurrent_lines`) — much more precise
    edge slopes, hence height; set False to use the independently fitted lines
    (e.g. when the visible horizon is displaced from the geometric one).
    """

    threshold: int | None = None
    detect_max_width: int = 640
    hough_theta_deg: float = 0.5
    min_votes_frac: float = 0.08
    max_candidates: int = 12
    min_contrast: float = 12.0
    max_horizon_tilt_deg: float = 40.0
    max_misclosure_deg: float = 1.0
    vp_margin: float = 0.25
    min_edge_length_frac: float = 0.05
    quality_scale_deg: float = 0.2
    roi_half_size: tuple[float, float] = (0.3, 0.3)
    concurrent_fit: bool = True


@dataclass(frozen=True)
class RunwayResult:
    """Outcome of one frame.

    When ``found`` is False, ``reason`` says why and the pose fields are None.
    Angles in degrees, lengths in metres (height above the runway, lateral
    offset right of the centre line, both of the aircraft reference point).
    ``quality`` (0..1) is :func:`quality_from_misclosure` of ``misclosure_deg``,
    the angle at which the two edges miss meeting on the horizon.  Lines are pixel
    lines ``(A, B, C)`` with ``A u + B v + C = 0``; ``vanishing_point_px`` is
    ``(u, v)``.
    """

    found: bool
    reason: str | None = None
    bank_deg: float | None = None
    pitch_deg: float | None = None
    yaw_deg: float | None = None
    height_m: float | None = None
    lateral_m: float | None = None
    quality: float = 0.0
    misclosure_deg: float | None = None
    vanishing_point_px: tuple[float, float] | None = None
    horizon_px: tuple[float, float, float] | None = None
    left_edge_px: tuple[float, float, float] | None = None
    right_edge_px: tuple[float, float, float] | None = None
    roi: tuple[int, int, int, int] | None = None

    @classmethod
    def not_found(cls, reason: str, roi: tuple[int, int, int, int] | None = None) -> RunwayResult:
        return cls(found=False, reason=reason, roi=roi)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (the CLI's per-image record)."""

        def r(x: float | None, nd: int) -> float | None:
            return None if x is None else round(float(x), nd)

        out: dict[str, Any] = {
            "found": self.found,
            "bank_deg": r(self.bank_deg, 4),
            "pitch_deg": r(self.pitch_deg, 4),
            "yaw_deg": r(self.yaw_deg, 4),
            "height_m": r(self.height_m, 3),
            "lateral_m": r(self.lateral_m, 3),
            "quality": round(float(self.quality), 4),
        }
        if self.found:
            out["misclosure_deg"] = r(self.misclosure_deg, 4)
            out["vanishing_point_px"] = [round(c, 2) for c in self.vanishing_point_px or ()]
        else:
            out["reason"] = self.reason
        return out


def quality_from_misclosure(misclosure_deg: float, scale_deg: float = 0.2) -> float:
    """Quality figure 0..1: ``1 / (1 + (misclosure / scale)²)`` — 1 when the three lines meet exactly,
    0.5 at ``scale_deg`` (default 0.2°), → 0 as they miss."""
    return 1.0 / (1.0 + (misclosure_deg / scale_deg) ** 2)


def _positive(x: object) -> bool:
    return isinstance(x, numbers.Real) and not isinstance(x, bool) and math.isfinite(x) and float(x) > 0


def _check_camera(focal_px: float, half_width_m: float) -> None:
    if not _positive(focal_px):
        raise VisionError(f"focal length must be a positive number of pixels, got {focal_px!r}")
    if not _positive(half_width_m):
        raise VisionError(
            f"runway half-width must be a positive number of metres, got {half_width_m!r}")


def pose_from_pixel_lines(
    horizon: NDArray[np.float64],
    edge_a: NDArray[np.float64],
    edge_b: NDArray[np.float64],
    focal_px: float,
    half_width_m: float,
    principal_point: tuple[float, float],
    camera_offset_m: tuple[float, float, float] | None = None,
    quality_scale_deg: float = 0.2,
) -> RunwayResult:
    """Solve the pose from three pixel lines (either edge order) and wrap it as a :class:`RunwayResult`."""
    _check_camera(focal_px, half_width_m)
    pp = principal_point
    sol = g.solve_pose(
        g.pixel_line_to_image(horizon, pp),
        g.pixel_line_to_image(edge_a, pp),
        g.pixel_line_to_image(edge_b, pp),
        focal_px,
        half_width_m,
        camera_offset_m,
    )
    values = [float(v) for v in (sol.bank, sol.pitch, sol.yaw, sol.height_m, sol.lateral_m)]
    if not all(math.isfinite(v) for v in values):
        return RunwayResult.not_found("degenerate lines: the runway edges are parallel in the image")
    mis_deg = math.degrees(math.atan2(float(sol.misclosure_px), focal_px))
    vu, vv = g.image_to_pixel(sol.vp_x, sol.vp_y, pp)
    return RunwayResult(
        found=True,
        bank_deg=math.degrees(values[0]),
        pitch_deg=math.degrees(values[1]),
        yaw_deg=math.degrees(values[2]),
        height_m=values[3],
        lateral_m=values[4],
        quality=quality_from_misclosure(mis_deg, quality_scale_deg),
        misclosure_deg=mis_deg,
        vanishing_point_px=(float(vu), float(vv)),
        horizon_px=tuple(g.normalise_lines(horizon).tolist()),
        left_edge_px=tuple(g.normalise_lines(g.image_line_to_pixel(sol.left_edge, pp)).tolist()),
        right_edge_px=tuple(g.normalise_lines(g.image_line_to_pixel(sol.right_edge, pp)).tolist()),
    )


def pose_from_point_sets(
    point_sets: list[tuple[NDArray[np.float64], NDArray[np.float64]]],
    focal_px: float,
    half_width_m: float,
    principal_point: tuple[float, float],
    camera_offset_m: tuple[float, float, float] | None = None,
    params: ChainParams | None = None,
) -> RunwayResult:
    """Pose from pixel points ``(u, v)`` on the horizon and on the two runway edges (either order).

    Each line is fitted by orthogonal least squares; with ``params.concurrent_fit``
    the three lines are re-fitted through their common point
    (:func:`geometry.fit_concurrent_lines`) before solving.  The quality figure
    comes from the misclosure of the independent fits; above
    ``params.max_misclosure_deg`` the result is "not found".
    """
    params = params or ChainParams()
    free = [g.fit_line(np.asarray(u, float), np.asarray(v, float)) for u, v in point_sets]
    if params.concurrent_fit:
        _, _, fitted = g.fit_concurrent_lines(point_sets)
    else:
        fitted = free
    horizon, edge_a, edge_b = fitted
    res = pose_from_pixel_lines(horizon, edge_a, edge_b, focal_px, half_width_m, principal_point,
                                camera_offset_m)
    if not res.found:
        return res
    x, y = g.intersect_lines(free[1], free[2])
    mis_px = abs(float(g.point_line_distance(free[0], x, y)))
    mis_deg = math.degrees(math.atan2(mis_px, focal_px)) if math.isfinite(mis_px) else 90.0
    if mis_deg > params.max_misclosure_deg:
        return RunwayResult.not_found(
            f"runway edges do not meet on the horizon (misclosure {mis_deg:.2f} deg > "
            f"{params.max_misclosure_deg} deg)"
        )
    return replace(res, misclosure_deg=mis_deg,
                   quality=quality_from_misclosure(mis_deg, params.quality_scale_deg))


# --------------------------------------------------------------------------- selection
@dataclass(frozen=True)
class _Pair:
    score: float
    horizon: RefinedLine
    a: RefinedLine
    b: RefinedLine


def _to_gray(image: NDArray[Any]) -> NDArray[np.uint8]:
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[:, :, 0]
    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2GRAY if img.shape[2] == 4 else cv2.COLOR_BGR2GRAY)
    if img.ndim != 2:
        raise VisionError(f"expected a grey or BGR image, got an array of shape {img.shape}")
    if img.dtype != np.uint8:  # 16-bit or float frames: scale to 0..255
        top = float(np.nanmax(img)) if img.size else 0.0
        unit_float = np.issubdtype(img.dtype, np.floating) and 0 < top <= 1.0
        scale = 255.0 / top if unit_float or top > 255 else 1.0
        img = np.clip(np.nan_to_num(img.astype(np.float64) * scale), 0, 255).round().astype(np.uint8)
    return img


def _horizon_ok(line: RefinedLine, params: ChainParams) -> bool:
    a, b = line.line[0], line.line[1]
    # brighter side (sky) up: the normal points to negative v; tilt from horizontal within the bank limit
    tilt = math.degrees(math.atan2(abs(a), abs(b)))
    return b < 0 and tilt <= params.max_horizon_tilt_deg and line.coverage >= 0.5


def _wedge_is_bright(
    gray_f: NDArray[np.float32], vp: NDArray, ea: RefinedLine, eb: RefinedLine, da: NDArray, db: NDArray
) -> bool:
    """The runway fills the wedge between its edges: sample it where both edges are supported."""
    def span(e: RefinedLine, d_: NDArray) -> tuple[float, float]:
        r = sorted((float(np.dot(e.point(e.s0) - vp, d_)), float(np.dot(e.point(e.s1) - vp, d_))))
        return r[0], r[1]

    (a0, a1), (b0, b1) = span(ea, da), span(eb, db)
    r_lo, r_hi = max(a0, b0, 0.0), min(a1, b1)
    if r_hi <= r_lo:
        r_lo, r_hi = min(a0, b0), max(a1, b1)
    r = np.linspace(r_lo, r_hi, 8)[:, None, None]
    alpha = np.array([0.25, 0.5, 0.75])[None, :, None]
    pts = (vp + r * ((1 - alpha) * da + alpha * db)).reshape(-1, 2)
    h, w = gray_f.shape
    inside = (pts[:, 0] >= 0) & (pts[:, 0] <= w - 1) & (pts[:, 1] >= 0) & (pts[:, 1] <= h - 1)
    if inside.sum() < 6:
        return False
    vals = cv2.remap(gray_f, pts[inside, 0:1].astype(np.float32), pts[inside, 1:2].astype(np.float32),
                     cv2.INTER_LINEAR)
    mid = 0.25 * (ea.dark_level + ea.bright_level + eb.dark_level + eb.bright_level)
    return float(np.mean(vals.ravel() > mid)) >= 0.7


def _select(
    cands: list[RefinedLine],
    gray_f: NDArray[np.float32],
    focal_px: float,
    params: ChainParams,
) -> tuple[_Pair | None, str]:
    """Pick the horizon and the pair of runway edges (see docs/runway-vision.md, Method 4)."""
    h, w = gray_f.shape
    horizons = sorted((c for c in cands if _horizon_ok(c, params)), key=lambda c: -c.support)[:3]
    if not horizons:
        return None, "no horizon found"
    tol_px = focal_px * math.tan(math.radians(params.max_misclosure_deg))
    min_len = params.min_edge_length_frac * math.hypot(w, h)
    lo = np.array([-params.vp_margin * w, -params.vp_margin * h])
    hi = np.array([(1 + params.vp_margin) * w, (1 + params.vp_margin) * h])
    best: _Pair | None = None
    for hz in horizons:
        hl = hz.line  # normal points to the sky
        edges = [
            c for c in cands
            if c is not hz and c.length >= min_len and float(np.dot(hl[:2], c.midpoint) + hl[2]) < -2.0
        ]
        for i in range(len(edges)):
            for j in range(i + 1, len(edges)):
                ea, eb = edges[i], edges[j]
                x, y = g.intersect_lines(ea.line, eb.line)
                vp = np.array([float(x), float(y)])
                if not np.all(np.isfinite(vp)) or np.any(vp < lo) or np.any(vp > hi):
                    continue
                if abs(float(np.dot(hl[:2], vp) + hl[2])) > tol_px:
                    continue
                # rays from the vanishing point towards each edge's support (below the horizon)
                da, db = ea.midpoint - vp, eb.midpoint - vp
                na, nb = np.linalg.norm(da), np.linalg.norm(db)
                if na < 1e-6 or nb < 1e-6:
                    continue
                da, db = da / na, db / nb
                # each edge's support lies (almost) entirely on one ray from the vanishing point
                if any(
                    min(float(np.dot(e.point(e.s0) - vp, d_)), float(np.dot(e.point(e.s1) - vp, d_)))
                    < -(3.0 + 0.15 * e.length)
                    for e, d_ in ((ea, da), (eb, db))
                ):
                    continue
                cosang = float(np.dot(da, db))
                if cosang > math.cos(math.radians(0.3)) or cosang < math.cos(math.radians(170.0)):
                    continue
                inner = vp + 10.0 * (da + db) / np.linalg.norm(da + db)
                # both edges have the runway (brighter side) inside the wedge
                if (np.dot(ea.line[:2], inner) + ea.line[2] <= 0
                        or np.dot(eb.line[:2], inner) + eb.line[2] <= 0):
                    continue
                if not _wedge_is_bright(gray_f, vp, ea, eb, da, db):
                    continue
                score = ea.support + eb.support + 0.5 * hz.support
                if best is None or score > best.score:
                    best = _Pair(score, hz, ea, eb)
    if best is None:
        return None, "no pair of runway edges meeting on the horizon"
    return best, ""


def _detect(
    gray: NDArray[np.uint8],
    gray_f: NDArray[np.float32],
    focal_px: float,
    params: ChainParams,
    roi: tuple[int, int, int, int] | None,
) -> tuple[_Pair | None, str]:
    h, w = gray.shape
    scale = min(1.0, params.detect_max_width / w)
    small = gray
    if scale < 1.0:
        small = np.asarray(cv2.resize(gray, (round(w * scale), round(h * scale)),
                                      interpolation=cv2.INTER_AREA), np.uint8)
    sh, sw = small.shape
    if roi is None:
        x0, y0, x1, y1 = 0, 0, sw, sh
    else:
        x0, y0 = max(0, int(roi[0] * scale)), max(0, int(roi[1] * scale))
        x1, y1 = min(sw, math.ceil(roi[2] * scale)), min(sh, math.ceil(roi[3] * scale))
    crop = small[y0:y1, x0:x1]
    if crop.shape[0] < 16 or crop.shape[1] < 16:
        return None, "image too small"
    _, edges = binary_edges(crop, params.threshold)
    min_votes = max(15, int(params.min_votes_frac * min(crop.shape)))
    lines = hough_candidates(edges, scale, (x0, y0), min_votes, 3 * params.max_candidates,
                             params.hough_theta_deg)
    if not lines:
        return None, "no straight light/dark boundaries in the image"
    refined: list[RefinedLine] = []
    for ln in lines:
        r = refine_line(gray_f, ln, min_contrast=params.min_contrast, step=4.0, passes=(5.0,),
                        persist=3.0, min_support=6, min_run=3)
        if r is None:
            continue
        # drop lines that converged onto one already kept
        if any(abs(float(np.dot(r.line[:2], k.line[:2]))) > math.cos(math.radians(0.5))
               and abs(float(np.dot(k.line[:2], r.midpoint) + k.line[2])) < 2.0 for k in refined):
            continue
        refined.append(r)
        if len(refined) >= params.max_candidates:
            break
    if not refined:
        return None, "no straight light/dark boundaries in the image"
    return _select(refined, gray_f, focal_px, params)


def _final_refine(
    pair: _Pair, gray_f: NDArray[np.float32], params: ChainParams
) -> tuple[RefinedLine, RefinedLine, RefinedLine]:
    """Re-fit the three lines with samples near the other lines excluded (where profiles overlap)."""
    guard = 8.0
    hz, ea, eb = pair.horizon.line, pair.a.line, pair.b.line

    def refit(line: NDArray[np.float64], others: tuple[NDArray[np.float64], ...]) -> RefinedLine | None:
        return refine_line(gray_f, line, exclude=[(o, guard) for o in others],
                           min_contrast=params.min_contrast, step=2.0, passes=(3.0, 3.0))

    new_h, new_a, new_b = refit(hz, (ea, eb)), refit(ea, (eb, hz)), refit(eb, (ea, hz))
    return new_h or pair.horizon, new_a or pair.a, new_b or pair.b


def find_runway(
    image: NDArray[Any],
    focal_px: float,
    half_width_m: float,
    principal_point: tuple[float, float] | None = None,
    *,
    camera_offset_m: tuple[float, float, float] | None = None,
    params: ChainParams | None = None,
    roi: tuple[int, int, int, int] | None = None,
) -> RunwayResult:
    """Run the image chain on one frame and return a :class:`RunwayResult`.

    ``image`` is a grey ``(H, W)`` or BGR/BGRA ``(H, W, 3|4)`` array, normally uint8
    (16-bit and float frames are scaled to 0..255).

    ``focal_px`` focal length [px]; ``half_width_m`` runway half-width ``d`` [m];
    ``principal_point`` ``(u, v)`` [px] (default: image centre ``((W-1)/2, (H-1)/2)``);
    ``camera_offset_m`` camera position relative to the aircraft reference point in
    body axes (forward, right, down) [m]; ``roi`` ``(u0, v0, u1, v1)`` restricts the
    Hough search (the refinement still uses whole lines).  Never raises for image
    content: "no runway" comes back as ``found=False`` with a reason.
    """
    _check_camera(focal_px, half_width_m)
    params = params or ChainParams()
    gray = _to_gray(image)
    h, w = gray.shape
    if min(h, w) < 32:
        return RunwayResult.not_found(f"image too small ({w}x{h})", roi)
    pp = principal_point or ((w - 1) / 2.0, (h - 1) / 2.0)
    gray_f = np.asarray(cv2.GaussianBlur(gray.astype(np.float32), (0, 0), 1.0), np.float32)
    pair, reason = _detect(gray, gray_f, focal_px, params, roi)
    if pair is None:
        return RunwayResult.not_found(reason, roi)
    lines3 = _final_refine(pair, gray_f, params)
    res = pose_from_point_sets(
        [(r.points[:, 0], r.points[:, 1]) for r in lines3], focal_px, half_width_m, pp, camera_offset_m,
        params,
    )
    return replace(res, roi=roi)


class RunwayTracker:
    """Sequence processing: search a region of interest around the previous vanishing point first.

    Falls back to the whole frame when the ROI search fails (or on the first frame).
    """

    def __init__(
        self,
        focal_px: float,
        half_width_m: float,
        principal_point: tuple[float, float] | None = None,
        *,
        camera_offset_m: tuple[float, float, float] | None = None,
        params: ChainParams | None = None,
    ) -> None:
        _check_camera(focal_px, half_width_m)
        self.focal_px = focal_px
        self.half_width_m = half_width_m
        self.principal_point = principal_point
        self.camera_offset_m = camera_offset_m
        self.params = params or ChainParams()
        self._last_vp: tuple[float, float] | None = None

    def _roi(self, shape: tuple[int, int]) -> tuple[int, int, int, int] | None:
        if self._last_vp is None:
            return None
        h, w = shape[:2]
        fx, fy = self.params.roi_half_size
        u, v = self._last_vp
        u0, u1 = int(max(0, u - fx * w)), int(min(w, u + fx * w))
        v0, v1 = int(max(0, v - fy * h)), int(min(h, v + fy * h))
        if u1 - u0 < 32 or v1 - v0 < 32:
            return None
        return (u0, v0, u1, v1)

    def process(self, image: NDArray[Any]) -> RunwayResult:
        """Process the next frame."""
        roi = self._roi(np.asarray(image).shape)
        def find(area: tuple[int, int, int, int] | None) -> RunwayResult:
            return find_runway(image, self.focal_px, self.half_width_m, self.principal_point,
                               camera_offset_m=self.camera_offset_m, params=self.params, roi=area)

        res = find(roi)
        if not res.found and roi is not None:
            res = find(None)
        self._last_vp = res.vanishing_point_px if res.found else None
        return res
