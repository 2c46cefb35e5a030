"""CVaR-BF barrier maths: look-ahead point, dynamic-zone and wall barriers, the CVaR bound
(formulation in :mod:`pioneer.baselines.cvar_bf`)."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from pioneer.baselines.cvar_bf.config import CvarBfConfig

__all__ = [
    "cvar_lower",
    "cvar_weights",
    "dynamic_zone_barrier",
    "lookahead_jacobian",
    "lookahead_point",
    "wall_barrier",
]

F64 = NDArray[np.float64]


def lookahead_point(pose: F64, ell: float) -> F64:
    """p_l = p_r + ℓ (cos θ, sin θ) of poses ``(..., 3)`` → ``(..., 2)`` [m]."""
    pose = np.asarray(pose, dtype=np.float64)
    th = pose[..., 2]
    return pose[..., :2] + ell * np.stack([np.cos(th), np.sin(th)], axis=-1)


def lookahead_jacobian(theta: float, ell: float) -> F64:
    """J(θ) with ṗ_l = J(θ) (v, ω): ``[[cos θ, −ℓ sin θ], [sin θ, ℓ cos θ]]``, shape (2, 2)."""
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -ell * s], [s, ell * c]])


def dynamic_zone_barrier(
    p_r: F64,
    v_r: F64,
    p_o: F64,
    v_o: F64,
    radius: F64 | float,
    rho: float = CvarBfConfig.rho,
    v_hat: float = CvarBfConfig.v_hat,
    eps_vel: float = CvarBfConfig.eps_vel,
    grad: bool = False,
) -> tuple[F64, F64, F64]:
    """Dynamic-zone barrier h [m²] and its gradients w.r.t. the robot point and velocity.

    All arguments broadcast: ``p_r, v_r, p_o, v_o`` are ``(..., 2)`` [m, m/s], ``radius`` R
    [m] is ``(...)``. Returns ``(h, ∂h/∂p_r, ∂h/∂v_r)`` with shapes ``(...)``, ``(..., 2)``,
    ``(..., 2)`` (the gradients are zeros unless ``grad``).
    """
    a = np.asarray(p_o, dtype=np.float64) - p_r  # p_rel
    b = np.asarray(v_o, dtype=np.float64) - v_r  # v_rel
    na = np.sqrt(np.maximum((a * a).sum(-1), 1e-18))
    nb = np.sqrt((b * b).sum(-1) + eps_vel * eps_vel)
    c = (a * b).sum(-1) / (na * nb)
    r2 = np.asarray(radius, dtype=np.float64) ** 2
    k = r2 * np.linalg.norm(v_o, axis=-1) / v_hat
    h = na * na - r2 - k * np.logaddexp(0.0, -rho * c) / rho
    if not grad:
        z = np.zeros((*np.shape(h), 2))
        return h, z, z
    sig = 0.5 * (1.0 + np.tanh(-0.5 * rho * c))  # logistic σ(−ρc), dh/dc = K σ(−ρc)
    dh_dc = (k * sig)[..., None]
    ah = a / na[..., None]
    dc_da = (b / nb[..., None] - c[..., None] * ah) / na[..., None]
    dc_db = (ah - c[..., None] * b / nb[..., None]) / nb[..., None]
    dh_da = 2.0 * a + dh_dc * dc_da
    dh_db = dh_dc * dc_db
    return h, -dh_da, -dh_db  # p_rel = p_o − p_r and v_rel = v_o − v_r: chain rule signs


def wall_barrier(p: F64, walls: F64, radius: float) -> tuple[F64, F64]:
    """h_w = d(p, wall)² − radius² for every wall ``(M, 4)`` and its gradient ``(M, 2)``."""
    a = walls[:, :2]
    e = walls[:, 2:] - a
    ll = np.maximum((e * e).sum(-1), 1e-300)
    s = np.clip(((p - a) * e).sum(-1) / ll, 0.0, 1.0)
    d = p - (a + s[:, None] * e)
    return (d * d).sum(-1) - radius * radius, 2.0 * d


def cvar_weights(h: F64, p: F64, beta: float) -> F64:
    """The tail weights q* of CVaR_β of the lower tail of h (samples on the last axis,
    probabilities ``p``): the minimiser of Σ_s q_s h_s over 0 ≤ q_s ≤ p_s/β, Σ_s q_s = 1.

    Greedy: the samples in increasing order of h get their full p_s/β until the mass 1 is
    spent (the last one a fraction of it). Same shape as ``h``.
    """
    h = np.asarray(h, dtype=np.float64)
    flat = h.reshape(-1, h.shape[-1])  # (rows, S): plain fancy indexing, no *_along_axis
    order = np.argsort(flat, axis=-1, kind="stable")
    rows = np.arange(flat.shape[0])[:, None]
    ps = np.broadcast_to(p, h.shape).reshape(flat.shape)[rows, order] / beta
    before = np.cumsum(ps, axis=-1) - ps  # mass given to the lower samples
    q = np.empty_like(flat)
    q[rows, order] = np.minimum(np.maximum(1.0 - before, 0.0), ps)
    return q.reshape(h.shape)


def cvar_lower(h: F64, p: F64, beta: float) -> F64:
    """CVaR_β of the lower tail of h (samples on the last axis, probabilities ``p``).

    −min_ζ [ζ + (1/β) Σ_s p_s max(0, −h_s − ζ)] (Rockafellar–Uryasev), which equals
    min_q Σ_s q_s h_s over 0 ≤ q_s ≤ p_s/β, Σ_s q_s = 1: the mean of the worst β of the mass,
    Σ_s q*_s h_s with the tail weights of :func:`cvar_weights`.
    """
    h = np.asarray(h, dtype=np.float64)
    return (cvar_weights(h, p, beta) * h).sum(-1)
