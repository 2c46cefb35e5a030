"""Layers initialised from an explicit torch generator (never the global torch RNG)."""

from __future__ import annotations

import math

import torch
from torch import nn

__all__ = ["seeded_linear"]


def seeded_linear(n_in: int, n_out: int, gen: torch.Generator) -> nn.Linear:
    """PyTorch's default ``Linear`` initialisation, drawn from ``gen``."""
    layer: nn.Linear = nn.utils.skip_init(nn.Linear, n_in, n_out)
    nn.init.kaiming_uniform_(layer.weight, a=math.sqrt(5.0), generator=gen)
    bound = 1.0 / math.sqrt(n_in)
    nn.init.uniform_(layer.bias, -bound, bound, generator=gen)
    return layer
