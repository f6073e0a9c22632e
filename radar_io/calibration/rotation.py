"""Ground → camera rotation of calibration.md §1 (3-2-1 Euler angles, radians).

Ground frame: origin at the radar, X north, Y east, Z down.  Camera frame:
X_p forward, Y_p right, Z_p down along the optical axis.
``C_PE = R_x(φ) R_y(θ) R_z(ψ)`` maps ground vectors into the camera frame.
"""

from __future__ import annotations

import math

import numpy as np


def rotation_matrix(phi: float, theta: float, psi: float) -> np.ndarray:
    """C_PE (3×3) for roll φ, pitch θ, yaw ψ in radians (spec §1, element by element)."""
    sf, cf = math.sin(phi), math.cos(phi)
    st, ct = math.sin(theta), math.cos(theta)
    sp, cp = math.sin(psi), math.cos(psi)
    return np.array(
        [
            [ct * cp, ct * sp, -st],
            [sf * st * cp - cf * sp, sf * st * sp + cf * cp, sf * ct],
            [cf * st * cp + sf * sp, cf * st * sp - sf * cp, cf * ct],
        ]
    )


def rotation_partials(phi: float, theta: float, psi: float) -> np.ndarray:
    """∂C_PE/∂φ, ∂C_PE/∂θ, ∂C_PE/∂ψ stacked as a (3, 3, 3) array (per radian)."""
    sf, cf = math.sin(phi), math.cos(phi)
    st, ct = math.sin(theta), math.cos(theta)
    sp, cp = math.sin(psi), math.cos(psi)
    d_phi = np.array(
        [
            [0.0, 0.0, 0.0],
            [cf * st * cp + sf * sp, cf * st * sp - sf * cp, cf * ct],
            [-sf * st * cp + cf * sp, -sf * st * sp - cf * cp, -sf * ct],
        ]
    )
    d_theta = np.array(
        [
            [-st * cp, -st * sp, -ct],
            [sf * ct * cp, sf * ct * sp, -sf * st],
            [cf * ct * cp, cf * ct * sp, -cf * st],
        ]
    )
    d_psi = np.array(
        [
            [-ct * sp, ct * cp, 0.0],
            [-sf * st * sp - cf * cp, sf * st * cp - cf * sp, 0.0],
            [-cf * st * sp + sf * cp, cf * st * cp + sf * sp, 0.0],
        ]
    )
    return np.stack([d_phi, d_theta, d_psi])


def angles_from_matrix(c: np.ndarray) -> tuple[float, float, float]:
    """(φ, θ, ψ) in radians of a proper rotation C_PE; φ, ψ in (−π, π], θ in [−π/2, π/2]."""
    c = np.asarray(c, dtype=float)
    theta = math.asin(max(-1.0, min(1.0, -float(c[0, 2]))))
    phi = math.atan2(float(c[1, 2]), float(c[2, 2]))
    psi = math.atan2(float(c[0, 1]), float(c[0, 0]))
    return phi, theta, psi


def wrap_pi(a):
    """Angle(s) in radians wrapped to (−π, π] (scalar or array)."""
    return math.pi - np.mod(math.pi - np.asarray(a, dtype=float), 2.0 * math.pi)
