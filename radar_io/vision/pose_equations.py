"""Runway-vision geometry: pure, vectorised maths of spec ``runway-vision.md`` §1–§3.

Frames and units (all functions; angles in **radians**, lengths in **metres**,
image quantities in **pixels**):

* **Earth (runway) frame** — origin on the runway centre line, ``x`` along the
  centre line (forward, the landing direction), ``y`` to the right, ``z`` down.
  The runway edges are the lines ``y = +d`` (right) and ``y = -d`` (left) in
  ``z = 0``.  A camera in flight has ``z0 < 0``; *height* is ``-z0``.
* **Camera frame** — ``X`` forward along the optical axis, ``Y`` right, ``Z``
  down; earth → camera rotation ``a_ij = c_ij`` of calibration.md §1
  (``R_x(bank) R_y(pitch) R_z(yaw)``).  The camera is assumed bore-sighted with
  the aircraft body axes, so these are also the aircraft's Euler angles.
* **Image frame** (the spec's ``x', y'``) — origin at the principal point,
  ``x'`` to the right and ``y'`` **up**, in pixels.  Pixel coordinates ``(u, v)``
  used by OpenCV have ``v`` **down** with ``(0, 0)`` the centre of the top-left
  pixel: ``x' = u - cx`` and ``y' = cy - v``  (see :func:`pixel_to_image`).
* **Bank-corrected image** (``x'', y''``) — the image rotated by the bank angle
  about the principal point, i.e. the image a camera with zero bank would see:
  ``x'' = cos φ x' + sin φ y'``, ``y'' = -sin φ x' + cos φ y'``.

Image lines are homogeneous 3-vectors ``(a, b, c)`` meaning ``a x + b y + c = 0``;
arrays of lines have shape ``(..., 3)``.  Every function broadcasts over leading
dimensions.

The height/lateral equations (17)–(20) of the spec use the edge slopes
``k = dy''/dx''``, which pass through infinity when an edge is vertical in the
bank-corrected image (camera straight above that edge, at zero pitch or yaw).
:func:`solve_pose` therefore uses the inverse slopes ``m = 1/k = dx''/dy''``,
which stay finite for every edge below the horizon; :func:`edge_slopes` and
:func:`position_from_slopes` keep the spec's literal form for cross-checking.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "PoseSolution",
    "bank_correct",
    "edge_slopes",
    "fit_concurrent_lines",
    "fit_line",
    "horizon_line",
    "image_line_to_pixel",
    "image_to_pixel",
    "intersect_lines",
    "least_squares_point",
    "line_through",
    "normalise_lines",
    "pixel_line_to_image",
    "pixel_to_image",
    "point_line_distance",
    "position_from_inverse_slopes",
    "position_from_slopes",
    "project_points",
    "rotation_matrix",
    "runway_edge_lines",
    "solve_pose",
    "vanishing_point",
]

Array = NDArray[np.float64]


def _f(x: ArrayLike) -> Array:
    return np.asarray(x, dtype=np.float64)


# --------------------------------------------------------------------------- frames
def rotation_matrix(bank: ArrayLike, pitch: ArrayLike, yaw: ArrayLike) -> Array:
    """Earth → camera rotation ``C = R_x(bank) R_y(pitch) R_z(yaw)``, shape ``(..., 3, 3)``.

    Element ``[..., i-1, j-1]`` is ``c_ij`` of calibration.md §1 (the spec's
    ``a_ij``): camera-frame vector = ``C @`` earth-frame vector.  Angles in rad.
    """
    phi, th, psi = np.broadcast_arrays(_f(bank), _f(pitch), _f(yaw))
    sf, cf = np.sin(phi), np.cos(phi)
    st, ct = np.sin(th), np.cos(th)
    sp, cp = np.sin(psi), np.cos(psi)
    rows = [
        [ct * cp, ct * sp, -st],
        [sf * st * cp - cf * sp, sf * st * sp + cf * cp, sf * ct],
        [cf * st * cp + sf * sp, cf * st * sp - sf * cp, cf * ct],
    ]
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def pixel_to_image(u: ArrayLike, v: ArrayLike, principal_point: tuple[float, float]) -> tuple[Array, Array]:
    """Pixel ``(u right, v down)`` → spec image coordinates ``(x' right, y' up)`` about the
    principal point."""
    cx, cy = principal_point
    return _f(u) - cx, cy - _f(v)


def image_to_pixel(x: ArrayLike, y: ArrayLike, principal_point: tuple[float, float]) -> tuple[Array, Array]:
    """Spec image coordinates ``(x' right, y' up)`` → pixel ``(u right, v down)``."""
    cx, cy = principal_point
    return _f(x) + cx, cy - _f(y)


def pixel_line_to_image(line: ArrayLike, principal_point: tuple[float, float]) -> Array:
    """Pixel line ``A u + B v + C = 0`` → image line ``a x' + b y' + c = 0`` (same point set)."""
    ln = _f(line)
    cx, cy = principal_point
    a, b, c = ln[..., 0], ln[..., 1], ln[..., 2]
    return np.stack([a, -b, c + a * cx + b * cy], axis=-1)


def image_line_to_pixel(line: ArrayLike, principal_point: tuple[float, float]) -> Array:
    """Image line ``a x' + b y' + c = 0`` → pixel line ``A u + B v + C = 0`` (same point set)."""
    ln = _f(line)
    cx, cy = principal_point
    a, b, c = ln[..., 0], ln[..., 1], ln[..., 2]
    return np.stack([a, -b, c - a * cx + b * cy], axis=-1)


# --------------------------------------------------------------------------- forward model
def project_points(
    points: ArrayLike,
    camera_position: ArrayLike,
    bank: ArrayLike,
    pitch: ArrayLike,
    yaw: ArrayLike,
    focal_px: ArrayLike,
) -> tuple[Array, Array, Array]:
    """Pinhole projection, spec eq. (1)–(2).

    ``points`` ``(..., 3)`` earth-frame points [m]; ``camera_position`` ``(..., 3)``
    camera centre ``(x0, y0, z0)`` [m].  Returns image ``x'`` (right) and ``y'`` (up)
    [px] and the depth ``X_c`` along the optical axis [m] (the denominator; only
    points with ``X_c > 0`` are in front of the camera).
    """
    rot = rotation_matrix(bank, pitch, yaw)
    delta = _f(points) - _f(camera_position)
    cam = np.einsum("...ij,...j->...i", rot, delta)
    f = _f(focal_px)
    depth = cam[..., 0]
    return f * cam[..., 1] / depth, -f * cam[..., 2] / depth, depth


def vanishing_point(
    bank: ArrayLike, pitch: ArrayLike, yaw: ArrayLike, focal_px: ArrayLike
) -> tuple[Array, Array]:
    """Image of the runway direction at infinity, eq. (3)–(4): ``x'_v = f a21/a11``,
    ``y'_v = -f a31/a11`` [px]."""
    rot = rotation_matrix(bank, pitch, yaw)
    f = _f(focal_px)
    return f * rot[..., 1, 0] / rot[..., 0, 0], -f * rot[..., 2, 0] / rot[..., 0, 0]


