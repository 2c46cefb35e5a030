"""CrowdNav++ (Liu et al., ICRA 2023) as a PioneeR policy: observation, network, checkpoints.

Baseline ``crowdnav++`` of the paper's Table I: "Intention aware robot crowd navigation with
attention-based interaction graph". A recurrent actor–critic over a spatio-temporal graph of
the robot and the humans, with human–human self-attention, robot–human attention and the
humans' predicted trajectories, trained with PPO (:mod:`pioneer.learn.ppo`) on the privileged
simulator state (ground-truth human positions and velocities, as in the original).

Formulation as implemented
--------------------------
*Observation* (:func:`build_observation`, from ``info["state"]`` and ``info["world"]``):

- robot node u = [p_x, p_y, r_r, g_x − p_x, g_y − p_y, v_pref, cos θ, sin θ]  (B, 8)
  Positions in the map frame (as the original, whose robot node holds absolute p and g):
  our scenes have walls at fixed map coordinates and the observation has no other wall
  information, so the absolute position is what lets the network learn where the walls are.
  The goal enters as its offset from the robot (the part that matters for reaching it, and
  translation invariant), the heading as (cos θ, sin θ) (no jump at ±π). v_pref = v_max.
- temporal edge w = [v, ω], the last applied command  (B, 2)  (the original uses the robot's
  (v_x, v_y); with incremental unicycle actions the command state is what the policy must know).
- spatial edges e_i = [p_i − p_r, p̂_i(1) − p_r, …, p̂_i(K) − p_r]  (B, N_max, 2(K + 1)),
  robot-relative current and K = 5 predicted positions of every present human, in the map
  frame, sorted by current distance, padded to ``max_humans`` with a mask (B, N_max).
  Absent humans (status GONE) and humans beyond ``sensor_range`` are masked; if more humans are
  present than ``max_humans``, the nearest are kept.
- Prediction: constant velocity from the privileged state, p̂_i(k) = p_i + k Δt_pred v_i with
  Δt_pred = 0.25 s (the original's step, so the horizon stays 1.25 s at our Δt = 0.1 s). The
  original uses a learned predictor (GST); CV is its simplest stand-in and needs no training.

*Network* (:class:`CrowdNavNet`; E = ``embed`` = 64, H = ``hidden`` = 64):

    r   = ReLU(W_r [u, w])                                     robot embedding (B, E)
    s_i = ReLU(W_s e_i)                                        human embeddings (B, N, E)
    A^hh = softmax_j((W_q s_i)ᵀ(W_k s_j) / √E | mask_j)        human–human attention (B, N, N)
    h_i = ReLU(s_i + Σ_j A^hh_ij W_v s_j) · mask_i
    a^rh = softmax_i((W_q' r)ᵀ(W_k' h_i) / √E | mask_i)         robot–human attention (B, N)
    c   = Σ_i a^rh_i h_i
    x   = ReLU(W_x [r, c]);   h_t = GRU(x, h_{t−1})           temporal part of the graph
    μ   = actor(h_t) (2,),   V = critic(h_t)                    tanh MLPs, 64 hidden units

The masked softmaxes give exactly zero weight to absent humans (and all-zero weights when no
human is present), so the output does not depend on the padded entries. The GRU's hidden state
is reset at the start of every episode (:meth:`CrowdNavPolicy.reset`).

*Action* (:func:`command_from_action`): a diagonal Gaussian N(μ, diag σ²) over a ∈ R², clipped to
[−1, 1]² and scaled piecewise-linearly (0 ↦ 0) onto the original's unicycle increments
Δv ∈ [−0.1, 0.087] m/s and Δθ ∈ [−0.06, 0.06] rad per step. The policy integrates them on
the command state, since our environment takes absolute commands:

    v_t = clip(v_{t−1} + Δv, v_min, v_max),   ω_t = clip(Δθ / Δt, −ω_max, ω_max)

with v_{t−1} = ``state.command[:, 0]`` and the limits of the world's robot. As in the original,
Δθ is the heading change of the step (not an increment of ω); at our Δt = 0.1 s the turn rate
is at most 0.6 rad/s (0.24 rad/s in the original at Δt = 0.25 s) and the speed can change by
up to 0.87 m/s² (0.35 m/s²). The original samples unit-scale raw actions and clips them to
these small ranges, so most samples saturate; scaling the unit box keeps the initial
Gaussian (σ = e^−0.5 ≈ 0.6) inside it. In eval mode the action is the mean μ (deterministic).

Checkpoints (:func:`save_crowdnav` / :func:`load_crowdnav`) are safetensors with the
:class:`CrowdNavConfig` and free-form info as JSON metadata; no pickle.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import torch
from numpy.typing import NDArray
from torch import nn

from pioneer.config import Config, check_positive
from pioneer.control.policy import register_policy
from pioneer.errors import ConfigError, DataError, PioneerError, expect
from pioneer.learn.checkpoint import load_checked, read_checkpoint, write_checkpoint
from pioneer.learn.models import _linear
from pioneer.sim.humans import GONE
from pioneer.sim.robot import RobotConfig
from pioneer.sim.world import State, World

__all__ = [
    "CHECKPOINT_FORMAT",
    "ROBOT_DIM",
    "TEMPORAL_DIM",
    "CrowdNavConfig",
    "CrowdNavNet",
    "CrowdNavObs",
    "CrowdNavPolicy",
    "build_observation",
    "command_from_action",
    "load_crowdnav",
    "make_crowdnav_policy",
    "read_crowdnav_meta",
    "save_crowdnav",
    "shipped_weights",
]

CHECKPOINT_FORMAT = "pioneer.crowdnav/1"
ROBOT_DIM = 8  # [p_x, p_y, r, g_x − p_x, g_y − p_y, v_pref, cos θ, sin θ]
TEMPORAL_DIM = 2  # [v, ω]
F32 = NDArray[np.float32]


@dataclasses.dataclass(frozen=True)
class CrowdNavConfig(Config):
    """Observation, network and action parameters of CrowdNav++ (defaults: see module doc)."""

    max_humans: int = 5  # N_max, spatial-edge slots (nearest kept); training sets the scenario's N
    n_pred: int = 5  # K, predicted positions per human
    pred_dt: float = 0.25  # [s] Δt_pred between predicted positions (the original's step)
    sensor_range: float = 5.0  # [m] humans farther from the robot's centre are masked
    embed: int = 64  # E, node/edge embedding width
    hidden: int = 64  # H, GRU state width
    head_hidden: int = 64  # hidden units of the actor and critic MLPs
    dv_range: tuple[float, float] = (-0.1, 0.087)  # [m/s] Δv per step (original)
    dtheta_range: tuple[float, float] = (-0.06, 0.06)  # [rad] Δθ per step (original)
    log_std_init: float = -0.5  # initial log σ of the Gaussian (unit action box)

    def __post_init__(self) -> None:
        for name in ("max_humans", "n_pred", "embed", "hidden", "head_hidden"):
            value = getattr(self, name)
            if not (isinstance(value, int) and value >= 1):
                raise ConfigError(
                    expect(f"CrowdNavConfig.{name}", "an integer >= 1", value, f"set {name} >= 1")
                )
        check_positive("CrowdNavConfig", "pred_dt", self.pred_dt)
        check_positive("CrowdNavConfig", "sensor_range", self.sensor_range)
        for name in ("dv_range", "dtheta_range"):
            lo, hi = getattr(self, name)
            if not (math.isfinite(lo) and math.isfinite(hi) and lo < 0.0 < hi):
                raise ConfigError(
                    expect(
                        f"CrowdNavConfig.{name}", "(low < 0 < high)", (lo, hi), "e.g. (-0.1, 0.1)"
                    )
                )
        if not math.isfinite(self.log_std_init):
            raise ConfigError(
                expect("CrowdNavConfig.log_std_init", "a finite number", self.log_std_init, "-0.5")
            )

    @property
    def spatial_dim(self) -> int:
        """Width of one spatial edge: 2 (K + 1)."""
        return 2 * (self.n_pred + 1)


# ------------------------------------------------------------------------------ observation
class CrowdNavObs(NamedTuple):
    """One graph observation per world copy (float32; see the module docstring)."""

    robot: F32  # (B, 8) robot node
    temporal: F32  # (B, 2) temporal edge [v, ω]
    spatial: F32  # (B, N_max, 2(K + 1)) robot-relative current + predicted human positions [m]
    mask: NDArray[np.bool_]  # (B, N_max) True: a detected human in this slot


def build_observation(state: State, world: World, config: CrowdNavConfig) -> CrowdNavObs:
    """The CrowdNav++ graph observation of every copy of ``state`` (privileged, ground truth)."""
    cfg = config
    b = state.batch_size
    rob = world.sim.robot
    p = state.robot[:, :2]
    th = state.robot[:, 2]
    goal_off = state.goal - p
    robot = np.stack(
        [
            p[:, 0],
            p[:, 1],
            np.full(b, rob.radius),
            goal_off[:, 0],
            goal_off[:, 1],
            np.full(b, rob.v_max),
            np.cos(th),
            np.sin(th),
        ],
        axis=-1,
    )
    n = state.n_humans
    m = cfg.max_humans
    spatial = np.zeros((b, m, cfg.spatial_dim), dtype=np.float32)
    mask = np.zeros((b, m), dtype=np.bool_)
    if n:
        ks = np.arange(cfg.n_pred + 1) * cfg.pred_dt  # (K+1,) [s]
        traj = state.h_pos[:, :, None, :] + state.h_vel[:, :, None, :] * ks[None, None, :, None]
        rel = (traj - p[:, None, None, :]).reshape(b, n, -1)  # (B, N, 2(K+1))
        dist = np.hypot(rel[:, :, 0], rel[:, :, 1])
        seen = (state.h_status != GONE) & (dist <= cfg.sensor_range)
        order = np.argsort(np.where(seen, dist, np.inf), axis=1, kind="stable")[:, :m]
        k = order.shape[1]
        seen_k = np.take_along_axis(seen, order, axis=1)
        edges = np.take_along_axis(rel, order[:, :, None], axis=1)
        spatial[:, :k] = np.where(seen_k[:, :, None], edges, 0.0)
        mask[:, :k] = seen_k
    return CrowdNavObs(robot.astype(np.float32), state.command.astype(np.float32), spatial, mask)


def command_from_action(
    action: NDArray[np.floating],
    v_prev: NDArray[np.floating],
    robot: RobotConfig,
    dt: float,
    config: CrowdNavConfig,
) -> NDArray[np.float64]:
    """Absolute commands ``(B, 2)`` (v [m/s], ω [rad/s]) from raw actions ``(B, 2)``.

    a is clipped to [−1, 1]² and scaled piecewise-linearly onto Δv ∈ ``dv_range``,
    Δθ ∈ ``dtheta_range``; v = clip(v_prev + Δv, v_min, v_max), ω = clip(Δθ/Δt, ±ω_max).
    """
    a = np.clip(np.asarray(action, dtype=np.float64).reshape(-1, 2), -1.0, 1.0)
    lo = np.array([config.dv_range[0], config.dtheta_range[0]])
    hi = np.array([config.dv_range[1], config.dtheta_range[1]])
    inc = np.where(a >= 0.0, a * hi, -a * lo)
    v = np.clip(np.asarray(v_prev, dtype=np.float64) + inc[:, 0], robot.v_min, robot.v_max)
    w = np.clip(inc[:, 1] / dt, -robot.omega_max, robot.omega_max)
    return np.stack([v, w], axis=-1)


# ------------------------------------------------------------------------------ network
def _masked_softmax(scores: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Softmax over the last axis restricted to ``mask``; masked entries get exactly 0, and a
    row with no unmasked entry is all zeros (no NaN)."""
    s = scores.masked_fill(~mask, -math.inf)
    top = s.amax(dim=-1, keepdim=True)
    top = torch.where(torch.isfinite(top), top, torch.zeros_like(top))
    e = torch.exp(s - top) * mask
    return e / e.sum(dim=-1, keepdim=True).clamp_min(1e-30)


