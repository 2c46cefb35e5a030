"""What an environment's reward is: a function of one step that prices it.

The world decides how a step ends (:func:`pioneer.sim.events.classify`: success, collision,
timeout); the reward only prices the step, given those event codes. A ``StepReward`` is
called with the world, the states before and after the step (``B`` copies) and the event
codes ``(B,)``, and returns the total ``(B,)`` and its terms ``{name: (B,)}`` (reported in
``info["rewards"]``). The registered environments use
:class:`~pioneer.reward.crowdnav.CrowdNavReward` (the reward their ids have always given,
see ``docs/architecture.md``); pass another to train on another reward.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from pioneer.reward.crowdnav import CrowdNavReward, CrowdNavRewardConfig
from pioneer.sim.world import State, World

__all__ = ["StepReward", "step_reward"]

F64 = NDArray[np.float64]


class StepReward(Protocol):
    """Prices one step of ``B`` copies given its event codes."""

    def __call__(
        self, world: World, prev: State, new: State, event: NDArray[np.int8]
    ) -> tuple[F64, dict[str, F64]]: ...


def step_reward(reward: StepReward | CrowdNavRewardConfig | None) -> StepReward:
    """The environment's reward: the CrowdNav++ reward by default, or with the given terms
    (a :class:`CrowdNavRewardConfig`), or any ``StepReward``."""
    if reward is None:
        return CrowdNavReward()
    if isinstance(reward, CrowdNavRewardConfig):
        return CrowdNavReward(reward)
    return reward