def horizon_line(bank: ArrayLike, pitch: ArrayLike, focal_px: ArrayLike) -> Array:
    """Horizon of the ``z = 0`` plane, eq. (9) ``y' = tanφ x' - f tanθ / cosφ``, as a normalised
    image line."""
    phi, th = _f(bank), _f(pitch)
    f = _f(focal_px)
    # -sinφ x' + cosφ y' + f tanθ = 0   (eq. 9 multiplied by cosφ)
    phi, th, f = np.broadcast_arrays(phi, th, f)
    return np.stack([-np.sin(phi), np.cos(phi), f * np.tan(th)], axis=-1)


def runway_edge_lines(
    bank: ArrayLike,
    pitch: ArrayLike,
    yaw: ArrayLike,
    camera_lateral_m: ArrayLike,
    camera_height_m: ArrayLike,
    half_width_m: ArrayLike,
    focal_px: ArrayLike,
) -> tuple[Array, Array]:
    """Image lines of the right (``y = +d``) and left (``y = -d``) runway edges.

    Built with eq. (1)–(2) from a ground point of each edge and the edges' common
    point at infinity (independent of eq. 3–4 and 17–20).  ``camera_height_m`` is ``-z0`` of
    the camera.  Returns ``(right, left)`` normalised image lines.
    """
    bank, pitch, yaw, y0, h, d, f = np.broadcast_arrays(
        _f(bank), _f(pitch), _f(yaw), _f(camera_lateral_m), _f(camera_height_m), _f(half_width_m),
        _f(focal_px),
    )
    cam = np.stack([np.zeros_like(y0), y0, -h], axis=-1)
    origin = np.zeros_like(cam)
    # the edge's point at infinity (runway direction) is the same for both edges
    vx, vy, _ = project_points(np.stack([np.ones_like(h), 0 * h, 0 * h], -1), origin, bank, pitch, yaw, f)
    # a near point well in front of the camera (positive depth for |pitch|, |yaw| < 90 deg)
    near = 2.0 * (h + np.abs(y0) + d) / (np.cos(pitch) * np.cos(yaw))
    out = []
    for side in (1.0, -1.0):
        p = np.stack([near, side * d, 0 * h], axis=-1)
        x, y, _ = project_points(p, cam, bank, pitch, yaw, f)
        out.append(line_through((x, y), (vx, vy)))
    return out[0], out[1]


