"""Imitation warm start of CrowdNav++: teacher demonstrations, behaviour cloning, DAgger.

The CrowdNav family pretrains its RL policies by imitation before RL (Chen et al. 2019,
CADRL/SARL: value networks initialised by imitation learning on demonstrations). Our PPO-only
CrowdNav++ runs (2.5 M steps, 1/8 of the original's budget) settle in a local optimum — drive
to the door and wait — so ``pioneer train crowdnav++ --bc-episodes N`` first imitates the
privileged lookahead teacher (:func:`pioneer.control.teacher.make_teacher`) and then
fine-tunes with PPO (:mod:`.ppo`). This is a deviation from CrowdNav++, which
trains by RL alone; docs/baselines.md reports both.

Demonstrations in the policy's action space
    The teacher drives the scenario *through the policy's action space*: at every step its
    command u* = ``teacher.decide(world, state, prev=state.command[0]).command`` is mapped to
    the raw action a (:func:`action_from_command`, the inverse of
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
    episodes, labels every visited state with the teacher's action and aggregates.

Critic warm-up (in :mod:`pioneer.baselines.crowdnav.ppo`)
    ``critic_warmup`` PPO updates train only the critic head (its own Adam, ``critic_lr``) on
    the cloned policy's returns, with the shared encoder, GRU and actor frozen, so that PPO's
    first policy updates use sensible advantages instead of a random critic's.

Files (in the training ``out``; written atomically, no pickle)
    ``bc_data.npz``             the aggregated dataset, with its settings as JSON (``meta``);
                                collection resumes at the first missing round (the teacher's
                                round is kept when only the cloning settings changed);
    ``bc_policy.safetensors``   the cloned policy (:func:`~.network.load_crowdnav`);
                                when present the imitation phase is not redone.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import time
import typing
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, Literal

import numpy as np
import torch
from numpy.typing import NDArray

from pioneer.baselines.crowdnav.bc_data import BCData, load_bc_data, save_bc_data
from pioneer.baselines.crowdnav.network import (
    CrowdNavConfig,
    CrowdNavNet,
    load_crowdnav,
    read_crowdnav_meta,
    save_crowdnav,
)
from pioneer.baselines.crowdnav.observation import (
    build_observation,
    command_from_action,
    obs_tensors,
)
from pioneer.bounds import Count, NonNegativeInt, Positive
from pioneer.config import Config
from pioneer.errors import ConfigError, expect
from pioneer.io import to_json
from pioneer.sim.events import Event
from pioneer.sim.scenarios import ScenarioConfig
from pioneer.sim.world import State, World

__all__ = [
    "BCData",
    "WarmStartConfig",
    "action_from_command",
    "bc_loss",
    "collect_episodes",
    "episode_seeds",
    "load_bc_data",
    "save_bc_data",
    "train_bc",
    "warm_start",
]

DATA_FILE = "bc_data.npz"
POLICY_FILE = "bc_policy.safetensors"
# The demonstrators: "sfm", "dwa" (both independent of PioneeR) or PioneeR's "teacher".
Expert = Literal["sfm", "dwa", "teacher"]
EXPERTS: tuple[str, ...] = typing.get_args(Expert)
F64 = NDArray[np.float64]


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


# ------------------------------------------------------------------------------ actions
def action_from_command(
    command: NDArray[np.floating],
    v_prev: NDArray[np.floating],
    dt: float,
    config: CrowdNavConfig,
) -> F64:
    """Raw actions ``(B, 2)`` in [−1, 1]² whose commands come closest to ``command`` ``(B, 2)``.

    The inverse of :func:`~.observation.command_from_action`: Δv = v − v_prev and
    Δθ = ω Δt, each scaled by the bound on its side (0 ↦ 0) and clipped to [−1, 1].
    """
    u = np.asarray(command, dtype=np.float64).reshape(-1, 2)
    inc = np.stack([u[:, 0] - np.asarray(v_prev, dtype=np.float64).reshape(-1), u[:, 1] * dt], -1)
    lo = np.array([config.dv_range[0], config.dtheta_range[0]])
    hi = np.array([config.dv_range[1], config.dtheta_range[1]])
    a = np.where(inc >= 0.0, inc / hi, inc / -lo)
    return np.clip(a, -1.0, 1.0)


# ------------------------------------------------------------------------------ collection
class _Imitation:
    """The episode's driver: the teacher (its clipped action) or the model's mean action
    (DAgger), with every step's observation, teacher label and applied command kept."""

    name = "crowdnav-imitation"

    def __init__(
        self, teacher: Any, net_cfg: CrowdNavConfig, model: CrowdNavNet | None, world: World
    ) -> None:
        self.teacher, self.net_cfg, self.model, self.world = teacher, net_cfg, model, world
        self.cols: dict[str, list[Any]] = {
            k: []
            for k in (
                "robot",
                "temporal",
                "spatial",
                "mask",
                "action",
                "teacher_command",
                "command",
            )
        }
        self._h: Any = None

    def reset(self, info: Mapping[str, Any], rng: np.random.Generator) -> None:
        self._h = self.model.initial_state(1) if self.model is not None else None

    def act(self, obs: NDArray[np.float32], info: Mapping[str, Any]) -> F64:
        s: State = info["state"]
        world, sim, net_cfg = self.world, self.world.sim, self.net_cfg
        graph = build_observation(s, world, net_cfg)
        u_star = expert_command(self.teacher, world, s)
        a_star = action_from_command(u_star, s.command[:, 0], sim.dt, net_cfg)
        if self.model is None:
            a = a_star
        else:
            with torch.inference_mode():
                mean, _, self._h = self.model(*obs_tensors(graph), self._h)
            a = mean.numpy().astype(np.float64)
        cmd = command_from_action(a, s.command[:, 0], sim.robot, sim.dt, net_cfg)
        for k, x in zip(("robot", "temporal", "spatial", "mask"), graph, strict=True):
            self.cols[k].append(x)
        self.cols["action"].append(a_star.astype(np.float32))
        self.cols["teacher_command"].append(u_star.reshape(1, 2))
        self.cols["command"].append(cmd)
        return np.asarray(cmd[0], dtype=np.float64)


