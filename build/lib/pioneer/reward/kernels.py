"""Kernels of the density reward (paper §IV-A.1, eqs. 9–10).

- Squared exponential:  k_SE(z, z') = g² exp(−‖z − z'‖² / (2 l²))                 (eq. 10)
- Smooth leveraged:     k_SL((z, γ), (z', γ')) = cos(π/2 · (γ − γ')) · k_SE(z, z')   (eq. 9)

For γ, γ' ∈ {±1}, cos(π/2 (γ − γ')) = γ γ', so K_SL = Γ K_SE Γ (Choi et al., T-RO 2019).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["leverage_factor", "se_kernel", "sl_kernel", "sq_dists"]

F64 = NDArray[np.float64]


def sq_dists(a: NDArray[np.floating], b: NDArray[np.floating]) -> NDArray[np.floating]:
    """Squared Euclidean distances, ``(n, d) × (m, d) → (n, m)``, clipped at 0.

    Uses ‖a‖² + ‖b‖² − 2 a·bᵀ (one matrix product); the dtype of ``a`` is kept.
    """
    aa = np.einsum("ij,ij->i", a, a)[:, None]
    bb = np.einsum("ij,ij->i", b, b)[None, :]
    d = aa + bb - 2.0 * (a @ b.T)
    return np.maximum(d, 0.0, out=d)


def se_kernel(a: F64, b: F64, gain2: float, length: float) -> F64:
    """Squared-exponential kernel matrix ``(n, m)`` with gain g² and length scale l."""
    return gain2 * np.exp(sq_dists(a, b) * (-0.5 / (length * length)))


def leverage_factor(gamma_a: F64, gamma_b: F64) -> F64:
    """cos(π/2 · (γ_a − γ_b)) for all pairs, ``(n,) × (m,) → (n, m)``."""
    return np.cos(0.5 * np.pi * (np.asarray(gamma_a)[:, None] - np.asarray(gamma_b)[None, :]))


def sl_kernel(a: F64, gamma_a: F64, b: F64, gamma_b: F64, gain2: float, length: float) -> F64:
    """Smooth leveraged kernel matrix ``(n, m)`` (eq. 9)."""
    return leverage_factor(gamma_a, gamma_b) * se_kernel(a, b, gain2, length)
