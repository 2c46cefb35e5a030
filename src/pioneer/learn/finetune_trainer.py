"""The trainer of the students' fine-tuning: its settings, the critic, rollouts over
:class:`~pioneer.learn.layout_env.LayoutEnvs`, PPO updates and the whole training state
(the method and its formulas: :mod:`pioneer.learn.finetune`)."""

from __future__ import annotations

import copy
import hashlib
import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray
from torch import nn

from pioneer.errors import ConfigError, expect
from pioneer.learn.curriculum import Curriculum
from pioneer.learn.finetune_config import FINETUNE_REWARD, FinetuneConfig
from pioneer.learn.layout_env import LayoutEnvs, privileged_width
from pioneer.learn.models import Student
from pioneer.learn.rehearsal import Rehearsal
from pioneer.learn.situations import by_situation
from pioneer.nn.checkpoint import read_training_state, restore_optimizer, write_training_state
from pioneer.nn.critic import Critic, lower_tail_mean, value_loss
from pioneer.nn.ppo import (
    clipped_surrogate,
    compute_gae,
    gaussian_kl,
    lagrangian_advantage,
    progress_state,
    restore_progress,
    window_row,
)
from pioneer.sim.events import Event

__all__ = ["CURVE_COLUMNS", "FINETUNE_REWARD", "FinetuneConfig", "FinetuneTrainer"]

TRAIN_FORMAT = "pioneer.finetune-train/1"
CURVE_COLUMNS = (
    "update",
    "env_steps",
    "episodes",
    "mean_return",
    "success_rate",
    "collision_rate",
    "timeout_rate",
    "kl_coef",
    "std",
    "lagrange",
    "wall_time_s",
)
_NOT_SETTINGS = ("total_steps", "checkpoint_every")  # may change between a run and its resume
MAX_HUMANS = 6  # person slots of the critic's privileged view
F64 = NDArray[np.float64]


def _with_new_defaults(stored: dict[str, Any]) -> dict[str, Any]:
    """A checkpoint's settings with the fine-tuning settings added since it was written at
    their defaults: each new setting's default is the run as it was before it existed."""
    defaults = {k: v for k, v in FinetuneConfig().to_dict().items() if k not in _NOT_SETTINGS}
    if isinstance(stored.get("finetune"), dict):
        stored["finetune"] = {**json.loads(json.dumps(defaults)), **stored["finetune"]}
    return stored