# --------------------------------------------------------------------------- line algebra
def normalise_lines(lines: ArrayLike) -> Array:
    """Scale homogeneous lines so that ``a² + b² = 1`` (then ``a x + b y + c`` is a signed distance)."""
    ln = _f(lines)
    return ln / np.hypot(ln[..., 0], ln[..., 1])[..., None]


def line_through(p: tuple[ArrayLike, ArrayLike], q: tuple[ArrayLike, ArrayLike]) -> Array:
    """Normalised line through points ``p = (x, y)`` and ``q = (x, y)``."""
    px, py = _f(p[0]), _f(p[1])
    qx, qy = _f(q[0]), _f(q[1])
    ln = np.cross(np.stack([px, py, np.ones_like(px)], -1), np.stack([qx, qy, np.ones_like(qx)], -1))
    return normalise_lines(ln)


def intersect_lines(l1: ArrayLike, l2: ArrayLike) -> tuple[Array, Array]:
    """Intersection point ``(x, y)`` of two lines (``inf``/``nan`` if parallel)."""
    h = np.cross(_f(l1), _f(l2))
    with np.errstate(divide="ignore", invalid="ignore"):
        return h[..., 0] / h[..., 2], h[..., 1] / h[..., 2]


def point_line_distance(line: ArrayLike, x: ArrayLike, y: ArrayLike) -> Array:
    """Signed perpendicular distance of point ``(x, y)`` from ``line`` (positive on the ``(a, b)`` side)."""
    ln = normalise_lines(line)
    return ln[..., 0] * _f(x) + ln[..., 1] * _f(y) + ln[..., 2]


def least_squares_point(lines: ArrayLike, weights: ArrayLike | None = None) -> tuple[Array, Array]:
    """Point minimising the (weighted) sum of squared perpendicular distances to ``lines`` ``(..., n, 3)``."""
    ln = normalise_lines(lines)
    w = np.ones(ln.shape[:-1]) if weights is None else np.broadcast_to(_f(weights), ln.shape[:-1])
    a, b, c = ln[..., 0], ln[..., 1], ln[..., 2]
    saa, sab, sbb = (w * a * a).sum(-1), (w * a * b).sum(-1), (w * b * b).sum(-1)
    sac, sbc = (w * a * c).sum(-1), (w * b * c).sum(-1)
    det = saa * sbb - sab * sab
    with np.errstate(divide="ignore", invalid="ignore"):
        return (-sac * sbb + sbc * sab) / det, (-sbc * saa + sac * sab) / det


def fit_line(x: ArrayLike, y: ArrayLike) -> Array:
    """Total-least-squares (orthogonal) line through points ``x, y`` ``(..., n)``; needs two
    distinct points."""
    x, y = _f(x), _f(y)
    mx, my = x.mean(-1), y.mean(-1)
    dx, dy = x - mx[..., None], y - my[..., None]
    sxx, syy, sxy = (dx * dx).sum(-1), (dy * dy).sum(-1), (dx * dy).sum(-1)
    # direction of largest spread: angle 0.5*atan2(2sxy, sxx-syy); normal is perpendicular
    ang = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)
    a, b = -np.sin(ang), np.cos(ang)
    return np.stack([a, b, -(a * mx + b * my)], axis=-1)


