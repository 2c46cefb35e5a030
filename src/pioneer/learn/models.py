"""Student networks distilled from the teacher: MDN and MLP, and their checkpoints (paper §IV-B).

- :class:`MDN`: 29 → 128 → 128 (ReLU, dropout 0.1) → K = 10 diagonal Gaussian components:
  mixture logits (softmax), means and standard deviations (softplus + floor); loss = negative
  log-likelihood of the mixture (paper §IV-B; Choi et al., ICRA 2018).
- :class:`MLPStudent`: the same trunk with 2 outputs and a mean-squared-error loss (baseline).
- :func:`uncertainty`: the law-of-total-variance split into aleatoric and epistemic parts.
- :func:`pioneer.learn.training.train_student`: Adam, lr 1e−3, batch 256, seeded; returns the
  loss history.
- :func:`save_student` / :func:`load_student`: safetensors weights with the config as JSON in
  the file's metadata — a checkpoint rebuilds its own model and cannot execute code.

Choices and deviations from the paper:

- Deterministic action: the mean of the most probable component (``action_mode="mode"``,
  default); the mixture mean (``"mean"``) is an option. See
  :func:`pioneer.deploy.mixture.mixture_action` for why.
- Inputs are standardised and the action outputs are de-standardised by per-feature mean/std
  buffers stored in the module (and so in the checkpoint and the ONNX graph). All outputs
  (μ, σ, uncertainties) are therefore in physical units: v [m/s], ω [rad/s].
- σ = softplus(raw) · action_std + ``sigma_floor`` (floor in physical units), so the NLL is
  bounded below and cannot diverge on near-duplicate teacher labels.
- ``nll_beta`` = β > 0 (off by default) trains the MDN with the β-NLL of Seitzer et al.
  (ICLR 2022): each frame's NLL weighted by its detached total variance^β (standardised
  units, weights scaled to mean 1). Measured in docs/student.md; not used by the shipped MDNs.
- The MLP's MSE is taken on standardised actions so that v and ω weigh equally.
- ``symmetric`` (beyond the paper, off by default): the student is mirror-equivariant by
  construction — the network runs on the inputs and on their mirror image
  (:meth:`pioneer.deploy.runtime.StudentInputs.mirror_map`) and the two are combined
  (:func:`symmetrise_mixture`: the MDN's 2K-component mixture; the MLP's mean), so HL-RR is
  HR-RL seen in a mirror and a student of many worlds spends no capacity on the side.
- Randomness: weights are initialised from a ``torch.Generator`` seeded by ``seed``; training
  shuffles with its own generator and runs dropout under a forked, seeded torch RNG, so neither
  the global numpy RNG nor the caller's torch RNG state is used or changed.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, Any, Literal

import torch
import torch.nn.functional as F
from annotated_types import Interval, MinLen
from torch import nn

from pioneer.bounds import Count, NonNegative, UnitInterval
from pioneer.config import Config, default
from pioneer.deploy.inputs import StudentInputs
from pioneer.deploy.mixture import (
    ACTION_MODES,
    MIRROR_ACTION,
    ActionMode,
    mixture_action,
    mixture_uncertainty,
)
from pioneer.errors import ConfigError, expect
from pioneer.nn.checkpoint import load_checked, read_checkpoint, stored_config, write_checkpoint
from pioneer.nn.layers import seeded_linear
from pioneer.sim.lidar import OBS_DIM

__all__ = [
    "ACTION_DIM",
    "CHECKPOINT_FORMAT",
    "MDN",
    "MLPStudent",
    "Student",
    "StudentConfig",
    "build_student",
    "load_student",
    "mixture_action",
    "mixture_uncertainty",
    "read_checkpoint_meta",
    "save_student",
    "select_action",
    "symmetrise_mixture",
    "uncertainty",
]

ACTION_DIM = 2  # (v [m/s], ω [rad/s])
CHECKPOINT_FORMAT = "pioneer.student/1"
StudentKind = Literal["mdn", "mlp"]
KINDS: tuple[str, ...] = typing.get_args(StudentKind)


@dataclasses.dataclass(frozen=True)
class StudentConfig(Config):
    """Architecture of a student network (defaults = paper §V-B.2)."""

    kind: StudentKind = "mdn"  # "mdn" (mixture density network) or "mlp" (regression baseline)
    obs_dim: Count = OBS_DIM  # input features (29-D observation, paper §III-A)
    hidden: Annotated[tuple[Count, ...], MinLen(1)] = (128, 128)  # trunk widths, ReLU after each
    dropout: Annotated[float, Interval(ge=0, lt=1)] = 0.1  # after each hidden ReLU (training only)
    n_components: Count = 10  # K, mixture components (MDN only)
    sigma_floor: NonNegative = 1e-3  # [m/s | rad/s] added to every component std (MDN only)
    # the MDN's deterministic action: the mean of its most probable component ("mode") or the
    # mixture mean ("mean"); see the module docstring
    action_mode: ActionMode = "mode"
    nll_beta: UnitInterval = 0.0  # β of the β-NLL training loss (MDN only; 0 = plain NLL)
    # Beyond the paper (pioneer.deploy.runtime.StudentInputs): what the student reads
    # besides o_t.
    previous_observation: bool = False  # also the previous step's observation o_{t−1}
    previous_command: bool = False  # also u_{t−1}, the command sent at the previous step
    # Beyond the paper: mirror-equivariant by construction — the policy of the inputs x is
    # ½ p(u | x) + ½ p(m(u) | M x) (MDN; the MLP averages f(x) and m(f(M x))), M the world
    # mirrored x → −x and m(v, ω) = (v, −ω), so its command for a mirrored observation is the
    # mirrored command (docs/general-student.md, "Symmetry built in")
    symmetric: bool = False
    # how a symmetric MDN trains: each half's own likelihood on the frame and on its mirror
    # image ("each_half": both halves fit both sides), or the symmetric mixture's ("mixture":
    # one half may explain a frame alone, and the other's mode then misleads; docs/student.md)
    symmetric_loss: Literal["each_half", "mixture"] = "each_half"

    @property
    def inputs(self) -> StudentInputs:
        """What the student reads besides o_t."""
        return StudentInputs(self.previous_observation, self.previous_command)

    @property
    def input_dim(self) -> int:
        """The network's input width: the observation, o_{t−1} and u_{t−1} if it reads them."""
        return self.inputs.width(self.obs_dim)