def collect_episodes(
    scenario: ScenarioConfig,
    world: World,
    teacher: Any,
    seeds: list[int],
    net_cfg: CrowdNavConfig,
    model: CrowdNavNet | None = None,
    round_index: int = 0,
) -> BCData:
    """Run one episode per seed and label every step with the teacher's action.

    ``model`` ``None``: the teacher drives through the policy's action space (its clipped
    action is applied); otherwise the model's mean action drives (DAgger).
    """
    from pioneer.envs.env import NavEnv
    from pioneer.envs.episode import Episode

    env = NavEnv(scenario)
    driver = _Imitation(teacher, net_cfg, model, world)
    episode: list[NDArray[np.int64]] = []
    events: list[int] = []
    for e, seed in enumerate(seeds):
        run = Episode(env, driver, int(seed))
        run.run()
        events.append(int(Event[str(run.event).upper()]))
        episode.append(np.full(run.steps, e, dtype=np.int64))
    return BCData(
        **{k: np.concatenate(v) for k, v in driver.cols.items()},
        episode=np.concatenate(episode),
        ep_seed=np.asarray(seeds, dtype=np.int64),
        ep_round=np.full(len(seeds), round_index, dtype=np.int64),
        ep_event=np.asarray(events, dtype=np.int8),
    )


def expert_command(expert: Any, world: World, state: State) -> F64:
    """The demonstrator's command ``(v, ω)`` in ``state``: the lookahead teacher smooths from
    the applied command; the rule-based experts (``sfm``, ``dwa``) decide from the state."""
    from pioneer.control.teacher import LookaheadTeacher

    if isinstance(expert, LookaheadTeacher):
        return np.asarray(expert.decide(world, state, prev=state.command[0]).command)
    return np.asarray(expert.decide(world, state), dtype=np.float64)


def make_expert(name: str, scenario: str) -> Any:
    """The demonstrator ``name`` (one of :data:`EXPERTS`) for ``scenario``."""
    from pioneer.control.registry import build_policy

    if name == "teacher":
        from pioneer.control.teacher import make_teacher

        return make_teacher(scenario)

    return build_policy(name, scenario)


