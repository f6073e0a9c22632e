"""Forward projector and synthetic runway-image renderer (ground truth for tests and the benchmark).

The renderer draws, for a known pose, an infinite flat ground plane with a sky
gradient above its horizon and a light (concrete) runway strip of half-width
``d``, using only the pinhole projection of spec eq. (1)–(2)
(:func:`radar_io.vision.pose_equations.project_points`) and polygon clipping — never
the inverse formulas — so it is an independent check of them.  Edges are
anti-aliased by exact pixel-area coverage.  Optional clutter: patchy ground
texture, haze near the horizon, grey clouds, dark roads on the ground, bright
buildings, thin wires across the frame; then Gaussian blur and noise.

Pixel coordinates follow OpenCV: ``(u, v)``, ``v`` down, ``(0, 0)`` the centre of
the top-left pixel; the default principal point is the image centre
``((W - 1) / 2, (H - 1) / 2)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from radar_io.vision import pose_equations as g

__all__ = ["RunwayPose", "RunwayScene", "expected_lines", "focal_for_fov", "render_runway",
           "visible_edge_lengths"]


@dataclass(frozen=True)
class RunwayPose:
    """True aircraft pose relative to the runway (the renderer's input).

    Angles in degrees (bank right-wing-down positive, pitch nose-up positive, yaw
    nose-right of the runway direction positive); ``height_m`` above the runway and
    ``lateral_m`` right of the centre line refer to the aircraft reference point;
    ``camera_offset_m`` is the camera position relative to it in body axes
    ``(forward, right, down)``.
    """

    bank_deg: float
    pitch_deg: float
    yaw_deg: float
    height_m: float
    lateral_m: float
    camera_offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def angles_rad(self) -> tuple[float, float, float]:
        return math.radians(self.bank_deg), math.radians(self.pitch_deg), math.radians(self.yaw_deg)

    def camera_position(self) -> NDArray[np.float64]:
        """Camera centre ``(x0, y0, z0)`` in the runway frame [m] (reference point at ``x = 0``)."""
        rot = g.rotation_matrix(*self.angles_rad)
        ref = np.array([0.0, self.lateral_m, -self.height_m])
        return ref + rot.T @ np.asarray(self.camera_offset_m, dtype=float)


@dataclass(frozen=True)
class RunwayScene:
    """What to draw.  The runway runs from ``runway_start_m`` to ``runway_start_m + runway_length_m``
    relative to the camera's ``x0`` [m]; ``clutter`` switches the items in ``clutter_items`` on;
    blur and noise in pixels and grey levels; levels are mean grey values (0..255)."""

    half_width_m: float = 22.5
    runway_start_m: float = -300.0
    runway_length_m: float = 4000.0
    clutter: bool = True
    clutter_items: frozenset[str] = frozenset({"texture", "haze", "clouds", "roads", "buildings", "wires"})
    noise_sigma: float = 4.0
    blur_sigma: float = 0.8
    seed: int = 0
    sky_horizon_level: float = 215.0
    sky_zenith_level: float = 165.0
    ground_level: float = 95.0
    runway_level: float = 172.0


def focal_for_fov(width_px: int, hfov_deg: float = 60.0) -> float:
    """Focal length [px] giving horizontal field of view ``hfov_deg`` across ``width_px`` pixels."""
    return (width_px / 2.0) / math.tan(math.radians(hfov_deg) / 2.0)


def _default_pp(width: int, height: int) -> tuple[float, float]:
    return (width - 1) / 2.0, (height - 1) / 2.0


def expected_lines(
    pose: RunwayPose,
    focal_px: float,
    width: int,
    height: int,
    half_width_m: float = 22.5,
    principal_point: tuple[float, float] | None = None,
) -> dict[str, NDArray[np.float64]]:
    """True pixel lines ``A u + B v + C = 0`` (normalised) of the horizon and the right/left runway edges."""
    pp = principal_point or _default_pp(width, height)
    bank, pitch, yaw = pose.angles_rad
    cam = pose.camera_position()
    origin = np.zeros(3)
    pts = []
    for ang in (-0.3, 0.3):  # two horizontal directions in view: points at infinity of z = 0
        direction = np.array([math.cos(yaw + ang), math.sin(yaw + ang), 0.0])
        x, y, _ = g.project_points(direction, origin, bank, pitch, yaw, focal_px)
        pts.append((x, y))
    horizon = g.line_through(*pts)
    right, left = g.runway_edge_lines(bank, pitch, yaw, cam[1], -cam[2], half_width_m, focal_px)
    return {
        "horizon": g.normalise_lines(g.image_line_to_pixel(horizon, pp)),
        "right_edge": g.normalise_lines(g.image_line_to_pixel(right, pp)),
        "left_edge": g.normalise_lines(g.image_line_to_pixel(left, pp)),
    }


def visible_edge_lengths(
    pose: RunwayPose,
    width: int,
    height: int,
    focal_px: float,
    scene: RunwayScene | None = None,
    principal_point: tuple[float, float] | None = None,
    margin_px: float = 8.0,
    horizon_clearance_px: float = 10.0,
) -> tuple[float, float]:
    """Image length [px] of the right and left runway edges that is in the frame (``margin_px``
    inside its border) and at least ``horizon_clearance_px`` below the horizon — how much of each
    edge a detector can actually use."""
    sc = scene or RunwayScene()
    pp = principal_point or _default_pp(width, height)
    cam = pose.camera_position()
    hz = expected_lines(pose, focal_px, width, height, sc.half_width_m, pp)["horizon"]
    if hz[1] > 0:
        hz = -hz  # normal towards the sky
    xs = cam[0] + sc.runway_start_m + np.geomspace(1.0, sc.runway_length_m + 1.0, 4000) - 1.0
    out = []
    for side in (1.0, -1.0):
        pts = np.stack([xs, np.full_like(xs, side * sc.half_width_m), np.zeros_like(xs)], -1)
        x, y, depth = g.project_points(pts, cam, *pose.angles_rad, focal_px)
        u, v = g.image_to_pixel(x, y, pp)
        ok = (
            (depth > 0.5)
            & (u >= margin_px) & (u <= width - 1 - margin_px)
            & (v >= margin_px) & (v <= height - 1 - margin_px)
            & (hz[0] * u + hz[1] * v + hz[2] <= -horizon_clearance_px)
        )
        both = ok[1:] & ok[:-1]
        out.append(float(np.sum(np.hypot(np.diff(u), np.diff(v))[both])))
    return out[0], out[1]


# --------------------------------------------------------------------------- polygon helpers
def _clip(poly: NDArray[np.float64], value: NDArray[np.float64]) -> NDArray[np.float64]:
    """Sutherland–Hodgman: keep the part of polygon ``poly`` (n, k) where the affine ``value`` (n,) >= 0."""
    out = []
    n = len(poly)
    for i in range(n):
        p, q = poly[i], poly[(i + 1) % n]
        vp, vq = value[i], value[(i + 1) % n]
        if vp >= 0:
            out.append(p)
        if (vp >= 0) != (vq >= 0):
            out.append(p + (q - p) * (vp / (vp - vq)))
    return np.array(out).reshape(-1, poly.shape[1])


def _clip_rect(poly: NDArray[np.float64], x0: float, y0: float, x1: float, y1: float) -> NDArray[np.float64]:
    for a, b, c in ((1, 0, -x0), (-1, 0, x1), (0, 1, -y0), (0, -1, y1)):
        if len(poly) == 0:
            break
        poly = _clip(poly, a * poly[:, 0] + b * poly[:, 1] + c)
    return poly


def _halfplane_coverage(d: NDArray[np.float64], nx: float, ny: float) -> NDArray[np.float64]:
    """Exact area of a unit pixel inside the half-plane ``n . p + c >= 0`` (``|n| = 1``).

    ``d`` is ``n . centre + c`` at the pixel centres.  The pixel's extent along ``n``
    is the sum of two uniform variables of widths ``|nx|`` and ``|ny|``, whose CDF at
    ``d`` is the covered fraction.
    """
    w1, w2 = max(abs(nx), abs(ny)), min(abs(nx), abs(ny))
    lo, hi = 0.5 * (w1 - w2), 0.5 * (w1 + w2)
    x = np.abs(d)
    inner = 0.5 + x / w1
    ramp = 1.0 - (hi - np.minimum(x, hi)) ** 2 / (2.0 * w1 * w2) if w2 > 1e-12 else np.ones_like(x)
    cov = np.where(x <= lo, inner, ramp)
    return np.where(d >= 0, cov, 1.0 - cov)


class _Canvas:
    """Anti-aliased (exact area coverage) rasteriser for convex pixel-coordinate polygons."""

    def __init__(self, width: int, height: int):
        self.w, self.h = width, height

    def coverage(self, poly: NDArray[np.float64]) -> NDArray[np.float32]:
        """Fraction (0..1) of each pixel inside the convex polygon ``poly`` (n, 2).

        Exact wherever a single polygon edge crosses a pixel; at vertices the
        half-plane fractions are multiplied (a close approximation).
        """
        out = np.zeros((self.h, self.w), np.float32)
        poly = _clip_rect(np.asarray(poly, float), -2.0, -2.0, self.w + 1.0, self.h + 1.0)
        if len(poly) < 3:
            return out
        u0, v0 = (max(0, math.floor(poly[:, k].min())) for k in (0, 1))
        u1 = min(self.w, math.ceil(poly[:, 0].max()) + 1)
        v1 = min(self.h, math.ceil(poly[:, 1].max()) + 1)
        if u1 <= u0 or v1 <= v0:
            return out
        uu, vv = np.meshgrid(np.arange(u0, u1, dtype=float), np.arange(v0, v1, dtype=float))
        e = np.roll(poly, -1, axis=0) - poly
        length = np.linalg.norm(e, axis=1)
        area2 = float(np.sum(poly[:, 0] * np.roll(poly[:, 1], -1) - np.roll(poly[:, 0], -1) * poly[:, 1]))
        sign = 1.0 if area2 > 0 else -1.0
        cov = np.ones_like(uu)
        corners = np.array([[u0, v0], [u1 - 1, v0], [u0, v1 - 1], [u1 - 1, v1 - 1]], float)
        for (px, py), (ex, ey), ln in zip(poly, e, length, strict=True):
            if ln < 1e-9:
                continue
            nx, ny = -sign * ey / ln, sign * ex / ln  # inward normal
            if np.min(nx * (corners[:, 0] - px) + ny * (corners[:, 1] - py)) >= 0.75:
                continue  # the whole box is inside this edge's half-plane
            cov *= _halfplane_coverage(nx * (uu - px) + ny * (vv - py), nx, ny)
        out[v0:v1, u0:u1] = cov
        return out


def _ground_polygon_px(
    corners_m: NDArray[np.float64],
    cam: NDArray[np.float64],
    angles: tuple[float, float, float],
    focal_px: float,
    pp: tuple[float, float],
    near_m: float = 0.05,
) -> NDArray[np.float64]:
    """Project a ground polygon (n, 3) to pixels after clipping it to the part in front of the camera."""
    rot = g.rotation_matrix(*angles)
    camf = (corners_m - cam) @ rot.T  # camera-frame coordinates
    camf = _clip(camf, camf[:, 0] - near_m)
    if len(camf) < 3:
        return np.zeros((0, 2))
    x = focal_px * camf[:, 1] / camf[:, 0]
    y = -focal_px * camf[:, 2] / camf[:, 0]
    u, v = g.image_to_pixel(x, y, pp)
    return np.stack([u, v], -1)


def render_runway(
    pose: RunwayPose,
    width: int,
    height: int,
    focal_px: float,
    scene: RunwayScene | None = None,
    principal_point: tuple[float, float] | None = None,
) -> NDArray[np.uint8]:
    """Render a grey-scale ``(height, width)`` uint8 nose-camera image of the runway for ``pose``."""
    sc = scene or RunwayScene()
    pp = principal_point or _default_pp(width, height)
    rng = np.random.default_rng(sc.seed)
    canvas = _Canvas(width, height)
    angles = pose.angles_rad
    cam = pose.camera_position()
    lines = expected_lines(pose, focal_px, width, height, sc.half_width_m, pp)
    items = sc.clutter_items if sc.clutter else frozenset()

    # signed distance above the horizon [px] on the pixel grid (horizon normal points to the sky)
    hz = lines["horizon"].copy()
    if hz[1] > 0:  # (A, B) must point up, i.e. towards negative v
        hz = -hz
    uu, vv = np.meshgrid(np.arange(width, dtype=np.float32), np.arange(height, dtype=np.float32))
    above = hz[0] * uu + hz[1] * vv + hz[2]

    # sky: half-plane above the horizon; sky gradient darkens upward
    rect = np.array([[-0.5, -0.5], [width - 0.5, -0.5], [width - 0.5, height - 0.5], [-0.5, height - 0.5]])
    sky_poly = _clip(rect, hz[0] * rect[:, 0] + hz[1] * rect[:, 1] + hz[2])
    sky_cov = canvas.coverage(sky_poly)
    t = np.clip(above, 0, None) / (0.6 * height)
    sky = sc.sky_horizon_level + (sc.sky_zenith_level - sc.sky_horizon_level) * (1.0 - np.exp(-t))

    ground = np.full((height, width), sc.ground_level, np.float32)
    runway_level = np.full((height, width), sc.runway_level, np.float32)

    def smooth_noise(cells: tuple[int, int], amp: float, interp: int) -> NDArray[np.float32]:
        small = rng.normal(0.0, amp, cells[::-1]).astype(np.float32)
        return np.asarray(cv2.resize(small, (width, height), interpolation=interp), np.float32)

    if "texture" in items:  # fields, patches and fine grain; a grainy runway
        ground += smooth_noise((10, 8), 12.0, cv2.INTER_CUBIC)
        ground += cv2.GaussianBlur(smooth_noise((24, 18), 9.0, cv2.INTER_NEAREST), (0, 0), 1.0)
        ground += cv2.GaussianBlur(rng.normal(0, 10.0, (height, width)).astype(np.float32), (0, 0), 1.2)
        runway_level += cv2.GaussianBlur(rng.normal(0, 6.0, (height, width)).astype(np.float32), (0, 0), 1.0)
    if "haze" in items:  # ground lightens toward the horizon
        ground += 30.0 * np.exp(-np.clip(-above, 0, None) / (0.06 * height))
    for _ in range(rng.integers(1, 4) if "clouds" in items else 0):  # grey clouds in the sky
        cloud = np.zeros((height, width), np.float32)
        c = (int(rng.uniform(0, width)), int(rng.uniform(0, height)))
        axes = (int(rng.uniform(0.05, 0.2) * width), int(rng.uniform(0.02, 0.06) * height))
        cv2.ellipse(cloud, c, axes, float(rng.uniform(-10, 10)), 0, 360, 1.0, -1)
        cloud = np.asarray(cv2.GaussianBlur(cloud, (0, 0), max(2.0, 0.01 * width)), np.float32)
        sky += cloud * float(rng.uniform(-45.0, -20.0))
    for _ in range(rng.integers(1, 4) if "roads" in items else 0):  # dark roads on the ground, any direction
        ang = rng.uniform(0, math.pi)
        dist = rng.uniform(200.0, 2000.0)
        cx, cy = cam[0] + dist * math.cos(angles[2]), cam[1] + rng.uniform(-800, 800)
        w2 = rng.uniform(3.0, 6.0)
        dx, dy = math.cos(ang), math.sin(ang)
        corners = np.array(
            [
                [cx - 3000 * dx - w2 * dy, cy - 3000 * dy + w2 * dx, 0.0],
                [cx + 3000 * dx - w2 * dy, cy + 3000 * dy + w2 * dx, 0.0],
                [cx + 3000 * dx + w2 * dy, cy + 3000 * dy - w2 * dx, 0.0],
                [cx - 3000 * dx + w2 * dy, cy - 3000 * dy - w2 * dx, 0.0],
            ]
        )
        road = canvas.coverage(_ground_polygon_px(corners, cam, angles, focal_px, pp))
        ground = ground * (1 - road) + road * float(rng.uniform(45.0, 70.0))

    runway_corners = np.array(
        [
            [cam[0] + sc.runway_start_m, -sc.half_width_m, 0.0],
            [cam[0] + sc.runway_start_m + sc.runway_length_m, -sc.half_width_m, 0.0],
            [cam[0] + sc.runway_start_m + sc.runway_length_m, sc.half_width_m, 0.0],
            [cam[0] + sc.runway_start_m, sc.half_width_m, 0.0],
        ]
    )
    rw_poly = _ground_polygon_px(runway_corners, cam, angles, focal_px, pp)
    rw_cov = canvas.coverage(rw_poly)
    ground = ground * (1 - rw_cov) + runway_level * rw_cov

    img = sky * sky_cov + ground * (1 - sky_cov)

    for _ in range(rng.integers(3, 8) if "buildings" in items else 0):  # bright, on the ground side
        u, v = rng.uniform(0, width), rng.uniform(0, height)
        if above[min(int(v), height - 1), min(int(u), width - 1)] > 0:
            continue
        size = rng.uniform(0.004, 0.02) * width
        box = cv2.boxPoints(((u, v), (size, size * rng.uniform(0.5, 1.5)), float(rng.uniform(0, 90))))
        cov = canvas.coverage(box.astype(float))
        img = img * (1 - cov) + cov * float(rng.uniform(170.0, 230.0))
    for _ in range(rng.integers(0, 3) if "wires" in items else 0):  # thin dark lines anywhere
        p = rng.uniform([0, 0], [width, height])
        ang = rng.uniform(0, math.pi)
        dvec = np.array([math.cos(ang), math.sin(ang)])
        nvec = np.array([-dvec[1], dvec[0]]) * rng.uniform(0.5, 1.2)
        ln = rng.uniform(0.2, 0.8) * width
        poly = np.array([p - ln * dvec - nvec, p + ln * dvec - nvec,
                         p + ln * dvec + nvec, p - ln * dvec + nvec])
        cov = canvas.coverage(poly)
        img = img * (1 - cov) + cov * float(rng.uniform(30.0, 90.0))

    if sc.blur_sigma > 0:
        img = cv2.GaussianBlur(img, (0, 0), sc.blur_sigma)
    if sc.noise_sigma > 0:
        img = img + rng.normal(0.0, sc.noise_sigma, img.shape).astype(np.float32)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)
