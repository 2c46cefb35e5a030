"""Rule-based terms and the distance-adaptive weights of the teacher's score (paper §IV-A.2).

For a batch of rollouts (leading axis = candidate), with d_goal the distance from the rollout's
final position x_L to the goal and d_total the initial start–goal distance:

    R_goal = 1 − tanh(d_goal / d_total)                                   (paper eq. 15)
    R_obs  = tanh(mean_ℓ d_ℓ),  d_ℓ = min(d_ℓ,1, d_ℓ,2) from the observation   (eq. 16)
    r = clip(d_goal / d_total, 0, 1)                                           (eq. 17)
    α_den = 1 + cos(π (1 − r)),  α_goal = 2 (1 − r),  α_obs = 1                (eq. 18)
    R = α_den R_den + α_goal R_goal + α_obs R_obs                              (eq. 13)

Every term can be switched off (paper Table II ablation) and every weight overridden.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import NDArray

from pioneer.config import Config
from pioneer.laser import LidarConfig

__all__ = ["RuleWeights", "adaptive_weights", "combine", "goal_term", "obstacle_term"]

F64 = NDArray[np.float64]

D1_INDEX = LidarConfig().n_sectors  # observation index of d_1 (then d_2), paper eq. 2: 24


def goal_term(d_goal: F64, d_total: F64 | float) -> F64:
    """R_goal = 1 − tanh(d_goal / d_total) for final distances ``(C,)``."""
    return 1.0 - np.tanh(np.asarray(d_goal) / np.maximum(d_total, 1e-9))


def obstacle_term(obs_rollout: NDArray[np.floating], n_nearest: int = LidarConfig.n_nearest) -> F64:
    """R_obs = tanh(mean_ℓ min_i d_ℓ,i) for observation rollouts ``(C, L, 29)``."""
    d = np.asarray(obs_rollout)[..., D1_INDEX : D1_INDEX + n_nearest].min(axis=-1)
    return np.tanh(d.mean(axis=-1).astype(np.float64))


def adaptive_weights(d_goal: F64, d_total: F64 | float) -> tuple[F64, F64, F64]:
    """(α_den, α_goal, α_obs) for final distances ``(C,)`` (eq. 18)."""
    r = np.clip(np.asarray(d_goal) / np.maximum(d_total, 1e-9), 0.0, 1.0)
    return 1.0 + np.cos(np.pi * (1.0 - r)), 2.0 * (1.0 - r), np.ones_like(r)


@dataclasses.dataclass(frozen=True)
class RuleWeights(Config):
    """Switches and overrides for the three terms; ``None`` = the adaptive weight."""

    use_density: bool = True
    use_goal: bool = True
    use_obstacle: bool = True
    density_weight: float | None = None
    goal_weight: float | None = None
    obstacle_weight: float | None = None


def combine(
    r_den: F64, r_goal: F64, r_obs: F64, d_goal: F64, d_total: F64 | float, w: RuleWeights
) -> tuple[F64, dict[str, F64]]:
    """Total score ``(C,)`` and the weighted per-term contributions."""
    a_den, a_goal, a_obs = adaptive_weights(d_goal, d_total)
    a_den = a_den if w.density_weight is None else np.full_like(a_den, w.density_weight)
    a_goal = a_goal if w.goal_weight is None else np.full_like(a_goal, w.goal_weight)
    a_obs = a_obs if w.obstacle_weight is None else np.full_like(a_obs, w.obstacle_weight)
    terms = {
        "density": a_den * r_den * float(w.use_density),
        "goal": a_goal * r_goal * float(w.use_goal),
        "obstacle": a_obs * r_obs * float(w.use_obstacle),
    }
    return terms["density"] + terms["goal"] + terms["obstacle"], terms
