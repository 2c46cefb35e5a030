"""The ``crowdnav++`` policy: a trained :class:`CrowdNavNet` acting from ``info``."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import torch
from annotated_types import Ge
from numpy.typing import NDArray

from pioneer.baselines.crowdnav.inference import CrowdNavInference
from pioneer.baselines.crowdnav.network import CrowdNavNet, load_crowdnav
from pioneer.baselines.crowdnav.observation import (
    build_observation,
    command_from_action,
    obs_tensors,
)
from pioneer.data import shipped_crowdnav_weights
from pioneer.errors import ConfigError, expect
from pioneer.nn.forward_choice import FORWARD, Forward, check_forward
from pioneer.sim.world import State, World

__all__ = ["CrowdNavPolicy", "make_crowdnav_policy"]


# ------------------------------------------------------------------------------ policy
class CrowdNavPolicy:
    """CrowdNav++ acting from the privileged state in ``info`` (deterministic: mean action).

    ``reset`` zeroes the GRU state; ``act`` builds the graph observation, advances the GRU one
    step and integrates the mean increments on the last command. ``attention`` holds the last
    robot–human weights over the sorted, present humans. ``forward``: who computes the
    network's step (:mod:`pioneer.nn.forward_choice`).
    """

    def __init__(self, model: CrowdNavNet, name: str = "crowdnav++", forward: Forward = FORWARD):
        check_forward("crowdnav++", forward)
        self.model = model.eval()
        self.name = name
        self.forward = forward
        self._numpy = CrowdNavInference(model) if forward == "numpy" else None
        self.h = np.zeros((1, model.config.hidden), dtype=np.float32)  # the GRU state
        self.attention: NDArray[np.float32] = np.zeros(0, dtype=np.float32)

    def reset(self, info: Mapping[str, Any], rng: np.random.Generator) -> None:
        """Start an episode: GRU state to zero (the policy is deterministic; ``rng`` unused)."""
        self.h = np.zeros_like(self.h)

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
        if self._numpy is not None:
            mean, a_rh, self.h = self._numpy.step(o, self.h)
        else:
            with torch.inference_mode():
                x, a, _ = self.model.encode(*obs_tensors(o))
                h = self.model.gru(x, torch.from_numpy(self.h))
                m, _ = self.model.heads(h)
            mean, a_rh, self.h = m.numpy(), a.numpy(), h.numpy()
        self.attention = a_rh[0][o.mask[0]]
        cmd = command_from_action(
            mean, state.command[:, 0], world.sim.robot, world.sim.dt, self.model.config
        )
        return cmd[0]


def make_crowdnav_policy(
    weights: str | Path | None = None,
    scenario: str | None = None,
    name: str = "crowdnav++",
    torch_threads: Annotated[int, Ge(1)] | None = 1,
    variant: str = "ppo",
    forward: Forward = FORWARD,
) -> CrowdNavPolicy:
    """Policy factory: ``weights`` (``{scenario}`` filled in) or the shipped file for ``scenario``
    (``variant`` "ppo": pure PPO, the ``crowdnav++`` row; "il": imitation of sfm + PPO, the
    ``crowdnav++-il`` row; "il-teacher": imitation of the teacher + PPO without the intrusion
    term, the ``crowdnav++-il-teacher`` row).

    ``torch_threads`` sets torch's intra-op threads of this process (1: a batch-1 step gains
    nothing from threads and evaluation runs one worker per core); ``None`` leaves it.
    ``forward``: the network's acting step in NumPy (the default) or in torch, the reference
    (:mod:`pioneer.baselines.crowdnav.inference`).
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
    return CrowdNavPolicy(load_crowdnav(path), name=name, forward=forward)
