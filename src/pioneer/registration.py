"""Gymnasium ids of the PioneeR environments.

They are registered by entry-point string, so ``import pioneer`` makes ``gymnasium.make`` and
``gymnasium.make_vec`` (the native :class:`~pioneer.envs.vector.NavVectorEnv`, through the
``vector_entry_point``) work without loading the simulator (or numba) until an environment is
made — and the robot-side runtime (:mod:`pioneer.deploy`) stays light.
"""

from __future__ import annotations

import gymnasium as gym

__all__ = ["ENV_IDS", "register_envs"]

ENV_IDS = {
    "pioneer/ElevatorHRRL-v1": "hr-rl",
    "pioneer/ElevatorHLRR-v1": "hl-rr",
    "pioneer/StaticStudy-v1": "static",
}


def register_envs() -> None:
    """Register the PioneeR environment ids with Gymnasium (idempotent)."""
    for env_id, name in ENV_IDS.items():
        if env_id not in gym.registry:
            gym.register(
                id=env_id,
                entry_point="pioneer.envs.env:NavEnv",
                vector_entry_point="pioneer.envs.vector:NavVectorEnv",
                kwargs={"scenario": name},
            )
