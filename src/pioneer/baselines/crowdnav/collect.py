"""The worker side of CrowdNav++'s imitation warm start
(:mod:`~pioneer.baselines.crowdnav.imitation`): one episode driven by the expert through the
policy's action space, or by a clone (DAgger), with the expert's action as the label of every step
(:func:`collect_episode`), written to its file by :func:`collect_task`; the world, the expert and
the round's clone are cached per process (:mod:`pioneer.imitation.worker`)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray

from pioneer.baselines.crowdnav.bc_data import STEP_KEYS
from pioneer.baselines.crowdnav.network import CrowdNavConfig, CrowdNavNet, load_crowdnav
from pioneer.baselines.crowdnav.observation import (
    build_observation,
    command_from_action,
    obs_tensors,
)
from pioneer.imitation.store import save_episode
from pioneer.imitation.worker import LabelledDriver, WorkerCache
from pioneer.sim.scenarios import ScenarioConfig
from pioneer.sim.world import State, World

__all__ = [
    "CollectTask",
    "action_from_command",
    "clear_cache",
    "collect_episode",
    "collect_task",
    "episode_seeds",
    "make_expert",
]

F64 = NDArray[np.float64]


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


class _Imitation(LabelledDriver):
    """The episode's driver: the expert (its command through the policy's action space:
    clipped) or the model's mean action (DAgger), with every step's observation, expert label
    and applied command kept."""

    name = "crowdnav-imitation"

    def __init__(
        self, teacher: Any, net_cfg: CrowdNavConfig, model: CrowdNavNet | None, world: World
    ) -> None:
        super().__init__(teacher, "applied", world)
        self.net_cfg, self.model, self.sim_world = net_cfg, model, world
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

    def drive(self, obs: NDArray[np.float32], info: Mapping[str, Any], decision: Any) -> F64:
        s: State = info["state"]
        world, net_cfg = self.sim_world, self.net_cfg
        sim = world.sim
        graph = build_observation(s, world, net_cfg)
        u_star = np.asarray(decision.command, np.float64)
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


def collect_episode(
    scenario: ScenarioConfig,
    world: World,
    teacher: Any,
    seed: int,
    net_cfg: CrowdNavConfig,
    model: CrowdNavNet | None = None,
) -> dict[str, NDArray[Any]]:
    """Run one episode from initial-state seed ``seed`` and label every step with the
    teacher's action: the arrays of its file (:mod:`.bc_data`; ``round`` is the caller's).

    ``model`` ``None``: the teacher drives through the policy's action space (its clipped
    action is applied); otherwise the model's mean action drives (DAgger).
    """
    from pioneer.envs.env import NavEnv
    from pioneer.envs.episode import Episode

    driver = _Imitation(teacher, net_cfg, model, world)
    run = Episode(NavEnv(scenario), driver, int(seed))
    run.run()
    return {
        **{k: np.concatenate(driver.cols[k]) for k in STEP_KEYS},
        "event": np.array(str(run.event)),
        "env_seed": np.array(seed, dtype=np.int64),
    }


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


_CACHE = WorkerCache()  # per process: the world, the expert, the driving clone


def clear_cache() -> None:
    """Forget the cached world, expert and clone (a new run in this process)."""
    _CACHE.clear()


CollectTask = tuple[ScenarioConfig, str, CrowdNavConfig, int, int, str | None, str]


def collect_task(args: CollectTask) -> str:
    """Collect one labelled episode (:func:`collect_episode`) and write it to its file: the
    :class:`pioneer.imitation.rounds.Collector` function of the warm start. ``args``:
    scenario, expert name, network config, round, seed, driver clone (``None``: the expert
    drives) and the file."""
    scenario, expert, net_cfg, rnd, seed, driver, path = args
    world = _CACHE.get(("world", scenario.name), scenario.world)
    teacher = _CACHE.get(
        ("expert", expert, scenario.name), lambda: make_expert(expert, scenario.name)
    )
    model = _CACHE.latest("driver", driver, load_crowdnav) if driver is not None else None
    ep = collect_episode(scenario, world, teacher, seed, net_cfg, model)
    return save_episode(path, {**ep, "round": np.array(rnd, dtype=np.int64)})
