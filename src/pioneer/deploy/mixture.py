"""Mixture-density read-outs in plain numpy: decision and uncertainty (paper §IV-B).

The same formulas as :func:`pioneer.learn.models.uncertainty` (torch), for processes that
must not import torch (the robot runtime, analysis scripts). With mixture weights
π = softmax(logits), component means μ_k ∈ R² and diagonal standard deviations σ_k ∈ R², the
law of total variance, summed over the two action dimensions d, splits the predictive variance
into

    aleatoric  = Σ_k π_k Σ_d σ_kd²                       (expected within-component variance)
    epistemic  = Σ_k π_k ‖μ_k − Σ_j π_j μ_j‖²            (variance of the component means)

(Choi et al., ICRA 2018, arXiv 1709.02249). Units: (m/s)² + (rad/s)², as the paper sums them.
"""

from __future__ import annotations

import typing
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from pioneer.config import default
from pioneer.errors import ConfigError, expect

__all__ = [
    "ACTION_MODES",
    "MIRROR_ACTION",
    "ActionMode",
    "log_softmax",
    "mixture_action",
    "mixture_uncertainty",
    "softmax",
    "symmetric_mixture",
]

ActionMode = Literal["mode", "mean"]  # the MDN's deterministic action: the mixture's mode or mean
ACTION_MODES: tuple[str, ...] = typing.get_args(ActionMode)


def softmax(logits: NDArray[np.floating]) -> NDArray[np.float64]:
    """Numerically stable softmax over the last axis (float64), shape of ``logits``."""
    z = np.asarray(logits, dtype=np.float64)
    z = z - z.max(axis=-1, keepdims=True)
    e = np.exp(z)
    out: NDArray[np.float64] = e / e.sum(axis=-1, keepdims=True)
    return out


def mixture_uncertainty(
    logits: NDArray[np.floating], mu: NDArray[np.floating], sigma: NDArray[np.floating]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(aleatoric, epistemic)``, each ``(N,)``, from logits ``(N, K)``, means ``(N, K, D)``
    and standard deviations ``(N, K, D)`` of a diagonal Gaussian mixture (module docstring)."""
    pi = softmax(logits)
    m = np.asarray(mu, dtype=np.float64)
    s = np.asarray(sigma, dtype=np.float64)
    aleatoric = np.sum(pi * np.sum(s * s, axis=-1), axis=-1)
    mbar = np.sum(pi[..., None] * m, axis=-2)
    epistemic = np.sum(pi * np.sum((m - mbar[..., None, :]) ** 2, axis=-1), axis=-1)
    return aleatoric, epistemic


def mixture_action(
    logits: NDArray[np.floating], mu: NDArray[np.floating], mode: str = "mode"
) -> NDArray[np.float64]:
    """The deterministic action ``(N, D)`` of a mixture.

    ``"mode"`` (the default, docs/student.md): the mean of the most probable component — a
    command the teacher actually gave in similar situations, never the average of two
    distinct manoeuvres (passing left vs right averages to driving straight into the
    human). ``"mean"``: the mixture mean Σ_k π_k μ_k, smoother but prone to exactly that
    averaging.
    """
    m = np.asarray(mu, dtype=np.float64)
    if mode == "mode":
        k = np.argmax(np.asarray(logits), axis=-1)
        out: NDArray[np.float64] = np.take_along_axis(m, k[..., None, None], axis=-2)[..., 0, :]
        return out
    if mode == "mean":
        mean: NDArray[np.float64] = np.sum(softmax(logits)[..., None] * m, axis=-2)
        return mean
    fix = f"use {default(mixture_action, 'mode')!r}"
    raise ConfigError(expect("action_mode", f"one of {ACTION_MODES}", mode, fix))


MIRROR_ACTION = np.array([1.0, -1.0], dtype=np.float32)  # (v, ω) → (v, −ω): the mirrored command


def log_softmax(logits: NDArray[np.floating]) -> NDArray[np.float32]:
    """log softmax over the last axis, float32 (as :func:`torch.log_softmax`)."""
    z = np.asarray(logits, dtype=np.float32)
    z = z - z.max(axis=-1, keepdims=True)
    out: NDArray[np.float32] = z - np.log(np.exp(z).sum(axis=-1, keepdims=True))
    return out


def symmetric_mixture(
    own: tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.float32]],
    mirrored: tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.float32]],
) -> tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.float32]]:
    """The mirror-equivariant mixture ½ p(u | x) + ½ p(m(u) | M x) of a network's mixture
    ``own`` of the inputs x and ``mirrored``, its mixture of their mirror image M x, with
    m(v, ω) = (v, −ω): ``(logits (N, 2K), mu (N, 2K, 2), sigma (N, 2K, 2))``, the first K
    components x's, the last K M x's with ω negated. Its logits are the halves' log-weights,
    so a mirrored input swaps the halves and mirrors every mean: the command of M x is the
    mirrored command of x, and the uncertainty is the same. Torch twin:
    :func:`pioneer.learn.models.symmetrise_mixture`."""
    (lo, mo, so), (lm, mm, sm) = own, mirrored
    logits = np.concatenate([log_softmax(lo), log_softmax(lm)], axis=-1)
    mu = np.concatenate([mo, mm * MIRROR_ACTION], axis=-2)
    return logits, mu, np.concatenate([so, sm], axis=-2)
