"""The PPO trainer of CrowdNav++: settings, GAE, rollouts on the batched simulator, updates
and the whole training state (recipe and formulas in :mod:`pioneer.baselines.crowdnav.ppo`)."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray

from pioneer.baselines.crowdnav.imitation import WarmStartConfig
from pioneer.baselines.crowdnav.inference import CrowdNavInference
from pioneer.baselines.crowdnav.network import CrowdNavConfig, CrowdNavNet
from pioneer.baselines.crowdnav.observation import (
    build_observation,
    command_from_action,
)
from pioneer.bounds import Count, NonNegative, NonNegativeInt, Positive, UnitInterval
from pioneer.config import Config
from pioneer.errors import ConfigError, expect
from pioneer.nn.checkpoint import read_training_state, restore_optimizer, write_training_state
from pioneer.nn.ppo import (
    clipped_surrogate,
    compute_gae,
    progress_state,
    restore_progress,
    window_row,
)
from pioneer.nn.recurrent import gru_sequence
from pioneer.reward.crowdnav import CrowdNavRewardConfig, crowdnav_reward
from pioneer.sim.events import Event, classify
from pioneer.sim.scenarios import ScenarioConfig, sample_state
from pioneer.sim.world import State, step

__all__ = ["CURVE_COLUMNS", "PPOConfig", "compute_gae"]

TRAIN_FORMAT = "pioneer.crowdnav-train/1"
CURVE_COLUMNS = (
    "update",
    "env_steps",
    "episodes",
    "mean_return",
    "success_rate",
    "collision_rate",
    "timeout_rate",
    "wall_time_s",
)
F64 = NDArray[np.float64]


@dataclasses.dataclass(frozen=True)
class PPOConfig(Config):
    """PPO settings (the original's, except ``lr``; see the module docstring)."""

    total_steps: Count = 2_000_000  # env steps (all environments together)
    n_envs: Count = 16  # environments stepped together
    rollout: Count = 30  # steps per environment per update
    lr: Positive = 3e-4  # Adam learning rate (original: 4e-5 for 20 M steps)
    gamma: UnitInterval = 0.996  # discount per 0.1 s step (the original's 0.99 per 0.25 s step)
    gae_lambda: UnitInterval = 0.98  # GAE λ per 0.1 s step (the original's 0.95 per 0.25 s)
    clip: Positive = 0.2  # PPO ratio clip
    epochs: Count = 5  # passes over each rollout
    minibatches: Count = 2  # per epoch (split over environments)
    value_coef: NonNegative = 0.5  # value-loss weight
    entropy_coef: NonNegative = 0.01  # entropy bonus (original: 0; see baselines.crowdnav.ppo)
    max_grad_norm: Positive = 0.5  # gradient clipping (global L2 norm)
    adam_eps: Positive = 1e-5  # Adam ε
    seed: NonNegativeInt = 0  # seeds the weights, the action noise, the minibatches, the episodes
    checkpoint_every: Count = 50  # [updates] between checkpoints
    window: Count = 100  # finished episodes in the learning curve's running statistics

    def __post_init__(self) -> None:
        if self.minibatches > self.n_envs:
            raise ConfigError(
                expect(
                    "PPOConfig.minibatches",
                    f"<= n_envs ({self.n_envs})",
                    self.minibatches,
                    "use more environments or fewer minibatches",
                )
            )

    @property
    def steps_per_update(self) -> int:
        """Env steps per update: n_envs × rollout."""
        return self.n_envs * self.rollout

    @property
    def updates(self) -> int:
        """Updates needed for ``total_steps`` (rounded up)."""
        return -(-self.total_steps // self.steps_per_update)


# ------------------------------------------------------------------------------ state helpers


def _flat(d: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in d.items():
        if isinstance(v, Mapping):
            out.update(_flat(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


def _normal(mean: torch.Tensor, std: torch.Tensor) -> torch.distributions.Normal:
    """The policy's Gaussian without argument validation (its checks cost more than its
    log-probabilities at this size; the values are the same)."""
    return torch.distributions.Normal(mean, std, validate_args=False)


# ------------------------------------------------------------------------------ the trainer
class _Trainer:
    """Everything that changes during training (saved whole in the checkpoint)."""

    def __init__(
        self,
        scenario: ScenarioConfig,
        ppo: PPOConfig,
        net: CrowdNavConfig,
        reward: CrowdNavRewardConfig,
        warm: WarmStartConfig | None = None,
    ) -> None:
        self.scenario, self.ppo, self.net_cfg, self.reward_cfg = scenario, ppo, net, reward
        self.warm = warm or WarmStartConfig()
        self.world = scenario.world()
        self.model = CrowdNavNet(net, seed=ppo.seed)
        # fused: one kernel for every parameter's update instead of a loop of small operators
        self.opt = torch.optim.Adam(
            self.model.parameters(), lr=ppo.lr, eps=ppo.adam_eps, fused=True
        )
        # The critic warm-up trains the critic head alone, with its own optimiser.
        self.critic_params = [*self.model.critic.parameters(), *self.model.value_head.parameters()]
        self.critic_opt = torch.optim.Adam(
            self.critic_params, lr=self.warm.critic_lr, eps=ppo.adam_eps, fused=True
        )
        self.rng = np.random.default_rng(np.random.SeedSequence([ppo.seed, 0x0C20D]))
        self.gen = torch.Generator().manual_seed(ppo.seed + 1)
        b = ppo.n_envs
        self.state = State.concat([self._sample() for _ in range(b)])
        self.h = self.model.initial_state(b)
        self.start = np.ones(b, dtype=np.bool_)  # the hidden state is reset before this step
        self.ep_return = np.zeros(b)
        self.update = 0
        self.env_steps = 0
        self.episodes = 0
        self.wall = 0.0
        self.win_return: list[float] = []
        self.win_event: list[int] = []
        self.curve: list[list[float]] = []

    def _sample(self) -> State:
        seed = int(self.rng.integers(2**63))
        return sample_state(self.scenario, np.random.default_rng(seed))

    # -------------------------------------------------------------------- rollout
    def rollout(self) -> dict[str, Any]:
        """Collect ``rollout`` steps of every environment (no gradients). The network acts
        through its NumPy forward (:class:`~pioneer.baselines.crowdnav.inference.CrowdNavInference`:
        the module's values to float32 rounding, a third of its time for 64 environments);
        the update recomputes every quantity it differentiates with the module."""
        ppo, t_len, b = self.ppo, self.ppo.rollout, self.ppo.n_envs
        buf: dict[str, list[Any]] = {
            k: [] for k in ("robot", "temporal", "spatial", "mask", "start", "action", "logp")
        }
        values, rewards, dones = np.zeros((t_len, b)), np.zeros((t_len, b)), np.zeros((t_len, b))
        h0 = self.h.clone()
        h = self.h.numpy()
        net = CrowdNavInference(self.model)
        std = torch.exp(self.model.log_std.detach())
        sim = self.world.sim
        with torch.no_grad():
            for t in range(t_len):
                obs = build_observation(self.state, self.world, self.net_cfg)
                mean_np, value, h = net.act(obs, h * (~self.start)[:, None])
                mean = torch.from_numpy(mean_np)
                noise = torch.randn(mean.shape, generator=self.gen)
                action = mean + std * noise
                logp = _normal(mean, std).log_prob(action).sum(-1)
                for k, x in zip(("robot", "temporal", "spatial", "mask"), obs, strict=True):
                    buf[k].append(x)
                buf["start"].append(self.start.copy())
                buf["action"].append(action)
                buf["logp"].append(logp)
                values[t] = value
                cmd = command_from_action(
                    action.numpy(), self.state.command[:, 0], sim.robot, sim.dt, self.net_cfg
                )
                new = step(self.world, self.state, cmd)
                event = classify(self.state, new, sim.time_limit)  # the world ends episodes
                r = crowdnav_reward(self.world, self.state, new, event, self.reward_cfg)
                rewards[t] = r
                done = event != Event.NONE
                dones[t] = done
                self.ep_return += r
                for i in np.flatnonzero(done):
                    self._finish(float(self.ep_return[i]), int(event[i]))
                    self.ep_return[i] = 0.0
                    new.put(int(i), self._sample())
                self.state, self.start = new, done
            obs = build_observation(self.state, self.world, self.net_cfg)
            _, last_value, _ = net.act(obs, h * (~self.start)[:, None])
        self.h = torch.from_numpy(h)
        self.env_steps += t_len * b
        adv, ret = compute_gae(
            rewards, values, dones, last_value.astype(np.float64), ppo.gamma, ppo.gae_lambda
        )
        stacked = {k: np.stack(v) for k, v in buf.items() if k not in ("action", "logp")}
        return {
            **{k: torch.from_numpy(v) for k, v in stacked.items()},
            "action": torch.stack(buf["action"]),
            "logp": torch.stack(buf["logp"]),
            "adv": torch.from_numpy(adv).to(torch.float32),
            "ret": torch.from_numpy(ret).to(torch.float32),
            "h0": h0,
        }

    def _finish(self, ret: float, event: int) -> None:
        self.episodes += 1
        self.win_return = [*self.win_return, ret][-self.ppo.window :]
        self.win_event = [*self.win_event, event][-self.ppo.window :]

    # -------------------------------------------------------------------- update
    def learn(self, batch: dict[str, Any]) -> dict[str, float]:
        """PPO epochs over the rollout (or, during the critic warm-up, value regression of the
        critic head alone); returns mean losses."""
        ppo, model = self.ppo, self.model
        warmup = self.update < self.warm.critic_warmup
        adv = batch["adv"]
        adv = (adv - adv.mean()) / (adv.std() + 1e-8)
        stats = {"policy_loss": 0.0, "value_loss": 0.0, "entropy": 0.0, "n": 0.0}
        model.train()
        for _ in range(ppo.epochs):
            perm = torch.randperm(ppo.n_envs, generator=self.gen)
            for idx in torch.tensor_split(perm, ppo.minibatches):
                x, _, _ = model.encode(
                    batch["robot"][:, idx],
                    batch["temporal"][:, idx],
                    batch["spatial"][:, idx],
                    batch["mask"][:, idx],
                )
                keep = (~batch["start"][:, idx]).to(torch.float32)
                hs = gru_sequence(model.gru, x, batch["h0"][idx], keep)
                if warmup:
                    value = model.value_head(model.critic(hs.detach())).squeeze(-1)
                    vl = 0.5 * ((batch["ret"][:, idx] - value) ** 2).mean()
                    self.critic_opt.zero_grad(set_to_none=True)
                    (ppo.value_coef * vl).backward()
                    torch.nn.utils.clip_grad_norm_(
                        self.critic_params, ppo.max_grad_norm, foreach=True
                    )
                    self.critic_opt.step()
                    stats["value_loss"] += float(vl.detach())
                    stats["n"] += 1
                    continue
                mean, value = model.heads(hs)
                dist = _normal(mean, torch.exp(model.log_std))
                logp = dist.log_prob(batch["action"][:, idx]).sum(-1)
                pg = clipped_surrogate(logp, batch["logp"][:, idx], adv[:, idx], ppo.clip)
                vl = 0.5 * ((batch["ret"][:, idx] - value) ** 2).mean()
                ent = dist.entropy().sum(-1).mean()
                loss = pg + ppo.value_coef * vl - ppo.entropy_coef * ent
                self.opt.zero_grad(set_to_none=True)
                loss.backward()
                torch.nn.utils.clip_grad_norm_(model.parameters(), ppo.max_grad_norm, foreach=True)
                self.opt.step()
                stats["policy_loss"] += float(pg.detach())
                stats["value_loss"] += float(vl.detach())
                stats["entropy"] += float(ent.detach())
                stats["n"] += 1
        model.eval()
        n = stats.pop("n")
        return {k: v / n for k, v in stats.items()}

    def end_update(self) -> list[float]:
        """Count the update and append its learning-curve row."""
        self.update += 1
        return self.record()

    def record(self) -> list[float]:
        """Append this update's learning-curve row."""
        codes = (Event.SUCCESS, Event.COLLISION, Event.TIMEOUT)
        row = [
            float(self.update),
            float(self.env_steps),
            float(self.episodes),
            *window_row(self.win_return, self.win_event, codes),
            self.wall,
        ]
        self.curve.append(row)
        return row

    # -------------------------------------------------------------------- checkpoint
    def settings(self) -> dict[str, Any]:
        """What must match between a checkpoint and a resuming command."""
        ppo = self.ppo.to_dict()
        for k in ("total_steps", "checkpoint_every"):
            ppo.pop(k)
        out = {
            "scenario": self.scenario.name,
            "ppo": ppo,
            "net": self.net_cfg.to_dict(),
            "reward": self.reward_cfg.to_dict(),
        }
        if self.warm.active:  # absent for pure PPO: older checkpoints stay resumable
            out["warm_start"] = self.warm.to_dict()
        return out

    def save(self, path: Path) -> None:
        """The whole training state to ``path`` (safetensors + JSON metadata, atomically)."""
        tensors = {
            f"env/{k}": torch.from_numpy(np.ascontiguousarray(getattr(self.state, k)))
            for k in State.fields()
        }
        tensors["train/h"] = self.h.clone().contiguous()
        tensors["train/start"] = torch.from_numpy(self.start.copy())
        tensors["train/ep_return"] = torch.from_numpy(self.ep_return.copy())
        progress, meta = progress_state(self, len(CURVE_COLUMNS))
        tensors.update(progress)
        write_training_state(
            path,
            TRAIN_FORMAT,
            modules={"model": self.model},
            optimizers={"optim": self.opt, "critic_optim": self.critic_opt},
            tensors=tensors,
            meta={
                "settings": self.settings(),
                **meta,
            },
        )

    def load(self, path: Path) -> None:
        """Restore the state written by :meth:`save` (settings must match this trainer's)."""
        fix = "point --out at a new folder (the checkpoint is corrupt or of another kind)"
        meta, t = read_training_state(path, TRAIN_FORMAT, fix)
        stored = _flat(json.loads(meta["settings"]))
        mine = _flat(self.settings())
        diff = sorted(k for k in set(stored) | set(mine) if stored.get(k) != mine.get(k))
        if diff:
            raise ConfigError(
                expect(
                    f"{path}: settings",
                    "the same settings as this command (only --steps may change)",
                    {k: stored.get(k) for k in diff},
                    "repeat the original command (see train.json) or use a new --out",
                )
            )
        self.model.load_state_dict(
            {k[len("model/") :]: v for k, v in t.items() if k.startswith("model/")}, strict=True
        )
        restore_optimizer(self.opt, t, meta, "optim")
        if "critic_param_groups" in meta:
            restore_optimizer(self.critic_opt, t, meta, "critic_optim")
        self.state = State(**{k: t[f"env/{k}"].numpy().copy() for k in State.fields()})
        self.h = t["train/h"].clone()
        self.start = t["train/start"].numpy().copy()
        self.ep_return = t["train/ep_return"].numpy().copy()
        restore_progress(self, t, meta)
