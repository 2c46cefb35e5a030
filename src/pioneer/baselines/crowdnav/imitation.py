"""Imitation warm start of CrowdNav++: teacher demonstrations, behaviour cloning, DAgger.

The CrowdNav family pretrains its RL policies by imitation before RL (Chen et al. 2019,
CADRL/SARL: value networks initialised by imitation learning on demonstrations). Our PPO-only
CrowdNav++ runs settle in a local optimum — drive toward the door and wait (the compact world
at 2.5 M steps; the paper world even with the original's 20 M steps: docs/baselines.md) — so
``pioneer train crowdnav++ --bc-episodes N`` first imitates the
privileged lookahead teacher (:func:`pioneer.control.teacher.make_teacher`) and then
fine-tunes with PPO (:mod:`~pioneer.baselines.crowdnav.ppo`). This is a deviation from
CrowdNav++, which trains by RL alone; docs/baselines.md reports both.

Demonstrations in the policy's action space
    The teacher drives the scenario *through the policy's action space*: at every step its
    command u* = ``teacher.decide(world, state, prev=state.command[0]).command`` is mapped to
    the raw action a (:func:`~.collect.action_from_command`, the inverse of
    :func:`~.observation.command_from_action`): Δv = v* − v_{t−1} and Δθ = ω* Δt,
    clipped to the increment bounds and scaled onto [−1, 1]², and the command that a produces
    is the one applied. A policy that replays the recorded actions from the episode's initial
    state therefore reproduces the demonstration exactly; the clipping changes the teacher's
    command in ≈ 4 % of the steps (v when it accelerates from rest faster than 0.087 m/s per
    step; its ω stays within ±0.6 rad/s), and the teacher still succeeds in 100/100 episodes
    of each elevator scenario through it. Its unclipped command is recorded as
    ``teacher_command`` beside the applied ``command``.

Behaviour cloning (:func:`train_bc`)
    Whole episodes through the recurrent network (GRU from zero at each episode start, as in
    evaluation), loss ‖μ(o_t) − a_t‖² averaged over the valid steps of minibatches of episodes
    (Adam). Only the encoder, GRU and actor learn; afterwards log σ is set to the maximum-
    likelihood value, the per-dimension RMS residual, floored at ``min_std`` (PPO needs some
    exploration) and capped at the initial σ. Every model is trained from the same seeded
    initialisation as the PPO trainer's, so the result is a function of the data and the seed.

DAgger (Ross et al. 2011), ``dagger_rounds`` > 0
    Round r lets the policy cloned from rounds < r drive (mean action) for ``dagger_episodes``
    episodes, labels every visited state with the teacher's action and aggregates. The rounds,
    their files and the resume are :mod:`pioneer.imitation` (shared with the students'
    DAgger): every round's clone is a fresh model fitted on the aggregate of rounds 0..r.

Critic warm-up (in :mod:`pioneer.baselines.crowdnav.ppo`)
    ``critic_warmup`` PPO updates train only the critic head (its own Adam, ``critic_lr``) on
    the cloned policy's returns, with the shared encoder, GRU and actor frozen, so that PPO's
    first policy updates use sensible advantages instead of a random critic's.

Files (in the training ``out``; written atomically, no pickle)::

    ``imitation/config.json``   the phase's settings; a rerun with others is refused;
    ``imitation/rounds/round-RR/ep-EEE.npz``  one labelled episode (:mod:`.bc_data`); a rerun
                                collects only the missing ones;
    ``imitation/rounds/round-RR/policy.safetensors``  the clone fitted on rounds 0..RR (the
                                next round's driver);
    ``bc_policy.safetensors``   the cloned policy (the last round's clone,
                                :func:`~.network.load_crowdnav`); when present the imitation
                                phase is not redone.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import math
import time
import typing
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, Literal

import numpy as np
import torch

from pioneer.baselines.crowdnav.bc_data import BCData
from pioneer.baselines.crowdnav.collect import CollectTask, clear_cache, collect_task, episode_seeds
from pioneer.baselines.crowdnav.network import (
    CrowdNavConfig,
    CrowdNavNet,
    load_crowdnav,
    read_crowdnav_meta,
    save_crowdnav,
)
from pioneer.bounds import Count, NonNegativeInt, Positive
from pioneer.config import Config
from pioneer.errors import ConfigError, expect
from pioneer.imitation.rounds import Collector, Fitted, Step, one_thread, run_rounds
from pioneer.imitation.store import RunFolder, check_settings
from pioneer.interrupt import kept
from pioneer.io import to_json
from pioneer.nn.recurrent import gru_sequence
from pioneer.sim.scenarios import ScenarioConfig

__all__ = [
    "BCData",
    "WarmStartConfig",
    "bc_loss",
    "train_bc",
    "warm_start",
]

DATA_DIR = "imitation"
ROUND_POLICY_FILE = "policy.safetensors"
POLICY_FILE = "bc_policy.safetensors"
# The demonstrators: "sfm", "dwa" (both independent of PioneeR) or PioneeR's "teacher".
Expert = Literal["sfm", "dwa", "teacher"]
EXPERTS: tuple[str, ...] = typing.get_args(Expert)


@dataclasses.dataclass(frozen=True)
class WarmStartConfig(Config):
    """Imitation warm start and critic warm-up (all off by default: pure PPO)."""

    expert: Expert = "sfm"  # the demonstrator: sfm, dwa (independent of PioneeR) or teacher
    bc_episodes: NonNegativeInt = 0  # expert-driven demonstration episodes (0: no imitation)
    bc_epochs: Count = 30  # passes over the dataset per cloning
    bc_batch: Count = 16  # episodes per minibatch
    bc_lr: Positive = 1e-3  # Adam learning rate of the cloning
    dagger_rounds: NonNegativeInt = 0  # rounds of policy-driven, teacher-labelled episodes
    dagger_episodes: Count = 20  # episodes per DAgger round
    min_std: Positive = 0.1  # floor of σ (unit action box) after cloning
    # σ (unit action box) PPO starts from; None: the clone's (its RMS residual, floored)
    ppo_std: Positive | None = None
    critic_warmup: NonNegativeInt = 0  # [updates] PPO updates training only the critic head
    critic_lr: Positive = 1e-3  # Adam learning rate of the critic warm-up

    def __post_init__(self) -> None:
        if self.dagger_rounds and not self.bc_episodes:
            raise ConfigError(
                expect(
                    "--dagger-rounds",
                    "0 without teacher demonstrations",
                    self.dagger_rounds,
                    "add --bc-episodes N",
                )
            )

    @property
    def active(self) -> bool:
        """Whether anything differs from pure PPO."""
        return self.bc_episodes > 0 or self.critic_warmup > 0


# ------------------------------------------------------------------------------ cloning
def _padded(data: BCData) -> dict[str, torch.Tensor]:
    """Steps as (T_max, E, …) tensors, padded with zeros, and ``valid`` (T_max, E)."""
    e = data.n_episodes
    counts = np.bincount(data.episode, minlength=e)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    t_idx = np.arange(data.episode.size) - starts[data.episode]
    t_max = int(counts.max())
    out: dict[str, torch.Tensor] = {}
    for k in ("robot", "temporal", "spatial", "mask", "action"):
        x = getattr(data, k)
        arr = np.zeros((t_max, e, *x.shape[1:]), dtype=x.dtype)
        arr[t_idx, data.episode] = x
        out[k] = torch.from_numpy(arr)
    valid = np.zeros((t_max, e), dtype=np.float32)
    valid[t_idx, data.episode] = 1.0
    out["valid"] = torch.from_numpy(valid)
    return out


def _actor_means(model: CrowdNavNet, b: dict[str, torch.Tensor]) -> torch.Tensor:
    x, _, _ = model.encode(b["robot"], b["temporal"], b["spatial"], b["mask"])
    keep = torch.ones(x.shape[:2])  # each column is one episode from its start
    hs = gru_sequence(model.gru, x, model.initial_state(x.shape[1]), keep)
    return model.mean_head(model.actor(hs))


def train_bc(
    data: BCData,
    net_cfg: CrowdNavConfig,
    config: WarmStartConfig,
    seed: int,
    on_epoch: Callable[[int, float], None] | None = None,
) -> tuple[CrowdNavNet, list[float]]:
    """Clone the teacher: a fresh model (``seed``) fitted to ``data``; returns it (eval mode)
    and the mean loss ‖μ − a‖² of every epoch (the module docstring has the details)."""
    model = CrowdNavNet(net_cfg, seed=seed)
    gen = torch.Generator().manual_seed(int(seed) + 0xBC)
    params = [
        *model.robot_embed.parameters(),
        *model.spatial_embed.parameters(),
        *model.hh_qkv.parameters(),
        *model.rh_q.parameters(),
        *model.rh_k.parameters(),
        *model.merge.parameters(),
        *model.gru.parameters(),
        *model.actor.parameters(),
        *model.mean_head.parameters(),
    ]
    opt = torch.optim.Adam(params, lr=config.bc_lr)
    full = _padded(data)
    e = data.n_episodes
    n_batches = max(1, math.ceil(e / config.bc_batch))
    losses: list[float] = []
    model.train()
    for epoch in range(config.bc_epochs):
        perm = torch.randperm(e, generator=gen)
        total, weight = 0.0, 0.0
        for idx in torch.tensor_split(perm, n_batches):
            b = {k: v[:, idx] for k, v in full.items()}
            valid = b["valid"]
            mean = _actor_means(model, b)
            err = ((mean - b["action"]) ** 2).sum(-1)
            loss = (err * valid).sum() / valid.sum()
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            total += float(loss.detach()) * float(valid.sum())
            weight += float(valid.sum())
        losses.append(total / weight)
        if on_epoch is not None:
            on_epoch(epoch, losses[-1])
    model.eval()
    with torch.no_grad():
        mean = _actor_means(model, full)
        valid = full["valid"].bool()
        resid = (mean - full["action"])[valid]  # (S, 2)
        std = resid.pow(2).mean(0).sqrt()
        cap = math.exp(net_cfg.log_std_init)
        model.log_std.copy_(torch.log(std.clamp(config.min_std, max(cap, config.min_std))))
    return model, losses


def bc_loss(model: CrowdNavNet, data: BCData) -> float:
    """Mean ‖μ − a‖² of ``model`` over the steps of ``data``."""
    full = _padded(data)
    with torch.no_grad():
        mean = _actor_means(model, full)
        err = ((mean - full["action"]) ** 2).sum(-1)
        return float((err * full["valid"]).sum() / full["valid"].sum())


# ------------------------------------------------------------------------------ the phase
@dataclasses.dataclass(frozen=True)
class _Cloning:
    """The warm start's DAgger parts (:class:`pioneer.imitation.rounds.Method`): episodes
    labelled by the expert (:func:`~.collect.collect_task`), each round's clone a fresh model
    fitted on the aggregate (:func:`train_bc`)."""

    scenario: ScenarioConfig
    net_cfg: CrowdNavConfig
    config: WarmStartConfig
    seed: int

    def sizes(self) -> list[int]:
        """Episodes of each round."""
        cfg = self.config
        return [cfg.bc_episodes] + [cfg.dagger_episodes] * cfg.dagger_rounds

    def task(self, rnd: int, index: int, path: Path, driver: Path | None) -> CollectTask:
        seed = episode_seeds(self.seed, rnd, self.sizes()[rnd])[index]
        clone = None if driver is None else str(driver)
        return (self.scenario, self.config.expert, self.net_cfg, rnd, seed, clone, str(path))

    def aggregate(self, episodes: Sequence[Mapping[str, Any]]) -> BCData:
        return BCData.from_episodes(episodes)

    def loss(self, model: CrowdNavNet, data: BCData) -> float:
        return bc_loss(model, data)

    def fit(self, step: Step[BCData, CrowdNavNet]) -> tuple[CrowdNavNet, dict[str, Any]]:
        model, losses = train_bc(step.data, self.net_cfg, self.config, self.seed)
        info = {
            "round": step.round,
            "data": step.data.summary(),
            "bc_loss": [round(x, 6) for x in losses],
            "log_std": [float(x) for x in model.log_std.detach()],
            "driver_loss_on_round": step.loss_new,
        }
        return model, info

    def save(self, model: CrowdNavNet, path: Path, info: dict[str, Any]) -> None:
        save_crowdnav(model, path, info)

    def load(self, path: Path) -> tuple[CrowdNavNet, dict[str, Any]]:
        return load_crowdnav(path), dict(read_crowdnav_meta(path)["info"])


def warm_start(
    scenario: ScenarioConfig,
    net_cfg: CrowdNavConfig,
    config: WarmStartConfig,
    seed: int,
    out: Path,
    progress: bool = True,
    log: Callable[[str], None] | None = None,
    workers: int = 1,
) -> tuple[CrowdNavNet, dict[str, Any]]:
    """The imitation phase, resumable: the cloned model and its summary (``out`` files in the
    module docstring). A complete ``bc_policy.safetensors`` of the same settings is reused.
    ``workers`` > 1 collects the episodes in that many spawned processes."""
    if log is None:
        log = functools.partial(print, flush=True)
    settings = {
        "scenario": scenario.name,
        "seed": seed,
        "net": net_cfg.to_dict(),
        "bc_episodes": config.bc_episodes,
        "dagger_episodes": config.dagger_episodes,
        "expert": config.expert,
        "bc_epochs": config.bc_epochs,
        "bc_batch": config.bc_batch,
        "bc_lr": config.bc_lr,
        "min_std": config.min_std,
        "dagger_rounds": config.dagger_rounds,
    }
    pol = out / POLICY_FILE
    if pol.is_file():
        info = read_crowdnav_meta(pol)["info"]
        stored = info.get("settings")
        check_settings(str(pol), stored if isinstance(stored, dict) else {}, settings, "imitation")
        return load_crowdnav(pol), info
    t0 = time.perf_counter()
    folder = RunFolder(
        out / DATA_DIR, ROUND_POLICY_FILE, "CrowdNav++ imitation", free=("dagger_rounds",)
    )
    method = _Cloning(scenario, net_cfg, config, seed)
    sizes = method.sizes()
    folder.check(settings)
    folder.check_episodes(sizes)  # a corrupt episode is refused before any new one
    folder.prepare(settings)

    def start(rnd: int, todo: int) -> None:
        if progress and todo:
            driver = "teacher" if rnd == 0 else "DAgger"
            log(f"imitation: round {rnd}, {todo} of {sizes[rnd]} episodes to collect ({driver})")

    clear_cache()  # a new run in this process
    collector = Collector(collect_task, one_thread if workers > 1 else None, workers)
    rounds = run_rounds(folder, sizes, method, collector, start)
    last: Fitted[BCData, CrowdNavNet] | None = None
    with kept(lambda: folder.kept(sizes)), contextlib.closing(rounds):
        for last in rounds:
            if progress and last.fitted:
                first, final = last.info["bc_loss"][0], last.info["bc_loss"][-1]
                log(
                    f"imitation: round {last.step.round} cloned, loss {first:.4f} -> "
                    f"{final:.4f}; data {to_json(last.step.data.summary())}"
                )
        assert last is not None  # round 0 at least
        info = {
            "scenario": scenario.name,
            "phase": "imitation",
            "settings": settings,
            "data": last.step.data.summary(),
            "bc_loss": last.info["bc_loss"],
            "log_std": [float(x) for x in last.model.log_std.detach()],
            "wall_time_s_this_run": round(time.perf_counter() - t0, 1),
        }
        save_crowdnav(last.model, pol, info)
    return last.model, info