class CrowdNavNet(nn.Module):
    """Recurrent attention actor–critic of CrowdNav++ (shapes in the module docstring)."""

    config: CrowdNavConfig

    def __init__(self, config: CrowdNavConfig | None = None, seed: int = 0) -> None:
        super().__init__()
        cfg = self.config = config or CrowdNavConfig()
        gen = torch.Generator().manual_seed(int(seed))
        e, h, f = cfg.embed, cfg.hidden, cfg.head_hidden
        self.robot_embed = _linear(ROBOT_DIM + TEMPORAL_DIM, e, gen)
        self.spatial_embed = _linear(cfg.spatial_dim, e, gen)
        self.hh_qkv = _linear(e, 3 * e, gen)  # W_q, W_k, W_v of the human–human attention
        self.rh_q = _linear(e, e, gen)
        self.rh_k = _linear(e, e, gen)
        self.merge = _linear(2 * e, e, gen)
        self.gru = nn.GRUCell(e, h)
        bound = 1.0 / math.sqrt(h)
        for prm in self.gru.parameters():
            nn.init.uniform_(prm, -bound, bound, generator=gen)
        self.actor = nn.Sequential(_linear(h, f, gen), nn.Tanh(), _linear(f, f, gen), nn.Tanh())
        self.mean_head = _linear(f, 2, gen)
        self.critic = nn.Sequential(_linear(h, f, gen), nn.Tanh(), _linear(f, f, gen), nn.Tanh())
        self.value_head = _linear(f, 1, gen)
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
        q, k, v = self.hh_qkv(s).chunk(3, dim=-1)
        a_hh = _masked_softmax(q @ k.transpose(-1, -2) * scale, mask.unsqueeze(-2))
        hum = torch.relu(s + a_hh @ v) * mask.unsqueeze(-1)
        a_rh = _masked_softmax(
            (self.rh_k(hum) @ self.rh_q(r).unsqueeze(-1)).squeeze(-1) * scale, mask
        )
        c = (a_rh.unsqueeze(-1) * hum).sum(dim=-2)
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


