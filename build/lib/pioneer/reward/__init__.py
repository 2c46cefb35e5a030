"""The learned density reward and the rule-based terms of the teacher's score."""

from pioneer.reward.density import DensityConfig, DensityReward
from pioneer.reward.kernels import se_kernel, sl_kernel
from pioneer.reward.rules import RuleWeights, adaptive_weights, combine, goal_term, obstacle_term

__all__ = [
    "DensityConfig",
    "DensityReward",
    "RuleWeights",
    "adaptive_weights",
    "combine",
    "goal_term",
    "obstacle_term",
    "se_kernel",
    "sl_kernel",
]
