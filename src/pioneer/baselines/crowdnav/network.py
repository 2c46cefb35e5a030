"""CrowdNav++ actor–critic (formulation in :mod:`pioneer.baselines.crowdnav`) and its
safetensors checkpoints."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import torch
from annotated_types import Lt
from numpy.typing import NDArray
from torch import nn

from pioneer.bounds import Count, Finite, Positive
from pioneer.config import Config
from pioneer.nn.attention import node_attention, pool_attention
from pioneer.nn.checkpoint import load_checked, read_checkpoint, stored_config, write_checkpoint
from pioneer.nn.layers import Tanh, seeded_linear

__all__ = [
    "CHECKPOINT_FORMAT",
    "ROBOT_DIM",
    "TEMPORAL_DIM",
    "CrowdNavConfig",
    "CrowdNavNet",
    "load_crowdnav",
    "read_crowdnav_meta",
    "save_crowdnav",
]

CHECKPOINT_FORMAT = "pioneer.crowdnav/1"
ROBOT_DIM = 8  # [p_x, p_y, r, g_x − p_x, g_y − p_y, v_pref, cos θ, sin θ]
TEMPORAL_DIM = 2  # [v, ω]
F32 = NDArray[np.float32]
DeltaRange = tuple[Annotated[float, Lt(0)], Positive]  # (low, high) of a change: low < 0 < high


@dataclasses.dataclass(frozen=True)
class CrowdNavConfig(Config):
    """Observation, network and action parameters of CrowdNav++ (defaults: see module doc)."""

    # N_max, spatial-edge slots (nearest kept); training sets the scenario's N
    max_humans: Count = 5
    n_pred: Count = 5  # K, predicted positions per human
    pred_dt: Positive = 0.25  # [s] Δt_pred between predicted positions (the original's step)
    sensor_range: Positive = 5.0  # [m] humans farther from the robot's centre are masked
    embed: Count = 64  # E, node/edge embedding width
    hidden: Count = 64  # H, GRU state width
    head_hidden: Count = 64  # hidden units of the actor and critic MLPs
    dv_range: DeltaRange = (-0.1, 0.087)  # [m/s] Δv per step (original)
    dtheta_range: DeltaRange = (-0.06, 0.06)  # [rad] Δθ per step (original)
    log_std_init: Finite = -0.5  # initial log σ of the Gaussian (unit action box)

    @property
    def spatial_dim(self) -> int:
        """Width of one spatial edge: 2 (K + 1)."""
        return 2 * (self.n_pred + 1)


# ------------------------------------------------------------------------------ network
class CrowdNavNet(nn.Module):
    """Recurrent attention actor–critic of CrowdNav++ (shapes in the module docstring)."""

    config: CrowdNavConfig

    def __init__(self, config: CrowdNavConfig | None = None, seed: int = 0) -> None:
        super().__init__()
        cfg = self.config = config or CrowdNavConfig()
        gen = torch.Generator().manual_seed(int(seed))
        e, h, f = cfg.embed, cfg.hidden, cfg.head_hidden
        self.robot_embed = seeded_linear(ROBOT_DIM + TEMPORAL_DIM, e, gen)
        self.spatial_embed = seeded_linear(cfg.spatial_dim, e, gen)
        self.hh_qkv = seeded_linear(e, 3 * e, gen)  # W_q, W_k, W_v of the human–human attention
        self.rh_q = seeded_linear(e, e, gen)
        self.rh_k = seeded_linear(e, e, gen)
        self.merge = seeded_linear(2 * e, e, gen)
        self.gru = nn.GRUCell(e, h)
        bound = 1.0 / math.sqrt(h)
        for prm in self.gru.parameters():
            nn.init.uniform_(prm, -bound, bound, generator=gen)
        self.actor = nn.Sequential(
            seeded_linear(h, f, gen), Tanh(), seeded_linear(f, f, gen), Tanh()
        )
        self.mean_head = seeded_linear(f, 2, gen)
        self.critic = nn.Sequential(
            seeded_linear(h, f, gen), Tanh(), seeded_linear(f, f, gen), Tanh()
        )
        self.value_head = seeded_linear(f, 1, gen)
        with torch.no_grad():  # small initial means: start near "keep the command"
            self.mean_head.weight.mul_(0.01)
            self.mean_head.bias.zero_()
        self.log_std = nn.Parameter(torch.full((2,), float(cfg.log_std_init)))
        self.eval()

    def encode(
        self, robot: torch.Tensor, temporal: torch.Tensor, spatial: torch.Tensor, mask: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Graph features ``x`` (..., E), robot–human weights (..., N) and human–human weights
        (..., N, N) of observations with any leading batch shape."""
        lead = robot.shape[:-1]
        n = spatial.shape[-2]
        robot = robot.reshape(-1, ROBOT_DIM)
        temporal = temporal.reshape(-1, TEMPORAL_DIM)
        spatial = spatial.reshape(-1, n, self.config.spatial_dim)
        mask = mask.reshape(-1, n)
        scale = 1.0 / math.sqrt(self.config.embed)
        r = torch.relu(self.robot_embed(torch.cat([robot, temporal], dim=-1)))
        s = torch.relu(self.spatial_embed(spatial))
        # each attention block one compiled loop forward and back (pioneer.nn.attention)
        hum, a_hh = node_attention(self.hh_qkv(s), s, mask, scale)
        c, a_rh = pool_attention(self.rh_k(hum), self.rh_q(r), hum, mask, scale)
        x = torch.relu(self.merge(torch.cat([r, c], dim=-1)))
        return x.reshape(*lead, -1), a_rh.reshape(*lead, n), a_hh.reshape(*lead, n, n)

    def heads(self, h: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Action mean (..., 2) and value (...) from GRU states (..., H)."""
        mean = self.mean_head(self.actor(h))
        value = self.value_head(self.critic(h)).squeeze(-1)
        return mean, value

    def forward(
        self,
        robot: torch.Tensor,
        temporal: torch.Tensor,
        spatial: torch.Tensor,
        mask: torch.Tensor,
        h: torch.Tensor,
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """One step for a batch (B, …): ``(mean (B, 2), value (B,), new hidden (B, H))``."""
        x, _, _ = self.encode(robot, temporal, spatial, mask)
        h_new = self.gru(x, h)
        mean, value = self.heads(h_new)
        return mean, value, h_new

    def initial_state(self, batch: int) -> torch.Tensor:
        """The GRU state at the start of an episode, zeros (batch, H)."""
        return torch.zeros(batch, self.config.hidden)


# ------------------------------------------------------------------------------ checkpoints
def save_crowdnav(
    model: CrowdNavNet, path: str | Path, info: Mapping[str, Any] | None = None
) -> Path:
    """Write the policy weights to ``.safetensors`` (atomically), config and ``info`` as JSON."""
    return write_checkpoint(model, model.config.to_dict(), path, CHECKPOINT_FORMAT, info)


def _read(p: Path, tensors: bool) -> tuple[dict[str, Any], dict[str, torch.Tensor]]:
    fix = "train it with `pioneer train crowdnav++` (the file is missing, corrupt or not one)"
    meta, arrays = read_checkpoint(p, CHECKPOINT_FORMAT, "CrowdNav++ weights", fix, fix, tensors)
    return {"config": meta["config"], "info": meta["info"]}, arrays


def read_crowdnav_meta(path: str | Path) -> dict[str, Any]:
    """``config`` and ``info`` (dicts) stored with CrowdNav++ weights."""
    return _read(Path(path), tensors=False)[0]


def load_crowdnav(path: str | Path) -> CrowdNavNet:
    """Rebuild the network saved at ``path`` in eval mode; a bad file raises :class:`DataError`."""
    p = Path(path)
    meta, arrays = _read(p, tensors=True)
    cfg = stored_config(p, meta, CrowdNavConfig, "re-train or re-save")
    return load_checked(
        CrowdNavNet(cfg), arrays, p, f"CrowdNav++ {cfg.to_dict()}", "re-train or re-save it"
    )
