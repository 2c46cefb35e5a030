"""Reinforcement-learning fine-tuning of a DAgger student over a layout distribution (beyond
the paper; docs/student.md, "Fine-tuning with reinforcement learning").

``pioneer finetune --student FILE --scenario 'general-*' --out DIR`` calls
:func:`finetune_student`. DAgger teaches the student the teacher's single choice, made with a
future the student cannot see; fine-tuning lets the student's own outcomes correct what it
learned, while a pull towards the DAgger student keeps what the teacher taught.

Policy
    The student's deterministic command μ(x) — the mean of its most probable component (MDN) or
    its regression (MLP), exactly what it executes when deployed — plus Gaussian exploration
    noise with a learned, state-independent standard deviation σ in standardised action units
    (initial ``init_std``): π(u | x) = N(μ(x), (σ · s_u)²), s_u the student's action scale. A
    symmetric student stays mirror-equivariant (its architecture makes it so).
Critic
    A separate MLP (``critic_hidden``, ReLU) of the student's standardised inputs and the
    privileged state (:func:`pioneer.learn.layout_env.privileged`: elapsed time, goal, every
    person's position, velocity, size, start and reaction). It is not deployed. For the first
    ``critic_warmup`` updates only the critic learns, so the actor's first updates see a fitted
    value.
Pull towards the DAgger student
    β_t · ½ ‖(μ(x) − μ_0(x)) / (s_u σ_0)‖², the KL divergence between the DAgger student's and
    the actor's Gaussians at the initial noise σ_0; β_t falls linearly from ``kl_coef`` to 0
    over the first ``kl_fade`` env steps.
Reward
    The CrowdNav++ reward (:mod:`pioneer.reward.crowdnav`) without its intrusion term
    (``intrusion = 0``): +10 on success, −20 on a collision, 3 per metre towards the goal, the
    discomfort and spin costs. With the intrusion term waiting beside the door pays better than
    arriving (docs/baselines.md); without it, arriving pays most.
PPO
    :mod:`pioneer.nn.ppo`'s GAE and clipped surrogate, γ = 0.99 and λ = 0.95 per 0.1 s step,
    clip 0.2, ``epochs`` passes of ``minibatches`` shuffled minibatches of the flattened
    rollout, advantages normalised per rollout, gradient norm ≤ 0.5, Adam for the actor (``lr``,
    with σ) and the critic (``critic_lr``). The environments are
    :class:`~pioneer.learn.layout_env.LayoutEnvs`: ``groups`` layouts × ``group_size`` copies;
    every ``layout_period`` updates every group draws a new layout.

Outputs in ``out/`` (each written atomically)
    ``student.safetensors``   the fine-tuned student (the input's format and config: it runs,
                              exports and deploys like any student);
    ``checkpoint.safetensors`` the whole training state every ``checkpoint_every`` updates
                              (the actor, the DAgger student it is pulled to, the critic, σ,
                              both optimisers, every copy's state and inputs, the generators):
                              a resumed run equals an uninterrupted one on the same machine;
    ``curve.csv`` / ``curve.png``, ``train.json``.

Resuming: the same command on an ``out`` with a checkpoint continues it; a larger ``--steps``
extends a finished run; any other setting (or another input student) is refused.
"""

from __future__ import annotations

import copy
import dataclasses
import json
import math
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import torch
from annotated_types import MinLen
from torch import nn

from pioneer.bounds import Count, NonNegative, NonNegativeInt, Positive, UnitInterval
from pioneer.config import Config
from pioneer.errors import ConfigError, DataError, expect
from pioneer.interrupt import Interrupted
from pioneer.io import (
    atomic_path,
    check_not_input,
    file_sha256,
    output_dir_kind,
    run_lock,
    to_json,
    write_text_atomic,
)
from pioneer.learn.layout_env import LayoutEnvs, privileged_width
from pioneer.learn.models import Student, load_student, read_checkpoint_meta, save_student
from pioneer.nn.checkpoint import optimizer_state, optimizer_tensors, read_training_state
from pioneer.nn.layers import seeded_linear
from pioneer.nn.ppo import (
    check_resume,
    clipped_surrogate,
    compute_gae,
    curve_csv,
    update_loop,
    window_row,
)
from pioneer.reward.crowdnav import NO_INTRUSION, CrowdNavRewardConfig
from pioneer.sim.events import Event