class FinetuneTrainer:
    """Everything that changes during fine-tuning (saved whole in the checkpoint)."""

    def __init__(
        self,
        start: Student,
        names: Sequence[Sequence[str]],
        cfg: FinetuneConfig,
        ceiling: Mapping[str, float] | None = None,
        rehearse: Sequence[Sequence[str]] = (),
        progress: bool = False,
    ) -> None:
        self.cfg, self.names = cfg, [list(n) for n in names]
        self.rehearse = [list(n) for n in rehearse]  # layouts rehearsed (pioneer.learn.rehearsal)
        weights: list[float] | None = None
        if cfg.stratify:  # the patterns split by situation (pioneer.learn.situations)
            self.names, weights = by_situation(self.names)
        self.ceiling = None if ceiling is None else dict(ceiling)  # the curriculum's (regret)
        self.start_info: dict[str, Any] = {}  # the starting student's checkpoint info
        self.actor = start.eval()
        self.ref = copy.deepcopy(start).eval().requires_grad_(False)
        gen = torch.Generator().manual_seed(cfg.seed)
        n_in = start.config.input_dim + privileged_width(MAX_HUMANS)
        n_out = cfg.quantiles if self.risky else 1
        self.critic = Critic(n_in, cfg.critic_hidden, gen, n_out)
        self.log_std = nn.Parameter(torch.full((2,), math.log(cfg.init_std)))
        actor_params = [*self.actor.parameters(), self.log_std]
        self.opt = torch.optim.Adam(actor_params, lr=cfg.lr, eps=1e-5)
        self.critic_opt = torch.optim.Adam(self.critic.parameters(), lr=cfg.critic_lr, eps=1e-5)
        # PPO-Lagrangian's cost critic V_c (expected discounted collisions) and multiplier λ;
        # seeded apart, so an unconstrained run is the run it always was
        self.lagrange = 0.0
        self.cost_critic: Critic | None = None
        self.cost_opt: torch.optim.Adam | None = None
        if self.constrained:
            cost_gen = torch.Generator().manual_seed(cfg.seed + 2)
            self.cost_critic = Critic(n_in, cfg.critic_hidden, cost_gen)
            self.cost_opt = torch.optim.Adam(
                self.cost_critic.parameters(), lr=cfg.critic_lr, eps=1e-5
            )
        self.gen = torch.Generator().manual_seed(cfg.seed + 1)
        self.rng = np.random.default_rng(np.random.SeedSequence([cfg.seed, 0xF17E]))
        self.envs = LayoutEnvs(
            self.names,
            cfg.groups,
            cfg.group_size,
            start.config.inputs,
            cfg.reward,
            self.rng,
            cfg.seed,
            MAX_HUMANS,
            cfg.replay,
            cfg.replay_mode,
            self._curriculum(),
            weights,
        )
        # the moving average of the actor's weights (``average_horizon``), else None
        averaging = cfg.average_horizon > 0
        self.average = copy.deepcopy(start).requires_grad_(False) if averaging else None
        self.rehearsal = None
        if self.rehearse:  # the starting student's own states there, drawn before training
            self.rehearsal = Rehearsal.collect(start, self.rehearse, cfg, MAX_HUMANS, progress)
        self.ep_return = np.zeros(cfg.envs)
        self.update = self.env_steps = self.episodes = 0
        self.wall = 0.0
        self.win_return: list[float] = []
        self.win_event: list[int] = []
        self.curve: list[list[float]] = []

    def _curriculum(self) -> Curriculum | None:
        """The active set of hard layouts (``replay_mode = "mastery"``), else ``None``."""
        c = self.cfg
        if c.replay_mode != "mastery":
            return None
        return Curriculum(
            self.names,
            c.mastery_layouts,
            c.mastery,
            c.mastery_window,
            c.mastery_limit,
            self.ceiling,
        )

    @property
    def guided(self) -> bool:
        """Whether the teacher's labels guide the actor (teacher guidance)."""
        return self.cfg.teacher_coef > 0.0

    def _taught(self) -> NDArray[np.int64]:
        """The copies the teacher labels: the first of each of the first ``teacher_groups``."""
        cfg = self.cfg
        return np.arange(min(cfg.teacher_groups, cfg.groups), dtype=np.int64) * cfg.group_size

    @property
    def risky(self) -> bool:
        """Whether the advantages are risk-sensitive (a distributional critic, CVaR_α)."""
        return self.cfg.risk_alpha < 1.0

    def _values(self, seen: torch.Tensor) -> tuple[F64, F64]:
        """The critic's expected return (the targets' bootstrap) and the value the advantages
        use: the same, or CVaR_α of its quantiles when risk-sensitive."""
        v = self.critic(seen)
        if not self.risky:
            out = v.numpy().astype(np.float64)
            return out, out
        mean = v.mean(-1).numpy().astype(np.float64)
        return mean, lower_tail_mean(v, self.cfg.risk_alpha).numpy().astype(np.float64)

    @property
    def constrained(self) -> bool:
        """Whether the collision constraint (PPO-Lagrangian) is on."""
        return self.cfg.collision_limit < 1.0

    # -------------------------------------------------------------------- acting
    def _critic_in(self, x: torch.Tensor, priv: torch.Tensor) -> torch.Tensor:
        a = self.actor
        return torch.cat([(x - a.obs_mean) / a.obs_std, priv], dim=-1)

    def _logp(self, mean: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        z = (action - mean) / self.actor.act_std
        std = torch.exp(self.log_std)
        return (-0.5 * (z / std) ** 2 - self.log_std - 0.5 * math.log(2 * math.pi)).sum(-1)

    def kl_coef(self) -> float:
        """β_t: ``kl_coef`` falling linearly to 0 over the first ``kl_fade`` env steps (a
        fixed schedule, so a run extended by a larger ``--steps`` repeats its start)."""
        cfg = self.cfg
        if cfg.kl_fade <= 0:
            return 0.0
        return float(cfg.kl_coef * max(0.0, 1.0 - self.env_steps / cfg.kl_fade))

    def rollout(self) -> dict[str, torch.Tensor]:
        """``rollout`` steps of every copy under the exploring policy (no gradients)."""
        cfg, envs = self.cfg, self.envs
        t_len, b = cfg.rollout, cfg.envs
        xs, privs, actions, logps = [], [], [], []
        values, rewards, dones = np.zeros((t_len, b)), np.zeros((t_len, b)), np.zeros((t_len, b))
        risk_values = np.zeros((t_len, b))
        cost_values, costs = np.zeros((t_len, b)), np.zeros((t_len, b))
        taught = self._taught() if self.guided else np.zeros(0, dtype=np.int64)
        labels = np.zeros((t_len, b, 2))
        std = torch.exp(self.log_std) * self.actor.act_std
        with torch.no_grad():
            for t in range(t_len):
                x = torch.from_numpy(envs.student_inputs())
                priv = torch.from_numpy(envs.privileged())
                mean = self.actor.deterministic_action(x, "mode")
                action = mean + std * torch.randn(mean.shape, generator=self.gen)
                seen = self._critic_in(x, priv)
                values[t], risk_values[t] = self._values(seen)
                if self.cost_critic is not None:
                    cost_values[t] = self.cost_critic(seen).numpy()
                if taught.size:
                    labels[t, taught] = envs.teacher_labels(taught)
                r, event = envs.step(action.numpy().astype(np.float64))
                rewards[t] = r
                costs[t] = event == Event.COLLISION
                done = event != Event.NONE
                dones[t] = done
                self.ep_return += r
                for i in np.flatnonzero(done):
                    self._finish(float(self.ep_return[i]), int(event[i]))
                    self.ep_return[i] = 0.0
                xs.append(x)
                privs.append(priv)
                actions.append(action)
                logps.append(self._logp(mean, action))
            x = torch.from_numpy(envs.student_inputs())
            priv = torch.from_numpy(envs.privileged())
            seen = self._critic_in(x, priv)
            last_value, last_risk = self._values(seen)
            last_cost = np.zeros(b)
            if self.cost_critic is not None:
                last_cost = self.cost_critic(seen).numpy().astype(np.float64)
            x_all = torch.cat(xs)
            ref = self.ref.deterministic_action(x_all, "mode")
        self.env_steps += t_len * b
        adv, ret = compute_gae(rewards, values, dones, last_value, cfg.gamma, cfg.gae_lambda)
        if self.risky:
            gl = cfg.gamma, cfg.gae_lambda
            adv = compute_gae(rewards, risk_values, dones, last_risk, *gl)[0]
        batch = {
            "x": x_all,
            "priv": torch.cat(privs),
            "action": torch.cat(actions),
            "logp": torch.cat(logps),
            "ref": ref,
        }
        if self.constrained:
            gl = cfg.gamma, cfg.gae_lambda
            adv_c, ret_c = compute_gae(costs, cost_values, dones, last_cost, *gl)
            adv = lagrangian_advantage(adv, adv_c, self.lagrange)
            batch["cost_ret"] = torch.from_numpy(ret_c.reshape(-1)).to(torch.float32)
        if taught.size:
            batch.update(self._guidance(labels, taught, ref))
        batch["adv"] = torch.from_numpy(adv.reshape(-1)).to(torch.float32)
        batch["ret"] = torch.from_numpy(ret.reshape(-1)).to(torch.float32)
        return batch

    def _guidance(
        self, labels: F64, taught: NDArray[np.int64], ref: torch.Tensor
    ) -> dict[str, torch.Tensor]:
        """The rollout's teacher labels ``(T, B, 2)`` as batch entries: ``taught`` (N,) which
        rows carry one, ``label`` (N, 2), and ``label_w`` (N,) their ADVISOR-style weight
        exp(−α d²), d = ‖(μ_0(x) − label) / s_u‖ the DAgger student's distance from the label:
        where the student taught by the teacher could not follow it, the imitation yields to
        the return (Weihs et al., arXiv 2007.12173)."""
        t_len, b = labels.shape[:2]
        mask = np.zeros((t_len, b), dtype=np.bool_)
        mask[:, taught] = True
        label = torch.from_numpy(labels.reshape(-1, 2)).to(torch.float32)
        d2 = (((ref - label) / self.actor.act_std) ** 2).sum(-1)
        return {
            "taught": torch.from_numpy(mask.reshape(-1)),
            "label": label,
            "label_w": torch.exp(-self.cfg.teacher_alpha * d2),
        }

    def _finish(self, ret: float, event: int) -> None:
        self.episodes += 1
        self.win_return = [*self.win_return, ret][-self.cfg.window :]
        self.win_event = [*self.win_event, event][-self.cfg.window :]

    # -------------------------------------------------------------------- learning
    def learn(self, batch: dict[str, torch.Tensor]) -> dict[str, float]:
        """PPO epochs (only the critic's regression during the warm-up); mean losses."""
        cfg = self.cfg
        actor_on = self.update >= cfg.critic_warmup
        beta = self.kl_coef()
        adv = batch["adv"]
        adv = (adv - adv.mean()) / (adv.std() + 1e-8)
        n = adv.shape[0]
        stats = {"policy_loss": 0.0, "value_loss": 0.0, "pull": 0.0}
        if self.guided:
            stats["imitation"] = 0.0
        if self.rehearsal is not None:
            stats["rehearsal"] = 0.0
        steps = 0
        scale = self.actor.act_std * cfg.init_std
        for _ in range(cfg.epochs):
            perm = torch.randperm(n, generator=self.gen)
            for idx in torch.tensor_split(perm, cfg.minibatches):
                x = batch["x"][idx]
                seen = self._critic_in(x, batch["priv"][idx])
                ret = batch["ret"][idx]
                stats["value_loss"] += self._regress(self.critic, self.critic_opt, seen, ret)
                steps += 1
                if self.cost_critic is not None and self.cost_opt is not None:
                    ret = batch["cost_ret"][idx]
                    cl = self._regress(self.cost_critic, self.cost_opt, seen, ret)
                    stats["cost_value_loss"] = stats.get("cost_value_loss", 0.0) + cl
                if not actor_on:
                    continue
                mean = self.actor.deterministic_action(x, "mode")
                logp = self._logp(mean, batch["action"][idx])
                pg = clipped_surrogate(logp, batch["logp"][idx], adv[idx], cfg.clip)
                pull = gaussian_kl(mean, batch["ref"][idx], scale).mean()
                loss = pg + beta * pull
                if "taught" in batch:
                    imitation = self._imitation(mean, batch, idx, scale)
                    loss = loss + cfg.teacher_coef * imitation
                    stats["imitation"] += float(imitation.detach())
                if self.rehearsal is not None:
                    kept = self.rehearsal.loss(self.actor, len(idx), scale, self.gen)
                    loss = loss + cfg.rehearse_coef * kept
                    stats["rehearsal"] += float(kept.detach())
                self.opt.zero_grad(set_to_none=True)
                loss.backward()
                nn.utils.clip_grad_norm_(
                    [*self.actor.parameters(), self.log_std], cfg.max_grad_norm
                )
                self.opt.step()
                stats["policy_loss"] += float(pg.detach())
                stats["pull"] += float(pull.detach())
        return {k: v / max(steps, 1) for k, v in stats.items()}

    @staticmethod
    def _imitation(
        mean: torch.Tensor, batch: dict[str, torch.Tensor], idx: torch.Tensor, scale: torch.Tensor
    ) -> torch.Tensor:
        """The teacher guidance's loss on a minibatch: the weighted mean over its labelled rows
        of ½ ‖(μ(x) − label) / (s_u σ_0)‖² (the pull's scale); 0 without a labelled row."""
        m = batch["taught"][idx]
        if not bool(m.any()):
            return mean.sum() * 0.0
        err = gaussian_kl(mean[m], batch["label"][idx][m], scale)
        return (batch["label_w"][idx][m] * err).mean()

    def _regress(
        self, critic: Critic, opt: torch.optim.Optimizer, seen: torch.Tensor, target: torch.Tensor
    ) -> float:
        """One step of ``critic`` towards ``target`` (½ mean squared error, or the quantile
        Huber loss of a distributional critic; the gradient's norm clipped); the loss."""
        loss = value_loss(critic(seen), target)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        nn.utils.clip_grad_norm_(critic.parameters(), self.cfg.max_grad_norm)
        opt.step()
        return float(loss.detach())

    def end_update(self) -> list[float]:
        """Count the update, move the weights' average (when averaging), redraw the layouts
        when due, move λ (when constrained), append the curve's row."""
        self.update += 1
        if self.average is not None:  # θ̄ ← θ̄ + (θ − θ̄) · steps per update / horizon
            rate = min(1.0, self.cfg.steps_per_update / self.cfg.average_horizon)
            with torch.no_grad():
                for mean, now in zip(
                    self.average.parameters(), self.actor.parameters(), strict=True
                ):
                    mean.lerp_(now, rate)
        if self.update % self.cfg.layout_period == 0:
            for g in range(self.cfg.groups):
                self.envs.redraw(g)
            self.ep_return[:] = 0.0  # the cut episodes are not counted
        codes = (Event.SUCCESS, Event.COLLISION, Event.TIMEOUT)
        stats = window_row(self.win_return, self.win_event, codes)
        if self.constrained and not math.isnan(stats[2]):
            self.lagrange = self.next_lagrange(stats[2])
        row = [
            float(self.update),
            float(self.env_steps),
            float(self.episodes),
            *stats,
            self.kl_coef(),
            float(torch.exp(self.log_std.detach()).mean()),
            self.lagrange,
            self.wall,
        ]
        self.curve.append(row)
        return row

    def next_lagrange(self, collision_rate: float) -> float:
        """λ after one update: projected dual ascent, max(0, λ + ``lagrange_lr`` ·
        (collision rate − ``collision_limit``)), the rate over the last ``window`` episodes."""
        cfg = self.cfg
        return max(0.0, self.lagrange + cfg.lagrange_lr * (collision_rate - cfg.collision_limit))

    # -------------------------------------------------------------------- checkpoint
    def settings(self, student_sha256: str) -> dict[str, Any]:
        """What must match between a checkpoint and a resuming command."""
        cfg = {k: v for k, v in self.cfg.to_dict().items() if k not in _NOT_SETTINGS}
        out = {"finetune": cfg, "student_sha256": student_sha256, "scenarios": self.names}
        if self.rehearse:
            out["rehearse"] = self.rehearse
        if self.ceiling is not None:  # the curriculum's reference success per layout
            table = json.dumps(sorted(self.ceiling.items())).encode()
            out["mastery_teacher_sha256"] = hashlib.sha256(table).hexdigest()
        return out

    def save(self, path: Path, settings: dict[str, Any]) -> None:
        """The whole training state to ``path`` (safetensors + JSON metadata, atomically)."""
        tensors = {
            f"env/{k}": torch.from_numpy(np.ascontiguousarray(a).copy())
            for k, a in self.envs.arrays().items()
        }
        tensors["log_std"] = self.log_std.detach().clone()
        tensors["lagrange"] = torch.tensor([self.lagrange], dtype=torch.float64)
        modules = {"actor": self.actor, "ref": self.ref, "critic": self.critic}
        if self.average is not None:
            modules["average"] = self.average
        optimizers = {"optim": self.opt, "critic_optim": self.critic_opt}
        if self.cost_critic is not None and self.cost_opt is not None:
            modules["cost_critic"] = self.cost_critic
            optimizers["cost_critic_optim"] = self.cost_opt
        tensors["train/ep_return"] = torch.from_numpy(self.ep_return.copy())
        progress, meta = progress_state(self, len(CURVE_COLUMNS))
        tensors.update(progress)
        write_training_state(
            path,
            TRAIN_FORMAT,
            modules=modules,
            optimizers=optimizers,
            tensors=tensors,
            meta={
                "settings": settings,
                **meta,
                "envs": self.envs.meta(),
            },
        )

    def load(self, path: Path, settings: dict[str, Any]) -> None:
        """Restore the state :meth:`save` wrote (its settings must be ``settings``)."""
        fix = "point --out at a new folder (the checkpoint is corrupt or of another kind)"
        meta, t = read_training_state(path, TRAIN_FORMAT, fix)
        stored = _with_new_defaults(json.loads(meta["settings"]))
        if stored != json.loads(json.dumps(settings)):
            keys = set(stored) | set(settings)
            diff = sorted(k for k in keys if stored.get(k) != settings.get(k))
            raise ConfigError(
                expect(
                    f"{path}: settings",
                    "the same settings and input student as this command (only --steps may change)",
                    diff,
                    "repeat the original command (see train.json) or use a new --out",
                )
            )
        modules: list[tuple[str, nn.Module]] = [
            ("actor", self.actor),
            ("ref", self.ref),
            ("critic", self.critic),
        ]
        if self.cost_critic is not None:
            modules.append(("cost_critic", self.cost_critic))
        if self.average is not None:
            modules.append(("average", self.average))
        for prefix, module in modules:
            sd = {k[len(prefix) + 1 :]: v for k, v in t.items() if k.startswith(prefix + "/")}
            module.load_state_dict(sd, strict=True)
        with torch.no_grad():
            self.log_std.copy_(t["log_std"])
        self.lagrange = float(t["lagrange"][0])
        restore_optimizer(self.opt, t, meta, "optim")
        restore_optimizer(self.critic_opt, t, meta, "critic_optim")
        if self.cost_opt is not None:
            restore_optimizer(self.cost_opt, t, meta, "cost_critic_optim")
        env = {k[4:]: v.numpy() for k, v in t.items() if k.startswith("env/")}
        self.envs.restore(env, json.loads(meta["envs"]))
        self.ep_return = t["train/ep_return"].numpy().copy()
        restore_progress(self, t, meta)
