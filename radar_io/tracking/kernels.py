"""Compiled inner loops of the tracker: the extended Kalman filter and the RTS smoother.

State ``s = [x, y, h, vx, vy, vh]`` in the radar frame (X north, Y east, H up; m, m/s).
Measurement ``z = [SR (m), EL (rad), AZ (rad)]``, scaled by its σ inside the update, so
the innovation covariance ``S = H P Hᵀ + I`` is well conditioned whatever the units.

The loops are sequential (a Kalman filter is a recursion), written over small fixed-size
arrays and compiled by numba when it is installed (``cache=True``: compiled once per
machine, loaded in a later process); without numba they run as plain Python, ~1000×
slower (docs/tracking.md, "Speed"). Every function here works on preallocated arrays and
allocates nothing per sample.

Flags per sample (``flags`` uint8): :data:`ACTIVE` the track holds an estimate here,
:data:`START` the track (re)starts here, :data:`UPDATED` the measurement was used,
:data:`OUTLIER` the measurement failed the NIS gate and was not used.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

ACTIVE, START, UPDATED, OUTLIER = 1, 2, 4, 8

#: carried forward-filter state: [t_last, t_last_update, active, tracks, time_errors,
#: next fix, fixes used]
CARRY_LEN = 7


def _jit(fn: Callable[..., Any]) -> Callable[..., Any]:
    try:
        import numba
    except ImportError:  # pragma: no cover - numba is a dependency; plain Python still works
        return fn
    return numba.njit(cache=True, nogil=True)(fn)


@_jit
def _mul6(A: np.ndarray, B: np.ndarray, out: np.ndarray) -> None:
    """out = A B for 6×6 matrices."""
    for i in range(6):
        for j in range(6):
            acc = 0.0
            for k in range(6):
                acc += A[i, k] * B[k, j]
            out[i, j] = acc


@_jit
def _predict(x: np.ndarray, P: np.ndarray, dt: float, q: float) -> None:
    """x ← F x, P ← F P Fᵀ + Q for the CV model (per axis Q = q·[[dt³/3, dt²/2], [dt²/2, dt]])."""
    for i in range(3):
        x[i] += dt * x[i + 3]
    # P = [[A, B], [Bᵀ, C]] (3×3 blocks): A' = A + dt(B + Bᵀ) + dt² C, B' = B + dt C
    for i in range(3):
        for j in range(3):
            P[i, j] += dt * (P[i, j + 3] + P[j, i + 3]) + dt * dt * P[i + 3, j + 3]
    for i in range(3):
        for j in range(3):
            P[i, j + 3] += dt * P[i + 3, j + 3]
            P[j + 3, i] = P[i, j + 3]
    q3, q2, q1 = q * dt * dt * dt / 3.0, q * dt * dt / 2.0, q * dt
    for i in range(3):
        P[i, i] += q3
        P[i, i + 3] += q2
        P[i + 3, i] += q2
        P[i + 3, i + 3] += q1


@_jit
def _init(x: np.ndarray, P: np.ndarray, sr: float, el: float, az: float, s_r: float,
          s_a: float, v0_var: float) -> None:
    """A new track at a measurement: converted position, its covariance J R Jᵀ, velocity 0 ± √v0_var."""
    ce, se, ca, sa = math.cos(el), math.sin(el), math.cos(az), math.sin(az)
    x[0], x[1], x[2] = sr * ce * ca, sr * ce * sa, sr * se
    x[3] = x[4] = x[5] = 0.0
    # columns of J = d(x, y, h)/d(sr, el, az), scaled by the σ of each
    J = np.empty((3, 3))
    J[0, 0], J[1, 0], J[2, 0] = ce * ca * s_r, ce * sa * s_r, se * s_r
    J[0, 1], J[1, 1], J[2, 1] = -sr * se * ca * s_a, -sr * se * sa * s_a, sr * ce * s_a
    J[0, 2], J[1, 2], J[2, 2] = -sr * ce * sa * s_a, sr * ce * ca * s_a, 0.0
    P[:, :] = 0.0
    for i in range(3):
        for j in range(3):
            P[i, j] = J[i, 0] * J[j, 0] + J[i, 1] * J[j, 1] + J[i, 2] * J[j, 2]
        P[i + 3, i + 3] = v0_var


@_jit
def _apply(x: np.ndarray, P: np.ndarray, H: np.ndarray, v0: float, v1: float, v2: float,
           gate: float, K: np.ndarray, A: np.ndarray, T: np.ndarray) -> float:
    """Kalman update with a scaled measurement (R = I): innovation ``v``, Jacobian ``H`` (3×6)
    whose velocity columns are zero (both measurements see the position only).

    Returns the NIS; x and P change only if NIS ≤ gate (Joseph form). ``K`` (6×3), ``A``,
    ``T`` (6×6) are scratch arrays.
    """
    # PHᵀ (6×3) into K, then S = H P Hᵀ + I
    for i in range(6):
        for m in range(3):
            K[i, m] = P[i, 0] * H[m, 0] + P[i, 1] * H[m, 1] + P[i, 2] * H[m, 2]
    s00 = H[0, 0] * K[0, 0] + H[0, 1] * K[1, 0] + H[0, 2] * K[2, 0] + 1.0
    s01 = H[0, 0] * K[0, 1] + H[0, 1] * K[1, 1] + H[0, 2] * K[2, 1]
    s02 = H[0, 0] * K[0, 2] + H[0, 1] * K[1, 2] + H[0, 2] * K[2, 2]
    s11 = H[1, 0] * K[0, 1] + H[1, 1] * K[1, 1] + H[1, 2] * K[2, 1] + 1.0
    s12 = H[1, 0] * K[0, 2] + H[1, 1] * K[1, 2] + H[1, 2] * K[2, 2]
    s22 = H[2, 0] * K[0, 2] + H[2, 1] * K[1, 2] + H[2, 2] * K[2, 2] + 1.0
    # S⁻¹ by cofactors (S ≥ I: well conditioned)
    c00, c01, c02 = s11 * s22 - s12 * s12, s02 * s12 - s01 * s22, s01 * s12 - s02 * s11
    det = s00 * c00 + s01 * c01 + s02 * c02
    c11, c12, c22 = s00 * s22 - s02 * s02, s01 * s02 - s00 * s12, s00 * s11 - s01 * s01
    i00, i01, i02, i11, i12, i22 = c00 / det, c01 / det, c02 / det, c11 / det, c12 / det, c22 / det
    w0 = i00 * v0 + i01 * v1 + i02 * v2
    w1 = i01 * v0 + i11 * v1 + i12 * v2
    w2 = i02 * v0 + i12 * v1 + i22 * v2
    nis = v0 * w0 + v1 * w1 + v2 * w2
    if not nis <= gate:
        return nis
    for i in range(6):  # K = P Hᵀ S⁻¹; x += K v
        a, b, c = K[i, 0], K[i, 1], K[i, 2]
        K[i, 0] = a * i00 + b * i01 + c * i02
        K[i, 1] = a * i01 + b * i11 + c * i12
        K[i, 2] = a * i02 + b * i12 + c * i22
        x[i] += a * w0 + b * w1 + c * w2
    # Joseph form: P ← (I − K H) P (I − K H)ᵀ + K Kᵀ  (R = I after scaling)
    for i in range(6):
        for j in range(6):
            A[i, j] = -(K[i, 0] * H[0, j] + K[i, 1] * H[1, j] + K[i, 2] * H[2, j])
        A[i, i] += 1.0
    _mul6(A, P, T)
    for i in range(6):
        for j in range(i, 6):
            acc = K[i, 0] * K[j, 0] + K[i, 1] * K[j, 1] + K[i, 2] * K[j, 2]
            for k in range(6):
                acc += T[i, k] * A[j, k]
            P[i, j] = acc
            P[j, i] = acc
    return nis


@_jit
def _update(x: np.ndarray, P: np.ndarray, sr: float, el: float, az: float, s_r: float,
            s_a: float, gate: float, H: np.ndarray, K: np.ndarray, A: np.ndarray,
            T: np.ndarray) -> float:
    """EKF update by a radar measurement (SR m, EL, AZ rad) with NIS gating; returns the NIS."""
    px, py, ph = x[0], x[1], x[2]
    g2 = px * px + py * py
    g = math.sqrt(g2)
    r2 = g2 + ph * ph
    r = math.sqrt(r2)
    if g == 0.0:
        return math.inf  # overhead: azimuth undefined, no linearisation
    # scaled innovation v = (z - h(x)) / σ, azimuth difference folded into (-π, π]
    d_az = az - math.atan2(py, px)
    d_az = d_az - 2.0 * math.pi * math.floor((d_az + math.pi) / (2.0 * math.pi))
    # scaled Jacobian H = diag(1/σ) ∂h/∂(x, y, h); velocity columns are zero
    H[:, :] = 0.0
    H[0, 0], H[0, 1], H[0, 2] = px / r / s_r, py / r / s_r, ph / r / s_r
    H[1, 0], H[1, 1], H[1, 2] = (-ph * px / (r2 * g) / s_a, -ph * py / (r2 * g) / s_a,
                                 g / r2 / s_a)
    H[2, 0], H[2, 1] = -py / g2 / s_a, px / g2 / s_a
    return _apply(x, P, H, (sr - r) / s_r, (el - math.atan2(ph, g)) / s_a, d_az / s_a, gate,
                  K, A, T)


@_jit
def _update_position(x: np.ndarray, P: np.ndarray, fix: np.ndarray, H: np.ndarray,
                     K: np.ndarray, A: np.ndarray, T: np.ndarray) -> float:
    """Update by a direct position fix ``[x, y, h, σx, σy, σh]`` (m); returns its NIS."""
    H[:, :] = 0.0
    for m in range(3):
        H[m, m] = 1.0 / fix[3 + m]
    return _apply(x, P, H, (fix[0] - x[0]) / fix[3], (fix[1] - x[1]) / fix[4],
                  (fix[2] - x[2]) / fix[5], math.inf, K, A, T)


@_jit
def forward(t: np.ndarray, sr: np.ndarray, el: np.ndarray, az: np.ndarray, good: np.ndarray,
            i0: int, i1: int, x: np.ndarray, P: np.ndarray, carry: np.ndarray,
            params: np.ndarray, nis: np.ndarray, flags: np.ndarray,
            out_x: np.ndarray, out_P: np.ndarray, fix_rows: np.ndarray,
            fixes: np.ndarray) -> None:
    """Run the filter over samples ``i0 … i1-1``, continuing from ``x``, ``P``, ``carry``.

    ``t`` unwrapped time (s); ``sr`` (m), ``el``, ``az`` (rad); ``good`` 0/1.
    ``params`` = [q, σ_range, σ_angle, gate, max_gap_s, v0_var]. Writes ``nis[k]``,
    ``flags[k]``, and, if ``out_x`` has rows, the filtered state and covariance of sample
    ``k`` at row ``k - i0`` of ``out_x`` / ``out_P``. ``x``, ``P``, ``carry`` hold the state
    after sample ``i1 - 1`` on return. ``fix_rows`` (ascending) / ``fixes`` (m × 6: x, y, h,
    σx, σy, σh): position fixes applied after the radar update of their row, if the track
    holds an estimate there.
    """
    q, s_r, s_a, gate, max_gap, v0_var = (params[0], params[1], params[2], params[3],
                                          params[4], params[5])
    store = out_x.shape[0] > 0
    H = np.empty((3, 6))
    K = np.empty((6, 3))
    A = np.empty((6, 6))
    T = np.empty((6, 6))
    t_last, t_upd, active = carry[0], carry[1], carry[2] > 0.0
    nf = int(carry[5])
    for k in range(i0, i1):
        tk = t[k]
        f = 0
        nis[k] = math.nan
        if active:
            dt = tk - t_last
            if dt < 0.0 or tk - t_upd > max_gap:
                active = False  # time ran backwards, or nothing used for too long: track ends
                if dt < 0.0:
                    carry[4] += 1.0
            elif dt > 0.0:
                _predict(x, P, dt, q)
        if good[k]:
            if not active:
                _init(x, P, sr[k], el[k], az[k], s_r, s_a, v0_var)
                active = True
                t_upd = tk
                f = START | UPDATED
                carry[3] += 1.0
            else:
                v = _update(x, P, sr[k], el[k], az[k], s_r, s_a, gate, H, K, A, T)
                nis[k] = v
                if v <= gate:
                    f = UPDATED
                    t_upd = tk
                else:
                    f = OUTLIER
        while nf < fix_rows.shape[0] and fix_rows[nf] <= k:
            if fix_rows[nf] == k and active:
                _update_position(x, P, fixes[nf], H, K, A, T)
                carry[6] += 1.0
            nf += 1
        if active:
            f |= ACTIVE
            t_last = tk
        flags[k] = f
        if store:
            j = k - i0
            for a in range(6):
                out_x[j, a] = x[a] if active else math.nan
                for b in range(6):
                    out_P[j, a, b] = P[a, b] if active else math.nan
    carry[0], carry[1], carry[2], carry[5] = t_last, t_upd, 1.0 if active else 0.0, nf


@_jit
def smooth(t: np.ndarray, flags: np.ndarray, i0: int, i1: int, fx: np.ndarray,
           fP: np.ndarray, xs: np.ndarray, Ps: np.ndarray, has_next: bool, q: float,
           out_state: np.ndarray, out_cov: np.ndarray) -> bool:
    """Rauch–Tung–Striebel pass backwards over samples ``i1-1 … i0``.

    ``fx`` / ``fP``: the filtered states and covariances of those samples (row ``k - i0``).
    ``xs`` / ``Ps`` / ``has_next``: the smoothed estimate of sample ``i1`` (if it continues
    the same track). Writes ``out_state[k]`` = smoothed state and ``out_cov[k]`` = the 1σ
    of the six states and the position cross-covariances xy, xh, yh; leaves in ``xs`` /
    ``Ps`` the smoothed estimate of sample ``i0`` and returns whether it continues a track.
    """
    xp = np.empty(6)
    Pp = np.empty((6, 6))
    L = np.empty((6, 6))
    G = np.empty((6, 6))
    D = np.empty((6, 6))
    E = np.empty((6, 6))
    nxt = has_next
    for k in range(i1 - 1, i0 - 1, -1):
        j = k - i0
        if not flags[k] & ACTIVE:
            for a in range(6):
                out_state[k, a] = math.nan
            for a in range(9):
                out_cov[k, a] = math.nan
            nxt = False
            continue
        if not nxt:  # last sample of a track: smoothed = filtered
            for a in range(6):
                xs[a] = fx[j, a]
                for b in range(6):
                    Ps[a, b] = fP[j, a, b]
        else:
            dt = t[k + 1] - t[k]
            for a in range(6):
                xp[a] = fx[j, a]
                for b in range(6):
                    Pp[a, b] = fP[j, a, b]
            if dt > 0.0:
                _predict(xp, Pp, dt, q)
            # G = P_k Fᵀ P_pred⁻¹, i.e. P_pred Gᵀ = F P_k: Cholesky of P_pred
            for a in range(6):
                for b in range(a + 1):
                    acc = Pp[a, b]
                    for c in range(b):
                        acc -= L[a, c] * L[b, c]
                    if a == b:
                        L[a, a] = math.sqrt(acc) if acc > 0.0 else 1e-300
                    else:
                        L[a, b] = acc / L[b, b]
            for c in range(6):  # right-hand side column c: (F P_k)[:, c]
                for a in range(6):
                    v = fP[j, a, c] + (dt * fP[j, a + 3, c] if a < 3 else 0.0)
                    for b in range(a):
                        v -= L[a, b] * D[b, c]
                    D[a, c] = v / L[a, a]
                for a in range(5, -1, -1):
                    v = D[a, c]
                    for b in range(a + 1, 6):
                        v -= L[b, a] * G[c, b]
                    G[c, a] = v / L[a, a]
            # xs = x + G (xs_next − x_pred); Ps = P + G (Ps_next − P_pred) Gᵀ
            for a in range(6):
                xp[a] = xs[a] - xp[a]
                for b in range(6):
                    Pp[a, b] = Ps[a, b] - Pp[a, b]
            for a in range(6):
                acc = fx[j, a]
                for b in range(6):
                    acc += G[a, b] * xp[b]
                xs[a] = acc
            _mul6(G, Pp, E)
            for a in range(6):
                for b in range(a, 6):
                    acc = fP[j, a, b]
                    for c in range(6):
                        acc += E[a, c] * G[b, c]
                    Ps[a, b] = acc
                    Ps[b, a] = acc
        for a in range(6):
            out_state[k, a] = xs[a]
            out_cov[k, a] = math.sqrt(Ps[a, a]) if Ps[a, a] > 0.0 else 0.0
        out_cov[k, 6], out_cov[k, 7], out_cov[k, 8] = Ps[0, 1], Ps[0, 2], Ps[1, 2]
        nxt = not flags[k] & START
    return nxt


@_jit
def covariance_columns(fP: np.ndarray, rows: np.ndarray, out_cov: np.ndarray) -> None:
    """1σ of the six states and the xy, xh, yh covariances of ``fP[j]`` into ``out_cov[rows[j]]``."""
    for j in range(fP.shape[0]):
        k = rows[j]
        for a in range(6):
            v = fP[j, a, a]
            out_cov[k, a] = math.sqrt(v) if v > 0.0 else (0.0 if v == 0.0 else math.nan)
        out_cov[k, 6], out_cov[k, 7], out_cov[k, 8] = fP[j, 0, 1], fP[j, 0, 2], fP[j, 1, 2]


#: the columns of :func:`velocity_columns`, in order (``*_sigma_*`` are 1σ)
VELOCITY_COLUMNS = ("vx_mps", "vy_mps", "vh_mps", "gs_mps", "vs_mps", "track_deg", "fpa_deg",
                    "vx_sigma_mps", "vy_sigma_mps", "vh_sigma_mps", "gs_sigma_mps",
                    "vs_sigma_mps", "track_sigma_deg", "fpa_sigma_deg")


@_jit
def velocity_columns(fx: np.ndarray, fP: np.ndarray, out: np.ndarray) -> None:
    """Velocity, ground speed, vertical speed, track and flight-path angle with their 1σ
    (first-order propagation of the velocity covariance) of each row of ``fx`` / ``fP``
    into ``out`` (rows × :data:`VELOCITY_COLUMNS`). Track: degrees clockwise from north
    (X) in [0, 360); vertical speed and flight-path angle positive up. NaN where the row
    has no estimate; track and its σ NaN at zero ground speed."""
    r2d = 180.0 / math.pi
    for j in range(fx.shape[0]):
        vx, vy, vh = fx[j, 3], fx[j, 4], fx[j, 5]
        pxx, pxy, pyy = fP[j, 3, 3], fP[j, 3, 4], fP[j, 4, 4]
        pxh, pyh, phh = fP[j, 3, 5], fP[j, 4, 5], fP[j, 5, 5]
        g2 = vx * vx + vy * vy
        gs = math.sqrt(g2)
        v2 = g2 + vh * vh
        out[j, 0], out[j, 1], out[j, 2], out[j, 3], out[j, 4] = vx, vy, vh, gs, vh
        out[j, 7] = math.sqrt(pxx) if pxx >= 0.0 else math.nan
        out[j, 8] = math.sqrt(pyy) if pyy >= 0.0 else math.nan
        out[j, 9] = out[j, 11] = math.sqrt(phh) if phh >= 0.0 else math.nan
        if g2 > 0.0:
            trk = math.atan2(vy, vx) * r2d
            out[j, 5] = trk + 360.0 if trk < 0.0 else trk
            var_gs = (vx * vx * pxx + 2.0 * vx * vy * pxy + vy * vy * pyy) / g2
            var_trk = (vy * vy * pxx - 2.0 * vx * vy * pxy + vx * vx * pyy) / (g2 * g2)
            cov_gh = (vx * pxh + vy * pyh) / gs
            var_fpa = (g2 * phh - 2.0 * gs * vh * cov_gh + vh * vh * var_gs) / (v2 * v2)
            out[j, 10] = math.sqrt(max(var_gs, 0.0))
            out[j, 12] = math.sqrt(max(var_trk, 0.0)) * r2d
            out[j, 13] = math.sqrt(max(var_fpa, 0.0)) * r2d
        else:
            out[j, 5] = out[j, 12] = math.nan
            out[j, 10] = math.sqrt(pxx) if pxx >= 0.0 else math.nan
            out[j, 13] = math.nan
        out[j, 6] = math.atan2(vh, gs) * r2d if v2 > 0.0 else math.nan


@_jit
def live_chunk(t: np.ndarray, sr: np.ndarray, el: np.ndarray, az: np.ndarray,
               good: np.ndarray, n: int, x: np.ndarray, P: np.ndarray, carry: np.ndarray,
               params: np.ndarray, nis: np.ndarray, flags: np.ndarray, fx: np.ndarray,
               fP: np.ndarray, out: np.ndarray, fix_rows: np.ndarray, fixes: np.ndarray) -> int:
    """:func:`forward` over the first ``n`` samples of preallocated buffers, then
    :func:`velocity_columns` of them into ``out[:n]``, rounded to 1e-4 (m/s, deg);
    returns the number of outliers. One compiled call per chunk of the live stream."""
    forward(t, sr, el, az, good, 0, n, x, P, carry, params, nis, flags, fx[:n], fP[:n],
            fix_rows, fixes)
    velocity_columns(fx[:n], fP[:n], out[:n])
    bad = 0
    for k in range(n):
        if flags[k] & OUTLIER:
            bad += 1
        for c in range(out.shape[1]):  # to 1e-4 (m/s, deg): shorter JSON, faster to encode
            v = out[k, c]
            if math.isfinite(v):
                out[k, c] = math.floor(v * 1e4 + 0.5) / 1e4
    return bad
