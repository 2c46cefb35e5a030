"""Graded demonstrations: a continuous fidelity γ ∈ (−1, 1) from each episode's quality.

The paper labels every demonstration ±1 and names graded labels as a limitation (§V-D); the
smooth leveraged kernel (eq. 9) takes any γ ∈ [−1, 1]. Here a positive episode's γ is its
quality q ∈ (0, 1], the product of three scores computed from the dataset's own columns:

- time: min(1, T_REF_S / T), the episode's duration against the paper teacher's (≈ 12 s,
  Table I); a fixed reference, since the last episode of a dataset may be cut short;
- margin: min(1, (d_min − r_robot) / MARGIN_REF_M), the closest raw beam range over the
  episode (to a person or a wall) less the robot's radius, against a comfortable margin;
- smoothness: 1 / (1 + mean |Δω| / SMOOTH_REF), the mean change of the angular command
  between consecutive frames.

A negative episode's γ is −(½ + ½ v_last / v_max): a collision at full speed is −1, one
while creeping is −½. Every γ is kept at least :data:`MIN_ABS_GAMMA` away from 0, so a
demonstration never stops counting.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from pioneer.limits import V_MAX
from pioneer.reward.dataset import Dataset
from pioneer.sim.robot import RobotConfig

__all__ = ["MARGIN_REF_M", "MIN_ABS_GAMMA", "SMOOTH_REF", "TIME_REF_S", "graded_gamma"]

TIME_REF_S = 12.0  # [s] the paper's teacher reaches its goal in 12.2–12.9 s (Table I)
MARGIN_REF_M = 0.3  # [m] a margin this large (beyond the robot's radius) scores 1
SMOOTH_REF = 0.1  # [rad/s] mean |Δω| per frame that halves the smoothness score
MIN_ABS_GAMMA = 0.05
_D1 = 24  # column of d_1, the nearest raw beam range, in the 29-D observation


def graded_gamma(d: Dataset) -> NDArray[np.float64]:
    """Per-row γ graded by the quality of its episode (module docstring)."""
    gamma = np.empty(len(d))
    for e in np.unique(d.episode):
        rows = d.episode == e
        if d.gamma[rows][0] > 0:
            t = d.time[rows]
            q_time = min(1.0, TIME_REF_S / (float(t.max() - t.min()) + _dt(t)))
            margin = float(d.obs[rows, _D1].min()) - RobotConfig().radius
            q_margin = float(np.clip(margin / MARGIN_REF_M, 0.0, 1.0))
            omega = d.action[rows, 1]
            jerk = float(np.abs(np.diff(omega)).mean()) if omega.size > 1 else 0.0
            q_smooth = 1.0 / (1.0 + jerk / SMOOTH_REF)
            gamma[rows] = max(MIN_ABS_GAMMA, q_time * q_margin * q_smooth)
        else:
            order = np.argsort(d.time[rows])
            v_last = float(d.action[rows, 0][order[-1]])
            gamma[rows] = -(0.5 + 0.5 * float(np.clip(v_last / V_MAX, 0.0, 1.0)))
    return gamma


def _dt(t: NDArray[np.float64]) -> float:
    """The frame period of an episode's times (0.1 s in the paper world)."""
    if t.size < 2:
        return 0.1
    return float(np.median(np.diff(np.sort(t))))