def fit_concurrent_lines(
    point_sets: Sequence[tuple[ArrayLike, ArrayLike]], iterations: int = 3
) -> tuple[float, float, list[Array]]:
    """Fit lines to several point sets under the constraint that they all meet in one point.

    Used for the horizon and the two runway edges, which (for a level runway and a
    flat earth) meet in the vanishing point.  Each set ``(x, y)`` needs two distinct
    points.  The common point is the least-squares intersection of the independent
    total-least-squares lines, each weighted by the inverse variance of its position
    at that point (``1/n + (s - s̄)² / Σ(s_i - s̄)²`` along the line, a common noise
    level assumed), iterated; each line is then re-fitted through it (orthogonal
    regression about the pivot).  Returns ``(x_v, y_v, lines)``.
    """
    sets = [(_f(x).ravel(), _f(y).ravel()) for x, y in point_sets]
    free = [fit_line(x, y) for x, y in sets]
    lines = np.stack(free)
    vx, vy = least_squares_point(lines)
    for _ in range(iterations):
        w = []
        for (x, y), ln in zip(sets, free, strict=True):
            t = np.array([-ln[1], ln[0]])
            s = x * t[0] + y * t[1]
            sbar = s.mean()
            spread = float(((s - sbar) ** 2).sum())
            s_v = float(vx * t[0] + vy * t[1])
            w.append(1.0 / (1.0 / len(s) + (s_v - sbar) ** 2 / max(spread, 1e-12)))
        vx, vy = least_squares_point(lines, np.array(w))
    out = []
    for x, y in sets:
        dx, dy = x - vx, y - vy
        sxx, syy, sxy = float(dx @ dx), float(dy @ dy), float(dx @ dy)
        ang = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)
        a, b = -np.sin(ang), np.cos(ang)
        out.append(np.array([a, b, -(a * vx + b * vy)]))
    return float(vx), float(vy), out


def bank_correct(x: ArrayLike, y: ArrayLike, bank: ArrayLike) -> tuple[Array, Array]:
    """Rotate image coordinates by the bank angle: ``(x', y')`` → bank-corrected ``(x'', y'')``."""
    x, y, phi = _f(x), _f(y), _f(bank)
    c, s = np.cos(phi), np.sin(phi)
    return c * x + s * y, -s * x + c * y


# --------------------------------------------------------------------------- spec eq. 17–20
def edge_slopes(
    pitch: ArrayLike, yaw: ArrayLike, y0: ArrayLike, z0: ArrayLike, half_width_m: ArrayLike
) -> tuple[Array, Array]:
    """Spec eq. (17)–(18): slopes ``k1`` (right edge) and ``k2`` (left edge), ``dy''/dx''``,
    bank-corrected image.

    ``y0`` lateral and ``z0`` vertical (down, negative in flight) camera position [m].
    """
    th, psi, y0, z0, d = (_f(v) for v in (pitch, yaw, y0, z0, half_width_m))
    ct, st, cp, sp = np.cos(th), np.sin(th), np.cos(psi), np.sin(psi)
    with np.errstate(divide="ignore"):
        k1 = cp * z0 / (ct * (d - y0) + st * sp * z0)
        k2 = cp * z0 / (ct * (-d - y0) + st * sp * z0)
    return k1, k2


def position_from_slopes(
    k1: ArrayLike, k2: ArrayLike, pitch: ArrayLike, yaw: ArrayLike, half_width_m: ArrayLike
) -> tuple[Array, Array]:
    """Spec eq. (19)–(20): camera ``(y0, z0)`` [m] from the edge slopes ``k1`` (right) and ``k2`` (left)."""
    k1, k2, th, psi, d = (_f(v) for v in (k1, k2, pitch, yaw, half_width_m))
    ct, st, cp, sp = np.cos(th), np.sin(th), np.cos(psi), np.sin(psi)
    z0 = 2.0 * k1 * k2 / (k2 - k1) * (ct / cp) * d
    y0 = -d * ((k1 + k2) / (k2 - k1) - 2.0 * k1 * k2 / (k2 - k1) * st * sp / cp)
    return y0, z0


def position_from_inverse_slopes(
    m1: ArrayLike, m2: ArrayLike, pitch: ArrayLike, yaw: ArrayLike, half_width_m: ArrayLike
) -> tuple[Array, Array]:
    """Eq. (19)–(20) rewritten with inverse slopes ``m = 1/k = dx''/dy''`` (finite for every visible edge).

    From (17)–(18): ``m1 = (cosθ (d - y0) + sinθ sinψ z0) / (cosψ z0)`` and the same
    with ``-d`` for ``m2``; hence ``z0 = 2 d cosθ / (cosψ (m1 - m2))`` and
    ``y0 = z0 (2 sinθ sinψ - cosψ (m1 + m2)) / (2 cosθ)``.  Returns ``(y0, z0)`` [m];
    ``m1 < m2`` for a camera above the runway plane.
    """
    m1, m2, th, psi, d = (_f(v) for v in (m1, m2, pitch, yaw, half_width_m))
    ct, st, cp, sp = np.cos(th), np.sin(th), np.cos(psi), np.sin(psi)
    with np.errstate(divide="ignore", invalid="ignore"):
        z0 = 2.0 * d * ct / (cp * (m1 - m2))
    y0 = z0 * (2.0 * st * sp - cp * (m1 + m2)) / (2.0 * ct)
    return y0, z0