# The StudentConfig fields only an MDN uses (an MLP ignores them).
MDN_ONLY: tuple[str, ...] = ("n_components", "sigma_floor", "action_mode", "nll_beta")


# ---------------------------------------------------------------------------------- read-outs
def uncertainty(
    logits: torch.Tensor, mu: torch.Tensor, sigma: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """``(aleatoric, epistemic)``, each ``(N,)``, of a diagonal Gaussian mixture.

    ``logits`` (N, K), ``mu`` and ``sigma`` (N, K, 2). Law of total variance summed over the
    action dimensions: aleatoric = Σ_k π_k Σ_d σ_kd², epistemic = Σ_k π_k ‖μ_k − Σ_j π_j μ_j‖²;
    their sum is the trace of the mixture's covariance. Numpy twin:
    :func:`pioneer.deploy.mixture.mixture_uncertainty`.
    """
    pi = torch.softmax(logits, dim=-1)
    aleatoric = (pi * (sigma * sigma).sum(dim=-1)).sum(dim=-1)
    mbar = (pi.unsqueeze(-1) * mu).sum(dim=-2)
    epistemic = (pi * ((mu - mbar.unsqueeze(-2)) ** 2).sum(dim=-1)).sum(dim=-1)
    return aleatoric, epistemic


def select_action(logits: torch.Tensor, mu: torch.Tensor, mode: str = "mode") -> torch.Tensor:
    """Deterministic action ``(N, 2)``: mean of the most probable component (``"mode"``) or the
    mixture mean (``"mean"``). Written with ``gather`` so it exports to ONNX."""
    if mode == "mode":
        k = logits.argmax(dim=-1)  # (N,)
        idx = k.view(-1, 1, 1).expand(-1, 1, ACTION_DIM)
        return mu.gather(1, idx).squeeze(1)
    if mode == "mean":
        return (torch.softmax(logits, dim=-1).unsqueeze(-1) * mu).sum(dim=-2)
    fix = f"use {default(select_action, 'mode')!r}"
    raise ConfigError(expect("action_mode", f"one of {ACTION_MODES}", mode, fix))


def symmetrise_mixture(
    own: tuple[torch.Tensor, torch.Tensor, torch.Tensor],
    mirrored: tuple[torch.Tensor, torch.Tensor, torch.Tensor],
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The mirror-equivariant mixture ½ p(u | x) + ½ p(m(u) | M x) from the network's mixture
    of the inputs (``own``) and of their mirror image (``mirrored``): ``(logits (N, 2K),
    mu (N, 2K, 2), sigma (N, 2K, 2))``. NumPy twin (the formula's statement):
    :func:`pioneer.deploy.mixture.symmetric_mixture`."""
    (lo, mo, so), (lm, mm, sm) = own, mirrored
    flip = torch.as_tensor(MIRROR_ACTION)
    logits = torch.cat([torch.log_softmax(lo, dim=-1), torch.log_softmax(lm, dim=-1)], dim=-1)
    return logits, torch.cat([mo, mm * flip], dim=-2), torch.cat([so, sm], dim=-2)


# ---------------------------------------------------------------------------------- networks
class Student(nn.Module):
    """Common base: the ReLU/dropout trunk and the normalisation buffers.

    Buffers (saved with the weights): ``obs_mean``/``obs_std`` (input_dim,) standardise inputs;
    ``act_mean``/``act_std`` (2,) map the heads' standardised outputs to physical units.
    """

    config: StudentConfig
    obs_mean: torch.Tensor
    obs_std: torch.Tensor
    act_mean: torch.Tensor
    act_std: torch.Tensor
    mirror_index: torch.Tensor  # (input_dim,) with config.symmetric: the mirror's gather …
    mirror_sign: torch.Tensor  # (input_dim,) … and sign (StudentInputs.mirror_map)

    def __init__(self, config: StudentConfig, gen: torch.Generator) -> None:
        super().__init__()
        self.config = config
        layers: list[nn.Module] = []
        n_in = config.input_dim
        for width in config.hidden:
            layers += [seeded_linear(n_in, width, gen), nn.ReLU(), nn.Dropout(config.dropout)]
            n_in = width
        self.trunk = nn.Sequential(*layers)
        self.register_buffer("obs_mean", torch.zeros(config.input_dim))
        self.register_buffer("obs_std", torch.ones(config.input_dim))
        self.register_buffer("act_mean", torch.zeros(ACTION_DIM))
        self.register_buffer("act_std", torch.ones(ACTION_DIM))
        if config.symmetric:  # the inputs' mirror image; not saved: the config rebuilds it
            index, sign = config.inputs.mirror_map(config.obs_dim)
            self.register_buffer("mirror_index", torch.as_tensor(index), persistent=False)
            self.register_buffer("mirror_sign", torch.as_tensor(sign), persistent=False)
        self.eval()

    def mirror(self, obs: torch.Tensor) -> torch.Tensor:
        """The mirror image of raw inputs ``(N, input_dim)`` (the world mirrored x → −x;
        :func:`pioneer.laser.apply_mirror`, here in torch so that it exports to ONNX)."""
        out = obs.index_select(1, self.mirror_index) * self.mirror_sign
        return torch.where(out <= -math.pi, -out, out)

    @property
    def kind(self) -> str:
        """``"mdn"`` or ``"mlp"``."""
        return self.config.kind

    def set_normalizer(self, obs: torch.Tensor, actions: torch.Tensor) -> None:
        """Fit the standardisation buffers to ``obs`` (N, input_dim) and ``actions`` (N, 2);
        near-constant features (std < 1e-6) keep scale 1."""
        with torch.no_grad():
            for x, mean, std in (
                (obs, self.obs_mean, self.obs_std),
                (actions, self.act_mean, self.act_std),
            ):
                s = x.std(dim=0, unbiased=False) if x.shape[0] > 1 else torch.ones_like(std)
                mean.copy_(x.mean(dim=0))
                std.copy_(torch.where(s < 1e-6, torch.ones_like(s), s))

    def features(self, obs: torch.Tensor) -> torch.Tensor:
        """Trunk output ``(N, hidden[-1])`` of standardised inputs ``(N, input_dim)``."""
        out: torch.Tensor = self.trunk((obs - self.obs_mean) / self.obs_std)
        return out

    def loss(self, obs: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """Mean training loss over the batch (scalar)."""
        raise NotImplementedError

    def target_loss(
        self, obs: torch.Tensor, commands: torch.Tensor, weights: torch.Tensor
    ) -> torch.Tensor:
        """Mean training loss against weighted targets — ``commands (N, k, 2)`` with
        ``weights (N, k)`` summing to 1 per frame (the teacher's scores distilled: DAgger's
        ``target="scores"``); one target of weight 1 is :meth:`loss`."""
        raise NotImplementedError

    def deterministic_action(self, obs: torch.Tensor, mode: str | None = None) -> torch.Tensor:
        """The command ``(N, 2)`` (v [m/s], ω [rad/s]) the policy executes."""
        raise NotImplementedError


class MDN(Student):
    """Mixture density network: ``forward(obs) -> (logits, mu, sigma)``.

    Shapes: ``obs`` (N, input_dim) float32; ``logits`` (N, K) unnormalised mixture log-weights;
    ``mu`` (N, K, 2) component means and ``sigma`` (N, K, 2) component standard deviations,
    both in physical units (v [m/s], ω [rad/s]).
    """

    def __init__(self, config: StudentConfig | None = None, seed: int = 0) -> None:
        cfg = config or StudentConfig(kind="mdn")
        if cfg.kind != "mdn":
            raise ConfigError(expect("MDN config.kind", "'mdn'", cfg.kind, "use MLPStudent"))
        gen = torch.Generator().manual_seed(int(seed))
        super().__init__(cfg, gen)
        k, h = cfg.n_components, cfg.hidden[-1]
        self.logits_head = seeded_linear(h, k, gen)
        self.mu_head = seeded_linear(h, k * ACTION_DIM, gen)
        self.sigma_head = seeded_linear(h, k * ACTION_DIM, gen)

    def forward(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        if self.config.symmetric:
            return symmetrise_mixture(self._mixture(obs), self._mixture(self.mirror(obs)))
        return self._mixture(obs)

    def _mixture(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        h = self.features(obs)
        shape = (-1, self.config.n_components, ACTION_DIM)
        logits = self.logits_head(h)
        mu = self.mu_head(h).view(shape) * self.act_std + self.act_mean
        sigma = F.softplus(self.sigma_head(h)).view(shape) * self.act_std
        return logits, mu, sigma + self.config.sigma_floor

    def log_prob(self, obs: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """log p(action | obs) ``(N,)`` under the mixture, via logsumexp (stable)."""
        logits, mu, sigma = self(obs)
        return _mixture_log_prob(logits, mu, sigma, actions.unsqueeze(1))[:, 0]

    def target_loss(
        self, obs: torch.Tensor, commands: torch.Tensor, weights: torch.Tensor
    ) -> torch.Tensor:
        """−(1/N) Σ_i Σ_j w_ij log p(u_ij | o_i): the cross-entropy of the mixture against the
        targets' weights (the KL divergence to them up to a constant), so the network learns
        which commands the teacher rates nearly as good, not only its single choice."""
        logits, mu, sigma = self(obs)
        logp = _mixture_log_prob(logits, mu, sigma, commands)  # (N, k)
        return -(weights * logp).sum(dim=-1).mean()

    def nll(self, obs: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """Mean negative log-likelihood [nats per sample] of ``actions`` (N, 2) given ``obs``."""
        return -self.log_prob(obs, actions).mean()

    def loss(self, obs: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """The training loss: :meth:`nll`, or with ``nll_beta`` = β > 0 the β-NLL."""
        beta = float(self.config.nll_beta)
        if self.config.symmetric and self.config.symmetric_loss == "each_half":
            flip = torch.as_tensor(MIRROR_ACTION)
            own = _mixture_log_prob(*self._mixture(obs), actions.unsqueeze(1))
            other = _mixture_log_prob(*self._mixture(self.mirror(obs)), (actions * flip)[:, None])
            return -0.5 * (own + other).mean()
        if beta == 0.0:
            return self.nll(obs, actions)
        logits, mu, sigma = self(obs)
        logp = _mixture_log_prob(logits, mu, sigma, actions.unsqueeze(1))[:, 0]
        with torch.no_grad():
            ale, epi = uncertainty(logits, mu / self.act_std, sigma / self.act_std)
            w = (ale + epi) ** beta
            w = w / w.mean()
        return -(w * logp).mean()

    def deterministic_action(self, obs: torch.Tensor, mode: str | None = None) -> torch.Tensor:
        """Mean of the most probable component (default) or the mixture mean, ``(N, 2)``."""
        logits, mu, _ = self(obs)
        return select_action(logits, mu, mode or self.config.action_mode)

    def uncertainty(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``(aleatoric, epistemic)`` per observation, each ``(N,)`` (see :func:`uncertainty`)."""
        return uncertainty(*self(obs))


class MLPStudent(Student):
    """Regression baseline: ``forward(obs) -> action`` ``(N, 2)`` in physical units."""

    def __init__(self, config: StudentConfig | None = None, seed: int = 0) -> None:
        cfg = config or StudentConfig(kind="mlp")
        if cfg.kind != "mlp":
            raise ConfigError(expect("MLPStudent config.kind", "'mlp'", cfg.kind, "use MDN"))
        gen = torch.Generator().manual_seed(int(seed))
        super().__init__(cfg, gen)
        self.head = seeded_linear(cfg.hidden[-1], ACTION_DIM, gen)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        out = self._regress(obs)
        if self.config.symmetric:
            out = 0.5 * (out + self._regress(self.mirror(obs)) * torch.as_tensor(MIRROR_ACTION))
        return out

    def _regress(self, obs: torch.Tensor) -> torch.Tensor:
        out: torch.Tensor = self.head(self.features(obs)) * self.act_std + self.act_mean
        return out

    def loss(self, obs: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """Mean squared error on standardised actions (v and ω weigh equally)."""
        err = (self(obs) - actions) / self.act_std
        return (err * err).mean()

    def target_loss(
        self, obs: torch.Tensor, commands: torch.Tensor, weights: torch.Tensor
    ) -> torch.Tensor:
        """The squared error to every target, weighted (its minimum: the weighted mean)."""
        err = (self(obs).unsqueeze(1) - commands) / self.act_std  # (N, k, 2)
        return (weights * (err * err).mean(dim=-1)).sum(dim=-1).mean()

    def deterministic_action(self, obs: torch.Tensor, mode: str | None = None) -> torch.Tensor:
        """The regressed command ``(N, 2)`` (``mode`` is ignored)."""
        out: torch.Tensor = self(obs)
        return out


_HALF_LOG_2PI = 0.5 * math.log(2.0 * math.pi)


def _mixture_log_prob(
    logits: torch.Tensor, mu: torch.Tensor, sigma: torch.Tensor, actions: torch.Tensor
) -> torch.Tensor:
    """log p(a | o) ``(N, k)`` of ``actions (N, k, 2)`` under each frame's mixture
    (``logits (N, K)``, ``mu``/``sigma (N, K, 2)``), via logsumexp (stable)."""
    mu, sigma = mu.unsqueeze(1), sigma.unsqueeze(1)  # (N, 1, K, 2)
    z = (actions.unsqueeze(2) - mu) / sigma  # (N, k, K, 2)
    comp = -0.5 * (z * z).sum(-1) - torch.log(sigma).sum(-1) - ACTION_DIM * _HALF_LOG_2PI
    return torch.logsumexp(torch.log_softmax(logits, dim=-1).unsqueeze(1) + comp, dim=-1)


def build_student(config: StudentConfig | None = None, seed: int = 0) -> MDN | MLPStudent:
    """A freshly initialised student of ``config.kind`` (default: the paper's MDN, §V-B.2)."""
    cfg = config or StudentConfig()
    return MDN(cfg, seed) if cfg.kind == "mdn" else MLPStudent(cfg, seed)


# ---------------------------------------------------------------------------------- checkpoints
def save_student(model: Student, path: str | Path, info: Mapping[str, Any] | None = None) -> Path:
    """Write ``model`` to a ``.safetensors`` file (atomically) and return the path.

    Weights and normalisation buffers are the tensors; the metadata holds the format tag, the
    :class:`StudentConfig` as JSON and optional free-form ``info`` (JSON-able: data source,
    epochs, final loss …). No pickle: loading cannot execute code.
    """
    return write_checkpoint(model, model.config.to_dict(), path, CHECKPOINT_FORMAT, info)


def read_checkpoint_meta(path: str | Path) -> dict[str, Any]:
    """The metadata of a student checkpoint: ``format``, ``config`` (dict), ``info`` (dict)."""
    meta, _ = _read_checkpoint(Path(path), tensors=False)
    return meta


def _read_checkpoint(p: Path, tensors: bool) -> tuple[dict[str, Any], dict[str, torch.Tensor]]:
    fix = "re-save it with save_student (the file is truncated, corrupt or not a checkpoint)"
    return read_checkpoint(
        p, CHECKPOINT_FORMAT, "student checkpoint", fix, "check the path", tensors
    )


def load_student(path: str | Path) -> MDN | MLPStudent:
    """Rebuild the student saved at ``path`` (right class and config), in eval mode.

    Raises :class:`DataError` for a missing, corrupt or mismatched file (unknown format, bad
    config, missing/unexpected tensors, wrong shapes, non-finite weights).
    """
    p = Path(path)
    meta, arrays = _read_checkpoint(p, tensors=True)
    cfg = stored_config(p, meta, StudentConfig, "re-save the checkpoint")
    return load_checked(
        build_student(cfg), arrays, p, f"{cfg.kind} {cfg.to_dict()}", "re-train or re-save it"
    )
