"""The one episode driver: reset an environment, step a policy to the episode's end.

Every place that runs an episode — evaluation, demonstration generation, DAgger collection,
the CrowdNav++ imitation warm start, teleoperation — goes through :class:`Episode`, so an
episode starts, steps and ends in one way: the environment is reset with the episode seed,
the policy is reset with a generator seeded by the same seed, and the episode ends at the
first step whose ``info["event"]`` is set (success, collision or timeout; the world decides).

What a caller keeps is its own business: :meth:`Episode.run` hands every :class:`Step` to an
``on_step`` callback (frames, teacher labels, gaps), and :meth:`Episode.step` lets an
interactive caller (teleoperation) advance one control period at a time.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pioneer.envs.env import NavEnv
from pioneer.envs.policy import Policy

__all__ = ["Episode", "Step"]


@dataclasses.dataclass(frozen=True)
class Step:
    """One control period: what the command was chosen from, the command, what followed."""

    index: int  # 0, 1, … within the episode
    obs: NDArray[np.float32]  # the observation the command was chosen from
    info: Mapping[str, Any]  # the environment's info at decision time
    command: NDArray[np.float64]  # (v, ω) applied for this period
    next_obs: NDArray[np.float32]
    next_info: Mapping[str, Any]  # the info after the step (its "event" ends the episode)


class Episode:
    """One episode of ``policy`` in ``env`` seeded by ``seed`` (reset on construction)."""

    def __init__(self, env: NavEnv, policy: Policy, seed: int) -> None:
        self.env = env
        self.policy = policy
        self.seed = seed
        self.obs, self.info = env.reset(seed=seed)
        policy.reset(self.info, np.random.default_rng(seed))
        self.steps = 0
        self.event: str | None = None

    @property
    def done(self) -> bool:
        """Whether the episode has ended."""
        return self.event is not None

    def step(self) -> Step:
        """Ask the policy for a command, apply it for one control period, return the step."""
        if self.event is not None:
            raise RuntimeError(f"the episode ended ({self.event}); start a new Episode")
        command = np.asarray(self.policy.act(self.obs, self.info), dtype=np.float64)
        next_obs, _, _, _, next_info = self.env.step(command)
        done = Step(self.steps, self.obs, self.info, command, next_obs, next_info)
        self.obs, self.info = next_obs, next_info
        self.steps += 1
        event = next_info["event"]
        self.event = None if event is None else str(event)
        return done

    def run(self, on_step: Callable[[Step], None] | None = None) -> Mapping[str, Any]:
        """Step to the end, handing every step to ``on_step``; returns the final ``info``."""
        while self.event is None:
            s = self.step()
            if on_step is not None:
                on_step(s)
        return self.info
