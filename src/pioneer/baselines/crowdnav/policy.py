"""The ``crowdnav++`` policy: a trained :class:`CrowdNavNet` acting from ``info``."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import torch
from annotated_types import Ge
from numpy.typing import NDArray

from pioneer.baselines.crowdnav.network import CrowdNavNet, load_crowdnav
from pioneer.baselines.crowdnav.observation import (
    build_observation,
    command_from_action,
    obs_tensors,
)
from pioneer.data import shipped_crowdnav_weights
from pioneer.errors import ConfigError, expect
from pioneer.sim.world import State, World

__all__ = ["CrowdNavPolicy", "make_crowdnav_policy"]


# ------------------------------------------------------------------------------ policy
class CrowdNavPolicy:
    """CrowdNav++ acting from the privileged state in ``info`` (deterministic: mean action).

    ``reset`` zeroes the GRU state; ``act`` builds the graph observation, advances the GRU one
    step and integrates the mean increments on the last command. ``attention`` holds the last
    robot–human weights over the sorted, present humans.
    """

    def __init__(self, model: CrowdNavNet, name: str = "crowdnav++") -> None:
        self.model = model.eval()
        self.name = name
        self.h = model.initial_state(1)
        self.attention: NDArray[np.float32] = np.zeros(0, dtype=np.float32)

    def reset(self, info: Mapping[str, Any], rng: np.random.Generator) -> None:
        """Start an episode: GRU state to zero (the policy is deterministic; ``rng`` unused)."""
        self.h = self.model.initial_state(1)

    def act(self, obs: NDArray[np.float32], info: Mapping[str, Any]) -> NDArray[np.float64]:
        """The command ``(v [m/s], ω [rad/s])``, shape ``(2,)``."""
        state, world = info.get("state"), info.get("world")
        if not isinstance(state, State) or not isinstance(world, World):
            raise ConfigError(
                expect(
                    "CrowdNavPolicy info",
                    "'state' (State) and 'world' (World) entries",
                    sorted(info),
                    "run it in pioneer.envs.env.NavEnv, whose info carries them",
                )
            )
        o = build_observation(state, world, self.model.config)
        with torch.inference_mode():
            x, a_rh, _ = self.model.encode(*obs_tensors(o))
            self.h = self.model.gru(x, self.h)
            mean, _ = self.model.heads(self.h)
        self.attention = a_rh[0].numpy()[o.mask[0]]
        cmd = command_from_action(
            mean.numpy(), state.command[:, 0], world.sim.robot, world.sim.dt, self.model.config
        )
        return cmd[0]


def make_crowdnav_policy(
    weights: str | Path | None = None,
    scenario: str | None = None,
    name: str = "crowdnav++",
    torch_threads: Annotated[int, Ge(1)] | None = 1,
    variant: str = "ppo",
) -> CrowdNavPolicy:
    """Policy factory: ``weights`` (``{scenario}`` filled in) or the shipped file for ``scenario``
    (``variant`` "ppo": pure PPO, the ``crowdnav++`` row; "il": imitation warm start + PPO, the
    ``crowdnav++-il`` row).

    ``torch_threads`` sets torch's intra-op threads of this process (1: a batch-1 step gains
    nothing from threads and evaluation runs one worker per core); ``None`` leaves it.
    """
    if weights is None:
        if scenario is None:
            raise ConfigError(
                expect("crowdnav++", "weights=FILE or a scenario", None, "pass scenario='hr-rl'")
            )
        path = shipped_crowdnav_weights(scenario, variant)
    else:
        path = Path(str(weights).format(scenario=scenario) if scenario else str(weights))
    if torch_threads is not None:
        torch.set_num_threads(int(torch_threads))
    return CrowdNavPolicy(load_crowdnav(path), name=name)
