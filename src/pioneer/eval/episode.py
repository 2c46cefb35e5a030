"""Run one episode of a policy in a scenario and record what happened."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pioneer.control.policy import Policy
from pioneer.sim.env import NavEnv
from pioneer.sim.scenarios import ScenarioConfig
from pioneer.sim.world import State, World

__all__ = ["EpisodeRecord", "Trajectory", "run_episode"]


@dataclasses.dataclass(frozen=True)
class Trajectory:
    """States of one episode, for plots and animations."""

    world: World
    states: list[State]  # the state after reset, then after every step (B = 1 each)

    @property
    def robot(self) -> NDArray[np.float64]:
        """Robot poses, shape ``(T, 3)``."""
        return np.stack([s.robot[0] for s in self.states])

    @property
    def humans(self) -> NDArray[np.float64]:
        """Human positions, shape ``(T, N, 2)``."""
        return np.stack([s.h_pos[0] for s in self.states])


@dataclasses.dataclass(frozen=True)
class EpisodeRecord:
    """Outcome and metrics of one episode (JSON-serialisable via ``to_dict``)."""

    scenario: str
    policy: str
    seed: int
    event: str  # "success", "collision" or "timeout"
    time_s: float
    path_length_m: float
    min_clearance_m: float  # minimum over the episode (inf if no humans)
    time_close_s: float  # time with clearance below 0.8 m
    steps: int

    def to_dict(self) -> dict[str, Any]:
        """Plain dict; an infinite clearance becomes ``None``."""
        d = dataclasses.asdict(self)
        if not math.isfinite(d["min_clearance_m"]):
            d["min_clearance_m"] = None
        return d


def run_episode(
    scenario: str | ScenarioConfig,
    policy: Policy,
    seed: int,
    record: bool = False,
    close_threshold: float = 0.8,
) -> tuple[EpisodeRecord, Trajectory | None]:
    """Run ``policy`` for one episode seeded by ``seed``; optionally keep every state."""
    env = NavEnv(scenario)
    obs, info = env.reset(seed=seed)
    policy.reset(info, np.random.default_rng(seed))
    states = [env.state] if record else []
    dt = env.scenario.sim.dt
    close = 0.0
    steps = 0
    event = None
    while event is None:
        obs, _, _, _, info = env.step(policy.act(obs, info))
        steps += 1
        if info["min_clearance"] < close_threshold:
            close += dt
        if record:
            states.append(env.state)
        event = info["event"]
    rec = EpisodeRecord(
        scenario=env.scenario.name,
        policy=policy.name,
        seed=seed,
        event=event,
        time_s=info["time"],
        path_length_m=info["path_length"],
        min_clearance_m=info["episode_min_clearance"],
        time_close_s=close,
        steps=steps,
    )
    return rec, (Trajectory(env.world, states) if record else None)
