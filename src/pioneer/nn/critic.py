"""A value network (an MLP) and the pieces of a distributional one: N quantiles of the return
learned by quantile regression (Dabney et al. 2018, "Distributional Reinforcement Learning with
Quantile Regression", QR-DQN, eq. 9–10) and the conditional value at risk read from them."""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from torch import nn

from pioneer.nn.layers import seeded_linear

__all__ = ["Critic", "lower_tail_mean", "quantile_huber", "quantile_levels", "value_loss"]


class Critic(nn.Module):
    """V(x): an MLP (ReLU) of its inputs with ``n_out`` outputs — 1: the expected return;
    N > 1: the return's quantiles at :func:`quantile_levels` ``(N)``."""

    def __init__(
        self, n_in: int, hidden: Sequence[int], gen: torch.Generator, n_out: int = 1
    ) -> None:
        super().__init__()
        layers: list[nn.Module] = []
        for width in hidden:
            layers += [seeded_linear(n_in, width, gen), nn.ReLU()]
            n_in = width
        layers.append(seeded_linear(n_in, n_out, gen))
        self.net = nn.Sequential(*layers)
        self.n_out = n_out

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Values ``(B,)``, or quantiles ``(B, N)`` when ``n_out`` > 1."""
        out: torch.Tensor = self.net(x)
        return out.squeeze(-1) if self.n_out == 1 else out


def quantile_levels(n: int) -> torch.Tensor:
    """The quantile midpoints τ̂_i = (2i − 1) / (2N), i = 1 … N (QR-DQN, Lemma 2)."""
    return (torch.arange(n, dtype=torch.float32) + 0.5) / n


def quantile_huber(pred: torch.Tensor, target: torch.Tensor, kappa: float = 1.0) -> torch.Tensor:
    """The quantile Huber loss of ``pred`` ``(B, N)`` (the quantiles at
    :func:`quantile_levels`) against one sampled return per row ``target`` ``(B,)``:
    mean over rows and quantiles of |τ̂_i − 1{u < 0}| · L_κ(u) / κ, u = target − pred_i,
    L_κ the Huber loss (QR-DQN eq. 10). Its minimiser over a row's distribution of targets
    tends to that distribution's τ̂_i-quantiles as κ → 0 (tested at κ = 0.01)."""
    tau = quantile_levels(pred.shape[-1])
    u = target[:, None] - pred
    abs_u = u.abs()
    huber = torch.where(abs_u <= kappa, 0.5 * u * u, kappa * (abs_u - 0.5 * kappa))
    weight = (tau - (u.detach() < 0).to(pred.dtype)).abs()
    return (weight * huber / kappa).mean()


def lower_tail_mean(quantiles: torch.Tensor, alpha: float) -> torch.Tensor:
    """CVaR_α of the distribution the quantiles ``(..., N)`` describe (each carrying mass
    1/N): the mean of its lowest α share, the quantile that straddles α counted in part;
    α = 1: the mean. Sorted first, so crossing quantiles do not matter."""
    n = quantiles.shape[-1]
    if not 0.0 < alpha <= 1.0:
        raise ValueError(f"alpha: expected 0 < alpha <= 1, received {alpha}")
    q, _ = torch.sort(quantiles, dim=-1)
    mass = alpha * n  # in units of one quantile's mass
    full = min(n, math.floor(mass + 1e-9))
    w = torch.zeros(n, dtype=q.dtype)
    w[:full] = 1.0
    if full < n:
        w[full] = mass - full
    return (q * w).sum(-1) / mass


def value_loss(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """A :class:`Critic`'s regression loss towards one sampled return per row: ½ the mean
    squared error of values ``(B,)``, the quantile Huber loss of quantiles ``(B, N)``."""
    if pred.dim() == 2:
        return quantile_huber(pred, target)
    return 0.5 * ((target - pred) ** 2).mean()