# --------------------------------------------------------------------------- inverse: lines → pose
@dataclass(frozen=True)
class PoseSolution:
    """Pose recovered from three image lines (arrays broadcast over the input lines).

    Angles in rad, lengths in m, image quantities in px (spec image frame, y up).
    ``height_m``/``lateral_m`` refer to the aircraft reference point (the camera
    itself when no mounting offset is given); ``camera_height_m``/``camera_lateral_m``
    to the camera.  ``misclosure_px`` is the perpendicular distance of the two
    edges' intersection from the horizon (0 for perfectly consistent lines).
    """

    bank: Array
    pitch: Array
    yaw: Array
    height_m: Array
    lateral_m: Array
    camera_height_m: Array
    camera_lateral_m: Array
    vp_x: Array
    vp_y: Array
    misclosure_px: Array
    right_edge: Array
    left_edge: Array


def solve_pose(
    horizon: ArrayLike,
    edge_a: ArrayLike,
    edge_b: ArrayLike,
    focal_px: ArrayLike,
    half_width_m: ArrayLike,
    camera_offset_m: ArrayLike | None = None,
) -> PoseSolution:
    """Bank, pitch, yaw, height and lateral offset from the horizon and two runway edges (spec §2–§3).

    Lines are image lines (``x'`` right, ``y'`` up, origin at the principal point),
    shape ``(..., 3)``.  The two edges may be given in either order: the right edge
    is the one with the smaller inverse slope ``dx''/dy''`` (always true for a
    camera above the runway).  ``camera_offset_m`` is the camera position relative
    to the aircraft reference point in body axes ``(forward, right, down)`` [m].

    Steps: bank from the horizon's slope (eq. 9); vanishing point as the
    least-squares intersection of the three lines; pitch and yaw from the
    vanishing point in the bank-corrected image (``y'' = -f tanθ``,
    ``x'' = -f tanψ / cosθ``); camera ``(y0, z0)`` from the edges' inverse slopes
    (:func:`position_from_inverse_slopes`, equivalent to eq. 19–20); finally the
    mounting offset is removed: ``p_ref = p_cam - Cᵀ offset``.
    """
    hz = normalise_lines(horizon)
    ea, eb = normalise_lines(edge_a), normalise_lines(edge_b)
    hz, ea, eb = np.broadcast_arrays(hz, ea, eb)
    f = _f(focal_px)
    d = _f(half_width_m)

    # bank: slope of the horizon dy'/dx' = -a/b = tan φ  (|φ| < 90°)
    a, b = hz[..., 0], hz[..., 1]
    sgn = np.where(b < 0, -1.0, 1.0)
    bank = np.arctan2(-a * sgn, b * sgn)

    vx, vy = least_squares_point(np.stack([hz, ea, eb], axis=-2))
    xv, yv = bank_correct(vx, vy, bank)
    pitch = np.arctan(-yv / f)
    yaw = np.arctan(-xv * np.cos(pitch) / f)

    # inverse slopes dx''/dy'' of the edges in the bank-corrected image: rotate the normals
    def inv_slope(line: Array) -> Array:
        nx, ny = bank_correct(line[..., 0], line[..., 1], bank)
        with np.errstate(divide="ignore", invalid="ignore"):
            return -ny / nx

    ma, mb = inv_slope(ea), inv_slope(eb)
    a_is_right = ma <= mb
    m1, m2 = np.where(a_is_right, ma, mb), np.where(a_is_right, mb, ma)
    right = np.where(a_is_right[..., None], ea, eb)
    left = np.where(a_is_right[..., None], eb, ea)
    y0, z0 = position_from_inverse_slopes(m1, m2, pitch, yaw, d)

    ix, iy = intersect_lines(ea, eb)
    misclosure = np.abs(point_line_distance(hz, ix, iy))

    ref_y, ref_z = y0, z0
    if camera_offset_m is not None:
        rot = rotation_matrix(bank, pitch, yaw)
        off = np.einsum("...ji,...j->...i", rot, np.broadcast_to(_f(camera_offset_m), rot.shape[:-1]))
        ref_y, ref_z = y0 - off[..., 1], z0 - off[..., 2]
    return PoseSolution(
        bank=bank,
        pitch=pitch,
        yaw=yaw,
        height_m=-ref_z,
        lateral_m=ref_y,
        camera_height_m=-z0,
        camera_lateral_m=y0,
        vp_x=vx,
        vp_y=vy,
        misclosure_px=misclosure,
        right_edge=right,
        left_edge=left,
    )