def episode_seeds(seed: int, round_index: int, n: int) -> list[int]:
    """Initial-state seeds of round ``round_index`` (independent of the other rounds)."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0xBC, round_index]))
    return [int(x) for x in rng.integers(2**62, size=n)]


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
    h = model.initial_state(x.shape[1])
    hs = []
    for t in range(x.shape[0]):
        h = model.gru(x[t], h)
        hs.append(h)
    return model.mean_head(model.actor(torch.stack(hs)))


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
_SETTINGS_FIX = "use a new --out (it holds an imitation phase of other settings)"


def _check_settings(where: Path, stored: Any, mine: dict[str, Any]) -> None:
    """Refuse to resume from ``where`` if its stored settings differ from this run's."""
    mine = json.loads(json.dumps(mine))
    if stored != mine:
        stored = stored if isinstance(stored, dict) else {}
        diff = sorted(k for k in set(stored) | set(mine) if stored.get(k) != mine.get(k))
        raise ConfigError(
            expect(
                f"{where}: settings",
                "this command's",
                {k: stored.get(k) for k in diff},
                _SETTINGS_FIX,
            )
        )


def _collect_rounds(
    scenario: ScenarioConfig,
    net_cfg: CrowdNavConfig,
    config: WarmStartConfig,
    seed: int,
    keys: tuple[Path, dict[str, Any], dict[str, Any]],
    log: Callable[[str], None] | None,
) -> BCData:
    """Teacher episodes and the DAgger rounds, resumed from (and appended to) the data file."""
    path, settings, clone = keys
    data: BCData | None = None
    if path.is_file():
        data, meta = load_bc_data(path)
        _check_settings(path, meta.get("settings"), settings)
        if meta.get("clone") != json.loads(json.dumps(clone)):
            data = data.rounds(1)  # the teacher's episodes stay valid, the DAgger rounds not
    world = scenario.world()
    teacher = make_expert(config.expert, scenario.name)
    for r in range(config.dagger_rounds + 1):
        if data is not None and np.any(data.ep_round == r):
            continue
        n = config.bc_episodes if r == 0 else config.dagger_episodes
        driver = None
        if r > 0:
            assert data is not None
            driver, _ = train_bc(data.rounds(r), net_cfg, config, seed)
        if log is not None:
            log(f"imitation: round {r}, {n} episodes ({'teacher' if r == 0 else 'DAgger'})")
        part = collect_episodes(
            scenario, world, teacher, episode_seeds(seed, r, n), net_cfg, driver, r
        )
        data = part if data is None else BCData.concat([data, part])
        save_bc_data(data, path, {"settings": settings, "clone": clone})
        if log is not None:
            log(f"imitation: {to_json(data.summary())}")
    assert data is not None
    return data.rounds(config.dagger_rounds + 1)


def warm_start(
    scenario: ScenarioConfig,
    net_cfg: CrowdNavConfig,
    config: WarmStartConfig,
    seed: int,
    out: Path,
    progress: bool = True,
    log: Callable[[str], None] | None = None,
) -> tuple[CrowdNavNet, dict[str, Any]]:
    """The imitation phase, resumable: the cloned model and its summary (``out`` files in the
    module docstring). A complete ``bc_policy.safetensors`` of the same settings is reused."""
    if log is None:
        log = functools.partial(print, flush=True)
    settings = {
        "scenario": scenario.name,
        "seed": seed,
        "net": net_cfg.to_dict(),
        "bc_episodes": config.bc_episodes,
        "dagger_episodes": config.dagger_episodes,
        "expert": config.expert,
    }
    # The DAgger rounds' data depends on the cloning settings too (their drivers are clones).
    clone = {
        "bc_epochs": config.bc_epochs,
        "bc_batch": config.bc_batch,
        "bc_lr": config.bc_lr,
        "min_std": config.min_std,
    }
    train_settings = {**settings, **clone, "dagger_rounds": config.dagger_rounds}
    pol = out / POLICY_FILE
    if pol.is_file():
        info = read_crowdnav_meta(pol)["info"]
        _check_settings(pol, info.get("settings"), train_settings)
        return load_crowdnav(pol), info
    t0 = time.perf_counter()
    keys = (out / DATA_FILE, settings, clone)
    data = _collect_rounds(scenario, net_cfg, config, seed, keys, log if progress else None)
    model, losses = train_bc(data, net_cfg, config, seed)
    if progress:
        log(f"imitation: cloned, loss {losses[0]:.4f} -> {losses[-1]:.4f}")
    info = {
        "scenario": scenario.name,
        "phase": "imitation",
        "settings": train_settings,
        "data": data.summary(),
        "bc_loss": [round(x, 6) for x in losses],
        "log_std": [float(x) for x in model.log_std.detach()],
        "wall_time_s_this_run": round(time.perf_counter() - t0, 1),
    }
    save_crowdnav(model, pol, info)
    return model, info