__all__ = ["CURVE_COLUMNS", "FINETUNE_REWARD", "FinetuneConfig", "finetune_student"]

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
    "wall_time_s",
)
FINETUNE_REWARD = NO_INTRUSION  # the CrowdNav++ reward without its intrusion term
MAX_HUMANS = 6  # person slots of the critic's privileged view


@dataclasses.dataclass(frozen=True)
class FinetuneConfig(Config):
    """Settings of a fine-tuning run (module docstring)."""

    total_steps: Count = 6_000_000  # env steps (all copies together)
    groups: Count = 8  # layouts stepped at once
    group_size: Count = 8  # copies of each layout
    rollout: Count = 64  # steps per copy per update
    layout_period: Count = 4  # [updates] between two draws of every group's layout
    lr: Positive = 3e-5  # the actor's Adam learning rate (with σ)
    critic_lr: Positive = 1e-3  # the critic's
    gamma: UnitInterval = 0.99  # discount per 0.1 s step
    gae_lambda: UnitInterval = 0.95  # GAE λ
    clip: Positive = 0.2  # PPO ratio clip
    epochs: Count = 4  # passes over each rollout
    minibatches: Count = 4  # per pass
    max_grad_norm: Positive = 0.5  # gradient clipping (global L2 norm, per network)
    init_std: Positive = 0.2  # σ_0: exploration noise in standardised action units
    kl_coef: NonNegative = 1.0  # β_0 of the pull towards the DAgger student
    kl_fade: NonNegativeInt = 500_000  # [env steps] over which β falls to 0
    critic_warmup: NonNegativeInt = 10  # [updates] the critic alone learns first
    critic_hidden: Annotated[tuple[Count, ...], MinLen(1)] = (128, 128)  # its widths
    reward: CrowdNavRewardConfig = FINETUNE_REWARD
    seed: NonNegativeInt = 0  # seeds the critic, the noise, the minibatches and the episodes
    checkpoint_every: Count = 20  # [updates] between checkpoints
    window: Count = 200  # finished episodes in the curve's running statistics

    @property
    def envs(self) -> int:
        """Copies stepped together: groups × group_size."""
        return self.groups * self.group_size

    @property
    def steps_per_update(self) -> int:
        """Env steps per update."""
        return self.envs * self.rollout

    @property
    def updates(self) -> int:
        """Updates for ``total_steps`` (rounded up)."""
        return -(-self.total_steps // self.steps_per_update)


class Critic(nn.Module):
    """V(x, s): an MLP of the student's standardised inputs and the privileged features."""

    def __init__(self, n_in: int, hidden: Sequence[int], gen: torch.Generator) -> None:
        super().__init__()
        layers: list[nn.Module] = []
        for width in hidden:
            layers += [seeded_linear(n_in, width, gen), nn.ReLU()]
            n_in = width
        layers.append(seeded_linear(n_in, 1, gen))
        self.net = nn.Sequential(*layers)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Values ``(N,)``."""
        out: torch.Tensor = self.net(x).squeeze(-1)
        return out


class _Trainer:
    """Everything that changes during fine-tuning (saved whole in the checkpoint)."""

    def __init__(self, start: Student, names: Sequence[Sequence[str]], cfg: FinetuneConfig) -> None:
        self.cfg, self.names = cfg, [list(n) for n in names]
        self.start_info: dict[str, Any] = {}  # the starting student's checkpoint info
        self.actor = start.eval()
        self.ref = copy.deepcopy(start).eval().requires_grad_(False)
        gen = torch.Generator().manual_seed(cfg.seed)
        n_in = start.config.input_dim + privileged_width(MAX_HUMANS)
        self.critic = Critic(n_in, cfg.critic_hidden, gen)
        self.log_std = nn.Parameter(torch.full((2,), math.log(cfg.init_std)))
        actor_params = [*self.actor.parameters(), self.log_std]
        self.opt = torch.optim.Adam(actor_params, lr=cfg.lr, eps=1e-5)
        self.critic_opt = torch.optim.Adam(self.critic.parameters(), lr=cfg.critic_lr, eps=1e-5)
        self.gen = torch.Generator().manual_seed(cfg.seed + 1)
        self.rng = np.random.default_rng(np.random.SeedSequence([cfg.seed, 0xF17E]))
        self.envs = LayoutEnvs(
            names,
            cfg.groups,
            cfg.group_size,
            start.config.inputs,
            cfg.reward,
            self.rng,
            cfg.seed,
            MAX_HUMANS,
        )
        self.ep_return = np.zeros(cfg.envs)
        self.update = self.env_steps = self.episodes = 0
        self.wall = 0.0
        self.win_return: list[float] = []
        self.win_event: list[int] = []
        self.curve: list[list[float]] = []

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
        std = torch.exp(self.log_std) * self.actor.act_std
        with torch.no_grad():
            for t in range(t_len):
                x = torch.from_numpy(envs.student_inputs())
                priv = torch.from_numpy(envs.privileged())
                mean = self.actor.deterministic_action(x, "mode")
                action = mean + std * torch.randn(mean.shape, generator=self.gen)
                values[t] = self.critic(self._critic_in(x, priv)).numpy()
                r, event = envs.step(action.numpy().astype(np.float64))
                rewards[t] = r
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
            last_value = self.critic(self._critic_in(x, priv)).numpy().astype(np.float64)
            x_all = torch.cat(xs)
            ref = self.ref.deterministic_action(x_all, "mode")
        self.env_steps += t_len * b
        adv, ret = compute_gae(rewards, values, dones, last_value, cfg.gamma, cfg.gae_lambda)
        return {
            "x": x_all,
            "priv": torch.cat(privs),
            "action": torch.cat(actions),
            "logp": torch.cat(logps),
            "ref": ref,
            "adv": torch.from_numpy(adv.reshape(-1)).to(torch.float32),
            "ret": torch.from_numpy(ret.reshape(-1)).to(torch.float32),
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
        steps = 0
        scale = self.actor.act_std * cfg.init_std
        for _ in range(cfg.epochs):
            perm = torch.randperm(n, generator=self.gen)
            for idx in torch.tensor_split(perm, cfg.minibatches):
                x = batch["x"][idx]
                value = self.critic(self._critic_in(x, batch["priv"][idx]))
                vl = 0.5 * ((batch["ret"][idx] - value) ** 2).mean()
                self.critic_opt.zero_grad(set_to_none=True)
                vl.backward()
                nn.utils.clip_grad_norm_(self.critic.parameters(), cfg.max_grad_norm)
                self.critic_opt.step()
                stats["value_loss"] += float(vl.detach())
                steps += 1
                if not actor_on:
                    continue
                mean = self.actor.deterministic_action(x, "mode")
                logp = self._logp(mean, batch["action"][idx])
                pg = clipped_surrogate(logp, batch["logp"][idx], adv[idx], cfg.clip)
                pull = 0.5 * (((mean - batch["ref"][idx]) / scale) ** 2).sum(-1).mean()
                loss = pg + beta * pull
                self.opt.zero_grad(set_to_none=True)
                loss.backward()
                nn.utils.clip_grad_norm_(
                    [*self.actor.parameters(), self.log_std], cfg.max_grad_norm
                )
                self.opt.step()
                stats["policy_loss"] += float(pg.detach())
                stats["pull"] += float(pull.detach())
        return {k: v / max(steps, 1) for k, v in stats.items()}

    def end_update(self) -> list[float]:
        """Count the update, redraw the layouts when due, append the curve's row."""
        self.update += 1
        if self.update % self.cfg.layout_period == 0:
            for g in range(self.cfg.groups):
                self.envs.redraw(g)
            self.ep_return[:] = 0.0  # the cut episodes are not counted
        codes = (Event.SUCCESS, Event.COLLISION, Event.TIMEOUT)
        row = [
            float(self.update),
            float(self.env_steps),
            float(self.episodes),
            *window_row(self.win_return, self.win_event, codes),
            self.kl_coef(),
            float(torch.exp(self.log_std.detach()).mean()),
            self.wall,
        ]
        self.curve.append(row)
        return row

    # -------------------------------------------------------------------- checkpoint
    def settings(self, student_sha256: str) -> dict[str, Any]:
        """What must match between a checkpoint and a resuming command."""
        cfg = self.cfg.to_dict()
        for k in ("total_steps", "checkpoint_every"):
            cfg.pop(k)
        return {"finetune": cfg, "student_sha256": student_sha256, "scenarios": self.names}

    def save(self, path: Path, settings: dict[str, Any]) -> None:
        """The whole training state to ``path`` (safetensors + JSON metadata, atomically)."""
        from safetensors.torch import save

        tensors: dict[str, torch.Tensor] = {}
        for prefix, module in (("actor", self.actor), ("ref", self.ref), ("critic", self.critic)):
            for k, v in module.state_dict().items():
                tensors[f"{prefix}/{k}"] = v.detach().clone().contiguous()
        tensors["log_std"] = self.log_std.detach().clone()
        osd, cosd = self.opt.state_dict(), self.critic_opt.state_dict()
        tensors.update(optimizer_tensors(osd, "optim"))
        tensors.update(optimizer_tensors(cosd, "critic_optim"))
        for k, a in self.envs.arrays().items():
            tensors[f"env/{k}"] = torch.from_numpy(np.ascontiguousarray(a).copy())
        tensors["train/ep_return"] = torch.from_numpy(self.ep_return.copy())
        tensors["curve"] = torch.tensor(self.curve, dtype=torch.float64).reshape(
            -1, len(CURVE_COLUMNS)
        )
        tensors["window/return"] = torch.tensor(self.win_return, dtype=torch.float64)
        tensors["window/event"] = torch.tensor(self.win_event, dtype=torch.int64)
        tensors["rng/torch"] = self.gen.get_state()
        counters: dict[str, float] = {"update": self.update, "env_steps": self.env_steps}
        counters |= {"episodes": self.episodes, "wall_time_s": self.wall}
        meta = {
            "format": TRAIN_FORMAT,
            "settings": json.dumps(settings),
            "param_groups": json.dumps(osd["param_groups"]),
            "critic_param_groups": json.dumps(cosd["param_groups"]),
            "counters": json.dumps(counters),
            "rng_numpy": json.dumps(self.rng.bit_generator.state),
            "envs": json.dumps(self.envs.meta()),
            "torch": torch.__version__,
        }
        with atomic_path(path) as tmp:
            tmp.write_bytes(save(tensors, metadata=meta))

    def load(self, path: Path, settings: dict[str, Any]) -> None:
        """Restore the state :meth:`save` wrote (its settings must be ``settings``)."""
        fix = "point --out at a new folder (the checkpoint is corrupt or of another kind)"
        meta, t = read_training_state(path, TRAIN_FORMAT, fix)
        stored = json.loads(meta["settings"])
        if stored != json.loads(json.dumps(settings)):
            diff = sorted(k for k in set(stored) | set(settings) if stored.get(k) != settings[k])
            raise ConfigError(
                expect(
                    f"{path}: settings",
                    "the same settings and input student as this command (only --steps may change)",
                    diff,
                    "repeat the original command (see train.json) or use a new --out",
                )
            )
        for prefix, module in (("actor", self.actor), ("ref", self.ref), ("critic", self.critic)):
            sd = {k[len(prefix) + 1 :]: v for k, v in t.items() if k.startswith(prefix + "/")}
            module.load_state_dict(sd, strict=True)
        with torch.no_grad():
            self.log_std.copy_(t["log_std"])
        self.opt.load_state_dict(optimizer_state(t, "optim", json.loads(meta["param_groups"])))
        groups = json.loads(meta["critic_param_groups"])
        self.critic_opt.load_state_dict(optimizer_state(t, "critic_optim", groups))
        env = {k[4:]: v.numpy() for k, v in t.items() if k.startswith("env/")}
        self.envs.restore(env, json.loads(meta["envs"]))
        self.ep_return = t["train/ep_return"].numpy().copy()
        self.curve = t["curve"].tolist()
        self.win_return = t["window/return"].tolist()
        self.win_event = [int(x) for x in t["window/event"].tolist()]
        self.gen.set_state(t["rng/torch"])
        self.rng.bit_generator.state = json.loads(meta["rng_numpy"])
        c = json.loads(meta["counters"])
        self.update, self.env_steps = int(c["update"]), int(c["env_steps"])
        self.episodes, self.wall = int(c["episodes"]), float(c["wall_time_s"])


# ------------------------------------------------------------------------------ the run
def _write_outputs(tr: _Trainer, out: Path, info: dict[str, Any], final: bool) -> None:
    tr.save(out / "checkpoint.safetensors", info["settings"])
    # the DAgger student's own record (its recipe, scenario, losses) stays, beside this run's
    save_student(tr.actor, out / "student.safetensors", {**tr.start_info, "finetune": info})
    write_text_atomic(out / "curve.csv", curve_csv(CURVE_COLUMNS, tr.curve))
    if final:
        from pioneer.viz.plots import plot_learning_curve

        arr = np.asarray(tr.curve, dtype=np.float64).reshape(-1, len(CURVE_COLUMNS))
        plot_learning_curve(
            {c: arr[:, i] for i, c in enumerate(CURVE_COLUMNS)},
            out / "curve.png",
            title=f"student fine-tuning · {sum(map(len, tr.names))} scenario(s)",
        )
        write_text_atomic(out / "train.json", to_json(info, indent=2) + "\n")


def finetune_student(
    student: str | Path,
    scenarios: Sequence[str],
    out_dir: str | Path,
    config: FinetuneConfig | None = None,
    resume: bool | None = None,
    progress: bool = True,
    command: str = "",
    torch_threads: int | None = 1,
    on_update: Callable[[dict[str, float]], None] | None = None,
) -> dict[str, Any]:
    """Fine-tune (or resume) the student at ``student`` over ``scenarios`` (names or patterns
    such as ``general-*``; each entry drawn equally often, a pattern's matches uniformly);
    returns the summary written to ``train.json``.

    ``resume``: ``None`` continues from ``out/checkpoint.safetensors`` if there is one,
    ``True`` requires it, ``False`` refuses it. Every input is checked before ``out`` is
    created; one run writes to ``out`` at a time (:func:`pioneer.io.run_lock`).
    """
    from pioneer.learn.dagger import scenario_set

    cfg = config or FinetuneConfig()
    if not scenarios:
        raise ConfigError(expect("--scenario", "one or more scenarios", "none", "name one"))
    names = [scenario_set(pattern) for pattern in scenarios]
    src = Path(student)
    start = load_student(src)
    obs_dims = {_obs_dim(n) for pool in names for n in pool}
    if obs_dims != {start.config.obs_dim}:
        raise DataError(
            expect(
                f"student {src}: obs_dim",
                f"the scenarios' observation width {sorted(obs_dims)}",
                start.config.obs_dim,
                "fine-tune a student of these scenarios' LiDAR",
            )
        )
    out = output_dir_kind(out_dir)
    check_not_input(out / "student.safetensors", [src])
    ckpt = out / "checkpoint.safetensors"
    check_resume(resume, ckpt, out)
    if torch_threads is not None:
        torch.set_num_threads(int(torch_threads))
    tr = _Trainer(start, names, cfg)
    tr.start_info = {k: v for k, v in read_checkpoint_meta(src)["info"].items() if k != "finetune"}
    settings = tr.settings(file_sha256(src))
    with run_lock(out):
        check_resume(resume, ckpt, out)  # again, holding the lock
        resumed_from = None
        if ckpt.is_file():
            tr.load(ckpt, settings)
            resumed_from = tr.update

        def info() -> dict[str, Any]:
            last = tr.curve[-1] if tr.curve else [math.nan] * len(CURVE_COLUMNS)
            return {
                "student": str(src),
                "command": command,
                "settings": settings,
                "updates": tr.update,
                "env_steps": tr.env_steps,
                "episodes": tr.episodes,
                "wall_time_s": round(tr.wall, 1),
                "resumed_from_update": resumed_from,
                "final": dict(zip(CURVE_COLUMNS[3:7], last[3:7], strict=True)),
            }

        t_start, s_start = time.perf_counter(), tr.env_steps
        try:
            _loop(tr, out, info, progress, on_update)
            summary = info()
            summary["steps_per_s_this_run"] = (tr.env_steps - s_start) / max(
                time.perf_counter() - t_start, 1e-9
            )
            _write_outputs(tr, out, summary, final=True)
        except Interrupted as exc:
            _write_outputs(tr, out, info(), final=False)
            exc.kept = f"update {tr.update} of {cfg.updates} kept in {ckpt}"
            raise
        return summary


def _obs_dim(name: str) -> int:
    from pioneer.sim.scenarios import get_scenario

    return int(get_scenario(name).sim.lidar.obs_dim)


def _loop(
    tr: _Trainer,
    out: Path,
    info: Callable[[], dict[str, Any]],
    progress: bool,
    on_update: Callable[[dict[str, float]], None] | None,
) -> None:
    cfg = tr.cfg
    update_loop(
        tr,
        cfg.updates,
        cfg.steps_per_update,
        CURVE_COLUMNS,
        "fine-tuning",
        progress,
        cfg.checkpoint_every,
        lambda: _write_outputs(tr, out, info(), final=False),
        on_update,
    )
