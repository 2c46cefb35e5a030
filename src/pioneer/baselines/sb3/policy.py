"""The registry's ``sb3-ppo``: a policy trained by :func:`pioneer.baselines.sb3.train_sb3_ppo`,
rebuilt from its ``policy.safetensors`` (no pickle)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pioneer.baselines.sb3.checkpoint import SB3_FORMAT
from pioneer.errors import ConfigError, DataError, expect

__all__ = ["Sb3Policy", "make_sb3_policy"]


class Sb3Policy:
    """A PPO policy trained by :func:`train_sb3_ppo`, acting on the 29-D observation alone.

    It acts as SB3's ``predict(obs, deterministic=True)`` does — the Gaussian's mean from the
    actor's network, clipped to the action space — by calling the same modules directly: the
    same operators on the same values (the tests compare both), without ``predict``'s
    per-call mode switch and input checks, which cost more than the 29 → 64 → 64 → 2 network.
    """

    def __init__(self, policy: Any, name: str = "sb3-ppo") -> None:
        import torch

        self.policy = policy
        self.name = name
        self._torch = torch
        self._low = policy.action_space.low
        self._high = policy.action_space.high

    def reset(self, info: Mapping[str, Any], rng: np.random.Generator) -> None:
        """Nothing to reset (a feed-forward policy)."""

    def act(self, obs: NDArray[np.float32], info: Mapping[str, Any]) -> NDArray[np.float64]:
        """The mean action, clipped to the action space (as SB3's ``predict``)."""
        p = self.policy
        x = self._torch.from_numpy(np.asarray(obs, dtype=np.float32).reshape(1, -1))
        with self._torch.inference_mode():
            features = p.extract_features(x, p.pi_features_extractor)
            mean = p.action_net(p.mlp_extractor.forward_actor(features))
        action = np.clip(mean.numpy().reshape(-1), self._low, self._high)
        return action.astype(np.float64)


def _obs_dim(scenario: str | None) -> int:
    """The width of the observation the policy is given (its scenario's LiDAR's)."""
    from pioneer.sim.lidar import OBS_DIM
    from pioneer.sim.scenarios import get_scenario

    return get_scenario(scenario).sim.lidar.obs_dim if scenario is not None else OBS_DIM


def make_sb3_policy(
    weights: str | None = None, scenario: str | None = None, name: str = "sb3-ppo"
) -> Sb3Policy:
    """Policy factory: the SB3 policy in ``weights`` (a ``policy.safetensors`` written by
    ``pioneer train sb3-ppo``; ``{scenario}`` is filled in), or the scenario's shipped one."""
    import gymnasium as gym
    import torch
    from stable_baselines3.common.policies import ActorCriticPolicy

    from pioneer.nn.checkpoint import load_checked, read_checkpoint

    if weights is None:
        if scenario is None:
            raise ConfigError(
                expect("sb3-ppo", "weights=FILE or a scenario", None, "pass scenario='hr-rl'")
            )
        from pioneer.data import shipped_sb3_weights

        p = shipped_sb3_weights(scenario)
    else:
        p = Path(weights.format(scenario=scenario) if scenario else weights)
    fix = "train one with `pioneer train sb3-ppo --out DIR` and pass weights=DIR/policy.safetensors"
    meta, arrays = read_checkpoint(p, SB3_FORMAT, "sb3-ppo weights", fix, fix, tensors=True)
    cfg = meta["config"]
    try:
        spaces = [
            gym.spaces.Box(
                np.array(cfg[k]["low"], dtype=np.float32),
                np.array(cfg[k]["high"], dtype=np.float32),
            )
            for k in ("observation_space", "action_space")
        ]
        policy = ActorCriticPolicy(
            spaces[0],
            spaces[1],
            lr_schedule=lambda _: 0.0,
            net_arch=cfg["net_arch"],
            activation_fn=getattr(torch.nn, cfg["activation_fn"]),
        )
    except (ValueError, KeyError, TypeError, AttributeError) as exc:
        raise DataError(expect(f"{p}: config", "an SB3 policy config", f"{exc}", fix)) from exc
    wanted = (_obs_dim(scenario),)
    if spaces[0].shape != wanted:
        raise DataError(expect(f"{p}: observation_space", f"shape {wanted}", spaces[0].shape, fix))
    load_checked(policy, arrays, p, f"SB3 MlpPolicy {cfg['net_arch']}", fix)
    policy.set_training_mode(False)
    torch.set_num_threads(1)
    return Sb3Policy(policy, name=name)
