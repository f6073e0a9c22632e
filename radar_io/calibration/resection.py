"""Single-photo space resection by Gauss–Newton (calibration.md §1–§3).

Frames (spec §1): ground X north, Y east, Z down, origin at the radar (metres);
camera X_p forward, Y_p right, Z_p down the optical axis; film coordinates
``P = F·(X_p, Y_p)/Z_p`` in millimetres from the principal point.  The public
API takes and returns angles in degrees; the maths primitives
(:func:`collinearity`, :func:`residual_partials`) work in radians.

Starting values when none are given (tried in order of their starting cost;
the first that converges is returned):

* **DLT** — with ≥ 6 points that are clearly not coplanar (smallest/largest
  singular value of the centred points > 0.05): the linear 3×4 projection
  matrix (Hartley-normalised), its left 3×3 block orthonormalised for the
  attitude, ``X_0 = −M⁻¹ p₄`` for the position;
* **plane homography** — with ≥ 4 points: the homography from the points'
  best-fit plane to the normalised film coordinates ``P/F``, decomposed as
  ``λ [r₁ r₂ t]`` (Zhang), ``r₃ = r₁ × r₂`` and the result orthonormalised;
* **level photo** — always: attitude level (φ = θ = 0), heading ψ and the
  horizontal position from the complex least-squares similarity
  ``P_x + iP_y ≈ (F/h) e^{−iψ} ((X + iY) − (X_0 + iY_0))``, height ``h`` from its scale.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from radar_io.calibration.rotation import angles_from_matrix, rotation_matrix, rotation_partials, wrap_pi
from radar_io.errors import CalibrationError

PARAM_KEYS = ("x0_m", "y0_m", "z0_m", "phi_deg", "theta_deg", "psi_deg")
_TO_API = np.array([1.0, 1.0, 1.0, 180.0 / math.pi, 180.0 / math.pi, 180.0 / math.pi])
_MAX_CONDITION = 1e12  # of the column-scaled normal matrix; above it the pose is undetermined


@dataclass(frozen=True)
class Pose:
    """Camera position (ground frame, m) and attitude φ, θ, ψ (deg)."""

    x0_m: float
    y0_m: float
    z0_m: float
    phi_deg: float
    theta_deg: float
    psi_deg: float

    @classmethod
    def from_vector(cls, c: np.ndarray) -> Pose:
        """From the internal unknown vector (X_0, Y_0, Z_0 in m; φ, θ, ψ in rad)."""
        return cls(*(float(v) for v in np.asarray(c, dtype=float) * _TO_API))

    def to_vector(self) -> np.ndarray:
        """The internal unknown vector (m, m, m, rad, rad, rad)."""
        return np.array([getattr(self, k) for k in PARAM_KEYS], dtype=float) / _TO_API

    def to_dict(self) -> dict[str, float]:
        return {k: float(getattr(self, k)) for k in PARAM_KEYS}


@dataclass(frozen=True)
class ResectionResult:
    """A converged resection.

    ``covariance`` is 6×6 in (m, m, m, deg, deg, deg) units: the inverse normal
    matrix times the a-posteriori variance of unit weight
    ``σ₀² = Σ εᵀWε / (2N − 6)`` (NaN when N = 3, i.e. no redundancy).
    ``residuals_mm`` are measured − fitted film coordinates (N, 2);
    ``rms_mm = sqrt(Σ ε² / 2N)`` (unweighted, per coordinate).
    """

    pose: Pose
    covariance: np.ndarray
    residuals_mm: np.ndarray
    fitted_mm: np.ndarray
    iterations: int
    rms_mm: float
    sigma0: float
    start: Pose

    @property
    def sigma(self) -> dict[str, float]:
        """1σ of each unknown from the covariance (m and deg)."""
        sd = np.sqrt(np.diag(self.covariance))
        return {k: float(v) for k, v in zip(PARAM_KEYS, sd, strict=True)}


# ----------------------------------------------------------------- maths primitives
def collinearity(points_m: np.ndarray, c: np.ndarray, focal_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """Film coordinates (N, 2) mm and camera-frame coordinates (N, 3) m for unknowns ``c`` (radians)."""
    r = rotation_matrix(*c[3:])
    cam = (points_m - c[:3]) @ r.T
    with np.errstate(divide="ignore", invalid="ignore"):
        film = focal_mm * cam[:, :2] / cam[:, 2:3]
    return film, cam


def residual_partials(points_m: np.ndarray, c: np.ndarray, focal_mm: float) -> np.ndarray:
    """∂ε_i/∂C (N, 2, 6) of ε = P_measured − P̂(C), analytic (spec §3, appendix A).

    Columns: X_0, Y_0, Z_0 (mm per m), φ, θ, ψ (mm per rad).
    """
    points_m = np.asarray(points_m, dtype=float)
    r = rotation_matrix(*c[3:])
    dr = rotation_partials(*c[3:])
    d = points_m - c[:3]
    cam = d @ r.T
    xy, z = cam[:, :2], cam[:, 2]
    f_z = (focal_mm / z)[:, None]
    f_z2 = (focal_mm / z**2)[:, None]
    a = np.empty((len(points_m), 2, 6))
    for k in range(3):  # ∂ε/∂X0_k = −(F c3k/Z²)[X, Y] + (F/Z)[c1k, c2k]
        a[:, :, k] = -f_z2 * r[2, k] * xy + f_z * r[:2, k]
    for j in range(3):  # ∂ε/∂α = (F/Z²)(∂Z/∂α)[X, Y] − (F/Z)[∂X/∂α, ∂Y/∂α]
        dcam = d @ dr[j].T
        a[:, :, 3 + j] = f_z2 * dcam[:, 2:3] * xy - f_z * dcam[:, :2]
    return a


def project(points_m: np.ndarray, pose: Pose, focal_mm: float) -> np.ndarray:
    """Film coordinates (N, 2) mm of ground points (N, 3) m seen from ``pose``.

    Raises if any point is behind the camera.
    """
    pts = _as_array(points_m, 3, "control points")
    film, cam = collinearity(pts, pose.to_vector(), float(focal_mm))
    _check_in_front(cam, "at the given pose")
    return film


# ----------------------------------------------------------------- the solver
def resect(
    points_m: np.ndarray,
    film_mm: np.ndarray,
    focal_mm: float,
    *,
    start: Pose | None = None,
    weights: np.ndarray | None = None,
    max_iterations: int = 20,
    tol_m: float = 1e-4,
    tol_deg: float = 1e-6,
    camera_above_points: bool = True,
) -> ResectionResult:
    """Solve the camera pose from N ≥ 3 control points (N, 3) m and their film coordinates (N, 2) mm.

    ``weights`` (N,) or (N, 2): W_i = diag(w_xi, w_yi) (> 0; e.g. 1/σ²), identity by default.
    Converged when a step moves the position by ≤ ``tol_m`` and every angle by ≤ ``tol_deg``.
    Each Gauss–Newton step is halved while it would put a point behind the camera or
    raise the cost (a safeguard that is inactive near the solution).
    With ``camera_above_points`` (the aerial case) a solution with the camera not above
    every control point (Z_0 ≥ min Z_i) is refused: it is the mirror-image pose a
    film-axis sign error produces.
    Raises :class:`CalibrationError` for degenerate or diverging input.
    """
    pts = _as_array(points_m, 3, "control points")
    film = _as_array(film_mm, 2, "film coordinates")
    if len(pts) != len(film):
        raise CalibrationError(f"{len(pts)} control points but {len(film)} film coordinates")
    if len(pts) < 3:
        raise CalibrationError(f"resection needs at least 3 control points, got {len(pts)}")
    focal = float(focal_mm)
    if not (math.isfinite(focal) and focal > 0):
        raise CalibrationError(f"focal length must be a positive number of mm, got {focal_mm!r}")
    _check_not_collinear(pts)
    w = _weights(weights, len(pts))
    if max_iterations < 1:
        raise CalibrationError("max_iterations must be at least 1")

    if start is not None:
        c0 = start.to_vector()
        if not np.all(np.isfinite(c0)):
            raise CalibrationError("starting pose must be finite")
        _check_in_front(collinearity(pts, c0, focal)[1], "at the starting pose")
        candidates = [c0]
    else:
        candidates = start_candidates(pts, film, focal)
        if not candidates:
            raise CalibrationError("no starting pose puts all control points in front of the camera")
    failures: list[str] = []
    for c0 in candidates:
        try:
            result = _gauss_newton(pts, film, w, focal, c0, max_iterations, tol_m, math.radians(tol_deg))
        except CalibrationError as exc:
            failures.append(str(exc))
            continue
        if camera_above_points and not result.pose.z0_m < float(np.min(pts[:, 2])):
            failures.append(
                f"the solution puts the camera below the control points (Z_0 = {result.pose.z0_m:.1f} m, "
                "Z down); check the film axes' signs (P_x forward, P_y right)"
            )
            continue
        return result
    raise CalibrationError(failures[0] if len(failures) == 1 else "; ".join(dict.fromkeys(failures)))


def _gauss_newton(
    pts: np.ndarray, film: np.ndarray, w: np.ndarray, focal: float, c0: np.ndarray,
    max_iterations: int, tol_m: float, tol_rad: float,
) -> ResectionResult:
    c = c0.copy()
    fitted, cam = collinearity(pts, c, focal)
    cost = float(np.sum(w * (film - fitted) ** 2))
    converged = False
    iterations = 0
    step = np.zeros(6)
    for iterations in range(1, max_iterations + 1):
        a = residual_partials(pts, c, focal)
        eps = film - fitted
        normal = np.einsum("nik,ni,nil->kl", a, w, a)
        grad = np.einsum("nik,ni,ni->k", a, w, eps)
        _check_conditioning(normal)
        delta = -np.linalg.solve(normal, grad)
        if np.all(np.abs(delta[:3]) <= tol_m) and np.all(np.abs(delta[3:]) <= tol_rad):
            c = c + delta
            fitted, cam = collinearity(pts, c, focal)
            converged = True
            break
        t = 1.0
        while True:
            trial = c + t * delta
            f_trial, cam_trial = collinearity(pts, trial, focal)
            if np.all(cam_trial[:, 2] > 0):
                cost_trial = float(np.sum(w * (film - f_trial) ** 2))
                if cost_trial <= cost * (1.0 + 1e-12):
                    break
            t *= 0.5
            if t < 1e-6:
                raise CalibrationError(
                    "resection diverged: no step along the Gauss-Newton direction reduces the residuals "
                    f"(after {iterations} iterations)"
                )
        step = t * delta
        c, fitted, cam, cost = trial, f_trial, cam_trial, cost_trial
    if not converged:
        raise CalibrationError(
            f"resection did not converge in {max_iterations} iterations (last step "
            f"{float(np.max(np.abs(step[:3]))):.3g} m, "
            f"{math.degrees(float(np.max(np.abs(step[3:])))):.3g} deg)"
        )
    _check_in_front(cam, "at the solution")
    c[3] = wrap_pi(c[3])
    c[5] = wrap_pi(c[5])
    a = residual_partials(pts, c, focal)
    normal = np.einsum("nik,ni,nil->kl", a, w, a)
    _check_conditioning(normal)
    eps = film - fitted
    dof = 2 * len(pts) - 6
    sigma0_sq = float(np.sum(w * eps**2)) / dof if dof > 0 else math.nan
    cov = np.linalg.inv(normal) * sigma0_sq * np.outer(_TO_API, _TO_API)
    return ResectionResult(
        pose=Pose.from_vector(c),
        covariance=cov,
        residuals_mm=eps,
        fitted_mm=fitted,
        iterations=iterations,
        rms_mm=float(np.sqrt(np.mean(eps**2))),
        sigma0=math.sqrt(sigma0_sq),
        start=Pose.from_vector(c0),
    )


# ----------------------------------------------------------------- checks
def _as_array(x: np.ndarray, cols: int, what: str) -> np.ndarray:
    a = np.asarray(x, dtype=float)
    if a.ndim != 2 or a.shape[1] != cols:
        raise CalibrationError(f"{what} must be an (N, {cols}) array, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise CalibrationError(f"{what} contain non-finite values")
    return a


def _weights(weights: np.ndarray | None, n: int) -> np.ndarray:
    if weights is None:
        return np.ones((n, 2))
    w = np.asarray(weights, dtype=float)
    if w.shape == (n,):
        w = np.repeat(w[:, None], 2, axis=1)
    if w.shape != (n, 2):
        raise CalibrationError(f"weights must have shape ({n},) or ({n}, 2), got {w.shape}")
    if not np.all(np.isfinite(w) & (w > 0)):
        raise CalibrationError("weights must be finite and > 0")
    return w


def _check_not_collinear(pts: np.ndarray) -> None:
    s = np.linalg.svd(pts - pts.mean(axis=0), compute_uv=False)
    if s[0] == 0 or s[1] <= 1e-9 * s[0]:
        raise CalibrationError("control points are collinear (or coincide): the pose is undetermined")


def _check_in_front(cam: np.ndarray, where: str) -> None:
    behind = np.flatnonzero(~(cam[:, 2] > 0))
    if behind.size:
        idx = ", ".join(str(i) for i in behind[:10])
        raise CalibrationError(f"control point(s) {idx} (0-based) behind the camera {where}")


def _check_conditioning(normal: np.ndarray) -> None:
    d = np.sqrt(np.diag(normal))
    if not np.all(np.isfinite(normal)) or np.any(d == 0):
        raise CalibrationError("normal matrix is singular: the control points do not determine the pose")
    cond = np.linalg.cond(normal / np.outer(d, d))
    if not math.isfinite(cond) or cond > _MAX_CONDITION:
        raise CalibrationError(
            f"normal matrix is singular (condition number {cond:.3g}): the control points do not "
            "determine the pose (e.g. too few points, or the camera on the 'danger cylinder' through them)"
        )


# ----------------------------------------------------------------- starting values
def start_candidates(points_m: np.ndarray, film_mm: np.ndarray, focal_mm: float) -> list[np.ndarray]:
    """Starting unknown vectors (radians) derived from the points (module docstring), sorted by starting cost.

    Candidates that put a point behind the camera are dropped.
    """
    pts = np.asarray(points_m, dtype=float)
    film = np.asarray(film_mm, dtype=float)
    uv = film / focal_mm
    s = np.linalg.svd(pts - pts.mean(axis=0), compute_uv=False)
    makers: list[Callable[[np.ndarray, np.ndarray], np.ndarray | None]] = []
    if len(pts) >= 6 and s[2] > 0.05 * s[0]:
        makers.append(_dlt_start)
    if len(pts) >= 4:
        makers.append(_homography_start)
    makers.append(_level_start)
    scored: list[tuple[float, int, np.ndarray]] = []
    for make in makers:
        try:
            c = make(pts, uv)
        except (np.linalg.LinAlgError, ValueError, ZeroDivisionError):
            continue
        if c is None or not np.all(np.isfinite(c)):
            continue
        fitted, cam = collinearity(pts, c, focal_mm)
        if np.all(cam[:, 2] > 0):
            scored.append((float(np.sum((film - fitted) ** 2)), len(scored), c))
    return [c for _, _, c in sorted(scored, key=lambda t: (t[0], t[1]))]


def _pose_vector(r: np.ndarray, x0: np.ndarray) -> np.ndarray:
    return np.array([*x0, *angles_from_matrix(r)])


def _normalising_transform(p: np.ndarray) -> np.ndarray:
    """Hartley normalisation: centroid to the origin, mean distance √dim."""
    dim = p.shape[1]
    centre = p.mean(axis=0)
    dist = np.mean(np.linalg.norm(p - centre, axis=1))
    scale = math.sqrt(dim) / dist
    t = np.eye(dim + 1)
    t[:dim, :dim] *= scale
    t[:dim, dim] = -scale * centre
    return t


def _homogeneous(p: np.ndarray) -> np.ndarray:
    return np.hstack([p, np.ones((len(p), 1))])


def _direct_linear(src: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """The 3×(k+1) matrix P with uv ~ P·[src, 1] (k = 3: camera matrix, k = 2: homography),
    by the normalised direct linear transform (SVD null vector)."""
    ts, tu = _normalising_transform(src), _normalising_transform(uv)
    sn = _homogeneous(src) @ ts.T
    un = _homogeneous(uv) @ tu.T
    k = sn.shape[1]
    rows = np.zeros((2 * len(src), 3 * k))
    rows[0::2, 0:k] = sn
    rows[0::2, 2 * k:] = -un[:, 0:1] * sn
    rows[1::2, k:2 * k] = sn
    rows[1::2, 2 * k:] = -un[:, 1:2] * sn
    return np.linalg.inv(tu) @ np.linalg.svd(rows)[2][-1].reshape(3, k) @ ts


def _dlt_start(pts: np.ndarray, uv: np.ndarray) -> np.ndarray:
    p = _direct_linear(pts, uv)
    m = p[:, :3]
    if np.linalg.det(m) < 0:
        p, m = -p, -m
    x0 = -np.linalg.solve(m, p[:, 3])
    u, _, vt = np.linalg.svd(m)
    return _pose_vector(u @ vt, x0)


def _homography_start(pts: np.ndarray, uv: np.ndarray) -> np.ndarray | None:
    centre = pts.mean(axis=0)
    e = np.linalg.svd(pts - centre)[2]
    e1, e2 = e[0], e[1]
    ab = (pts - centre) @ np.stack([e1, e2]).T
    h = _direct_linear(ab, uv)
    lam = 0.5 * (np.linalg.norm(h[:, 0]) + np.linalg.norm(h[:, 1]))
    if h[2, 2] < 0:  # the centroid must lie in front of the camera (Z_p > 0)
        lam = -lam
    r1, r2, t = h[:, 0] / lam, h[:, 1] / lam, h[:, 2] / lam
    u, _, vt = np.linalg.svd(np.column_stack([r1, r2, np.cross(r1, r2)]))
    q = u @ vt
    r = q @ np.column_stack([e1, e2, np.cross(e1, e2)]).T
    if np.linalg.det(r) < 0:
        return None
    return _pose_vector(r, centre - r.T @ t)


def _level_start(pts: np.ndarray, uv: np.ndarray) -> np.ndarray:
    zg = pts[:, 0] + 1j * pts[:, 1]
    zf = uv[:, 0] + 1j * uv[:, 1]
    dg = zg - zg.mean()
    alpha = np.sum((zf - zf.mean()) * np.conj(dg)) / np.sum(np.abs(dg) ** 2)
    beta = zf.mean() - alpha * zg.mean()
    z0 = -beta / alpha
    height = 1.0 / abs(alpha)  # uv = P/F, so |alpha| = 1/h
    return np.array([z0.real, z0.imag, pts[:, 2].mean() - height, 0.0, 0.0, -np.angle(alpha)])
