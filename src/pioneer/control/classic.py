"""Classical reference controllers. ``goal``: drive straight at the goal, ignoring people."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pioneer.control.policy import register_policy

__all__ = ["GoalPolicy"]


class GoalPolicy:
    """Pure go-to-goal: turn toward the goal bearing φ_g, drive when roughly facing it.

    ω = clip(k_ω φ_g, ±ω_max);  v = v_max · max(0, cos φ_g) · min(1, d_goal / d_slow).
    Uses only the observation's goal bearing and the goal distance from ``info``.
    """

    name = "goal"

    def __init__(
        self,
        v_max: float = 0.8,
        omega_max: float = 0.4 * math.pi,
        k_omega: float = 1.5,
        slow_distance: float = 0.5,
    ) -> None:
        self.v_max = v_max  # [m/s]
        self.omega_max = omega_max  # [rad/s]
        self.k_omega = k_omega  # [1/s]
        self.slow_distance = slow_distance  # [m]

    def reset(self, info: Mapping[str, Any], rng: np.random.Generator) -> None:
        """Stateless: nothing to reset."""

    def act(self, obs: NDArray[np.float32], info: Mapping[str, Any]) -> NDArray[np.float64]:
        """Command toward the goal."""
        bearing = float(obs[-1])
        d_goal = float(
            np.linalg.norm(np.asarray(info["goal"]) - np.asarray(info["robot_pose"])[:2])
        )
        w = float(np.clip(self.k_omega * bearing, -self.omega_max, self.omega_max))
        v = self.v_max * max(0.0, math.cos(bearing)) * min(1.0, d_goal / self.slow_distance)
        return np.array([v, w])


register_policy("goal", GoalPolicy)
