"""Image-line primitives of the runway chain (spec §4): binary edges, Hough candidates, sub-pixel refinement.

All lines here are **pixel** lines ``A u + B v + C = 0`` (``u`` right, ``v`` down,
``(0, 0)`` the centre of the top-left pixel) stored as float64 3-vectors with
``A² + B² = 1``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

from radar_io.vision.pose_equations import fit_line

__all__ = ["RefinedLine", "binary_edges", "hough_candidates", "refine_line"]

Line = NDArray[np.float64]


def binary_edges(
    gray: NDArray[np.uint8], threshold: int | None = None
) -> tuple[NDArray[np.uint8], NDArray[np.uint8]]:
    """Threshold ``gray`` to a binary image (Otsu when ``threshold`` is None); ``(binary, edges)``.

    The binary image is median-filtered to drop speckle from ground texture; the
    edges are its light/dark boundaries (Canny on the binary image: the spec's
    "differentiation").
    """
    blur = cv2.GaussianBlur(gray, (5, 5), 0)
    if threshold is None:
        _, binary = cv2.threshold(blur, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    else:
        _, binary = cv2.threshold(blur, int(threshold), 255, cv2.THRESH_BINARY)
    binary = cv2.medianBlur(binary, 5)
    # OpenCV's stubs type every result as any numeric array; these are uint8 (no copy)
    return np.asarray(binary, np.uint8), np.asarray(cv2.Canny(binary, 50, 150), np.uint8)


def hough_candidates(
    edges: NDArray[np.uint8],
    scale: float,
    offset: tuple[int, int],
    min_votes: int,
    max_lines: int,
    theta_res_deg: float = 0.5,
    merge_angle_deg: float = 2.0,
    merge_dist_px: float = 6.0,
) -> list[Line]:
    """Strongest distinct Hough lines of ``edges``, as full-resolution pixel lines.

    ``edges`` is a crop at ``offset = (u0, v0)`` (in its own pixels) of an image
    downscaled by ``scale`` (<= 1) from full resolution.  Near-duplicate lines
    (angle within ``merge_angle_deg`` and ``merge_dist_px`` apart at the crop
    centre, in crop pixels) are merged keeping the one with more votes.
    """
    found = cv2.HoughLinesWithAccumulator(edges, 1, math.radians(theta_res_deg), int(min_votes))
    if found is None:
        return []
    found = np.asarray(found, dtype=np.float64).reshape(-1, 3)
    h, w = edges.shape
    mid = np.array([w / 2.0, h / 2.0])
    kept: list[tuple[float, float]] = []  # (signed distance of the crop centre, theta in [0, pi))
    out: list[Line] = []
    tol_th = math.radians(merge_angle_deg)
    for rho, theta, _votes in found:  # sorted by votes, strongest first
        c, s = math.cos(theta), math.sin(theta)
        rho_mid = rho - (c * mid[0] + s * mid[1])
        if any(
            (abs(theta - th) < tol_th and abs(rho_mid - r) < merge_dist_px)
            # the same line with its normal flipped
            or (math.pi - abs(theta - th) < tol_th and abs(rho_mid + r) < merge_dist_px)
            for r, th in kept
        ):
            continue
        kept.append((rho_mid, theta))
        # crop pixel (uc, vc) = ((u + 0.5) * scale - 0.5 - u0, (v + 0.5) * scale - 0.5 - v0)
        u0, v0 = offset
        a, b = scale * c, scale * s
        cc = c * (0.5 * scale - 0.5 - u0) + s * (0.5 * scale - 0.5 - v0) - rho
        ln = np.array([a, b, cc]) / math.hypot(a, b)
        out.append(ln)
        if len(out) >= max_lines:
            break
    return out


@dataclass(frozen=True)
class RefinedLine:
    """A line refined on the grey image.

    ``line`` is normalised with its normal ``(A, B)`` pointing to the **brighter**
    side.  ``s0, s1`` bound the supporting samples along the direction ``(-B, A)``
    measured from the foot point ``-C (A, B)``; ``support`` is the number of inlier
    samples, ``coverage`` their fraction of the samples inside the image, ``rms`` the
    fit residual [px], ``contrast`` the median grey step across the line and
    ``dark_level``/``bright_level`` the median grey values a few pixels to either side.
    """

    line: Line
    support: int
    coverage: float
    s0: float
    s1: float
    rms: float
    contrast: float
    dark_level: float = 0.0
    bright_level: float = 0.0
    points: NDArray[np.float64] = field(repr=False, compare=False, default_factory=lambda: np.zeros((0, 2)))

    @property
    def direction(self) -> NDArray[np.float64]:
        return np.array([-self.line[1], self.line[0]])

    @property
    def foot(self) -> NDArray[np.float64]:
        return -self.line[2] * self.line[:2]

    def point(self, s: float) -> NDArray[np.float64]:
        return self.foot + s * self.direction

    @property
    def midpoint(self) -> NDArray[np.float64]:
        return self.point(0.5 * (self.s0 + self.s1))

    @property
    def length(self) -> float:
        return self.s1 - self.s0


def _segment_in_rect(foot: NDArray, t: NDArray, lo: NDArray, hi: NDArray) -> tuple[float, float] | None:
    s_min, s_max = -math.inf, math.inf
    for k in range(2):
        if abs(t[k]) < 1e-12:
            if not lo[k] <= foot[k] <= hi[k]:
                return None
            continue
        a, b = (lo[k] - foot[k]) / t[k], (hi[k] - foot[k]) / t[k]
        s_min, s_max = max(s_min, min(a, b)), min(s_max, max(a, b))
    return (s_min, s_max) if s_max > s_min else None


def refine_line(
    gray: NDArray[np.float32],
    line: Line,
    *,
    min_contrast: float,
    step: float = 2.0,
    passes: tuple[float, ...] = (6.0, 3.0),
    persist: float = 5.0,
    exclude: list[tuple[Line, float]] | None = None,
    min_support: int = 8,
    min_run: int = 4,
) -> RefinedLine | None:
    """Refine ``line`` to sub-pixel accuracy on the (smoothed, float) grey image.

    Profiles across the line are sampled every ``step`` px along it (bilinear
    interpolation); in each profile the edge sits at the centroid of the gradient
    peak.  A sample is dropped when its grey step is below ``min_contrast``, when
    the step does not persist ``persist`` px further out on both sides (thin
    wires and lines), when the peak is at the window border, or when it lies
    within the given distance of a line in ``exclude`` (e.g. the other runway edge
    near the vanishing point).  A robust orthogonal least-squares line (RANSAC
    start, then 3-MAD trimming, keeping only runs of at least ``min_run``
    consecutive samples) is fitted to the rest.  One pass per entry of ``passes``
    (profile half-widths, px), each re-centred on the previous fit.  Returns None
    without ``min_support`` samples.
    """
    h, w = gray.shape
    ln = np.asarray(line, dtype=np.float64)
    ln = ln / math.hypot(ln[0], ln[1])
    result: RefinedLine | None = None
    for hw in passes:
        n = ln[:2]
        t = np.array([-n[1], n[0]])
        foot = -ln[2] * n
        margin = hw + persist + 1.5
        seg = _segment_in_rect(foot, t, np.array([margin, margin]),
                               np.array([w - 1 - margin, h - 1 - margin]))
        if seg is None:
            return None
        s = np.arange(seg[0], seg[1], step)
        if exclude:
            pts = foot[None, :] + s[:, None] * t[None, :]
            keep = np.ones(len(s), bool)
            for ex_line, ex_dist in exclude:
                exn = ex_line / math.hypot(ex_line[0], ex_line[1])
                keep &= np.abs(pts @ exn[:2] + exn[2]) > ex_dist
            s = s[keep]
        n_total = len(s)
        if n_total < min_support:
            return None
        u = np.arange(-hw, hw + 0.5, 1.0)
        # profile offsets plus two outer samples that check the step persists (rejects thin wires)
        uo = np.concatenate([u, [-hw - persist, hw + persist]])
        px = foot[0] + s[:, None] * t[0] + uo[None, :] * n[0]
        py = foot[1] + s[:, None] * t[1] + uo[None, :] * n[1]
        full = cv2.remap(gray, px.astype(np.float32), py.astype(np.float32), cv2.INTER_LINEAR)
        prof, outer = full[:, : len(u)], full[:, len(u) :]
        diff = prof[:, 1:] - prof[:, :-1]
        uh = u[:-1] + 0.5
        stepv = prof[:, -1] - prof[:, 0]
        sgn = 1.0 if float(np.sum(stepv)) >= 0 else -1.0
        gpos = np.clip(sgn * diff, 0.0, None)
        peak = gpos.max(axis=1)
        arg = gpos.argmax(axis=1)
        wts = np.clip(gpos - 0.3 * peak[:, None], 0.0, None)
        wsum = wts.sum(axis=1)
        valid = (
            (sgn * stepv >= min_contrast)
            & (sgn * (outer[:, 1] - outer[:, 0]) >= min_contrast)
            & (arg > 0)
            & (arg < len(uh) - 1)
            & (wsum > 0)
        )
        if valid.sum() < min_support:
            return None
        # edge point of every sample: centroid of the gradient peak (invalid samples stay NaN)
        off = np.full(len(s), np.nan)
        off[valid] = (wts[valid] * uh[None, :]).sum(axis=1) / wsum[valid]
        qx = foot[0] + s * t[0] + off * n[0]
        qy = foot[1] + s * t[1] + off * n[1]
        inl = np.zeros(len(s), bool)
        inl[valid] = _ransac_inliers(qx[valid], qy[valid], tol=0.75)
        inl = _drop_short_runs(inl, min_run)
        for _ in range(4):
            if inl.sum() < min_support:
                return None
            fit = fit_line(qx[inl], qy[inl])
            res = np.abs(qx * fit[0] + qy * fit[1] + fit[2])
            mad = 1.4826 * float(np.median(res[inl]))
            new = _drop_short_runs(valid & (np.nan_to_num(res, nan=np.inf) <= max(3.0 * mad, 0.35)), min_run)
            if np.array_equal(new, inl):
                break
            inl = new
        if inl.sum() < min_support:
            return None
        fit = fit_line(qx[inl], qy[inl])
        if fit[:2] @ (sgn * n) < 0:  # orient the normal to the brighter side
            fit = -fit
        ln = fit
        res = qx[inl] * fit[0] + qy[inl] * fit[1] + fit[2]
        # extent along the refined line
        t2 = np.array([-fit[1], fit[0]])
        foot2 = -fit[2] * fit[:2]
        proj = (qx[inl] - foot2[0]) * t2[0] + (qy[inl] - foot2[1]) * t2[1]
        result = RefinedLine(
            line=fit,
            support=int(inl.sum()),
            coverage=float(inl.sum()) / max(n_total, 1),
            s0=float(proj.min()),
            s1=float(proj.max()),
            rms=float(np.sqrt(np.mean(res**2))),
            contrast=float(np.median(sgn * stepv[inl])),
            dark_level=float(np.median(outer[inl, 0 if sgn > 0 else 1])),
            bright_level=float(np.median(outer[inl, 1 if sgn > 0 else 0])),
            points=np.stack([qx[inl], qy[inl]], axis=-1),
        )
    return result


def _drop_short_runs(mask: NDArray[np.bool_], min_run: int) -> NDArray[np.bool_]:
    """Clear runs of True shorter than ``min_run`` (isolated samples are noise, not an edge)."""
    if min_run <= 1 or not mask.any():
        return mask
    starts = mask & ~np.concatenate([[False], mask[:-1]])
    run_id = np.cumsum(starts) * mask  # 1.. for samples in runs, 0 elsewhere
    lengths = np.bincount(run_id)
    lengths[0] = 0
    return lengths[run_id] >= min_run


def _ransac_inliers(x: NDArray, y: NDArray, tol: float, trials: int = 64) -> NDArray[np.bool_]:
    """Inlier mask of the line through two samples that most other samples lie within ``tol`` px of.

    Deterministic (fixed seed), so results are reproducible.
    """
    n = len(x)
    rng = np.random.default_rng(12345)
    i = rng.integers(0, n, trials)
    j = rng.integers(0, n, trials)
    dx, dy = x[j] - x[i], y[j] - y[i]
    norm = np.hypot(dx, dy)
    ok = norm > 4.0
    if not ok.any():
        return np.ones(n, bool)
    i, dx, dy, norm = i[ok], dx[ok], dy[ok], norm[ok]
    a, b = -dy / norm, dx / norm
    c = -(a * x[i] + b * y[i])
    dist = np.abs(a[:, None] * x[None, :] + b[:, None] * y[None, :] + c[:, None])
    counts = (dist <= tol).sum(axis=1)
    return dist[int(np.argmax(counts))] <= tol