def obs_tensors(obs: CrowdNavObs) -> tuple[torch.Tensor, ...]:
    """The four observation arrays as tensors (no copy)."""
    return tuple(torch.from_numpy(np.ascontiguousarray(x)) for x in obs)


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
    try:
        cfg = CrowdNavConfig.from_dict(meta["config"])
    except PioneerError as exc:
        raise DataError(
            expect(f"{p}: config", "a valid CrowdNavConfig", str(exc), "re-train or re-save")
        ) from exc
    return load_checked(
        CrowdNavNet(cfg), arrays, p, f"CrowdNav++ {cfg.to_dict()}", "re-train or re-save it"
    )


def shipped_weights(scenario: str) -> Path:
    """Path of the shipped weights for ``scenario`` (``data/baselines/crowdnav-{scenario}``; a
    variant with a built-in ``base`` uses that scenario's)."""
    from pioneer.data import shipped_crowdnav_weights

    return shipped_crowdnav_weights(scenario)


# ------------------------------------------------------------------------------ policy
class CrowdNavPolicy:
    """CrowdNav++ acting from the privileged state in ``info`` (deterministic: mean action).

    ``reset`` zeroes the GRU state; ``act`` builds the graph observation, advances the GRU one
    step and integrates the mean increments on the last command. ``attention`` holds the last
    robot–human weights over the sorted, present humans.
    """

    def __init__(self, model: CrowdNavNet, name: str = "crowdnav++") -> None:
        self.model = model.eval()
        self.name = name
        self.h = model.initial_state(1)
        self.attention: NDArray[np.float32] = np.zeros(0, dtype=np.float32)

    def reset(self, info: Mapping[str, Any], rng: np.random.Generator) -> None:
        """Start an episode: GRU state to zero (the policy is deterministic; ``rng`` unused)."""
        self.h = self.model.initial_state(1)

    def act(self, obs: NDArray[np.float32], info: Mapping[str, Any]) -> NDArray[np.float64]:
        """The command ``(v [m/s], ω [rad/s])``, shape ``(2,)``."""
        state, world = info.get("state"), info.get("world")
        if not isinstance(state, State) or not isinstance(world, World):
            raise ConfigError(
                expect(
                    "CrowdNavPolicy info",
                    "'state' (State) and 'world' (World) entries",
                    sorted(info),
                    "run it in pioneer.sim.env.NavEnv, whose info carries them",
                )
            )
        o = build_observation(state, world, self.model.config)
        with torch.inference_mode():
            x, a_rh, _ = self.model.encode(*obs_tensors(o))
            self.h = self.model.gru(x, self.h)
            mean, _ = self.model.heads(self.h)
        self.attention = a_rh[0].numpy()[o.mask[0]]
        cmd = command_from_action(
            mean.numpy(), state.command[:, 0], world.sim.robot, world.sim.dt, self.model.config
        )
        return cmd[0]


def make_crowdnav_policy(
    weights: str | Path | None = None,
    scenario: str | None = None,
    name: str = "crowdnav++",
    torch_threads: int | None = 1,
) -> CrowdNavPolicy:
    """Policy factory: ``weights`` (``{scenario}`` filled in) or the shipped file for ``scenario``.

    ``torch_threads`` sets torch's intra-op threads of this process (1: a batch-1 step gains
    nothing from threads and evaluation runs one worker per core); ``None`` leaves it.
    """
    if weights is None:
        if scenario is None:
            raise ConfigError(
                expect("crowdnav++", "weights=FILE or a scenario", None, "pass scenario='hr-rl'")
            )
        path = shipped_weights(scenario)
    else:
        path = Path(str(weights).format(scenario=scenario) if scenario else str(weights))
    if torch_threads is not None:
        torch.set_num_threads(int(torch_threads))
    return CrowdNavPolicy(load_crowdnav(path), name=name)


register_policy("crowdnav++", make_crowdnav_policy)
