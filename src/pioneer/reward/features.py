"""Reward features z of a state–action pair (SPEC 2): one definition for the demonstrations
(dataset rows) and the teacher's rollouts.

``xy`` is the robot's position (the static study, paper Sec. IV-A); ``obs_action`` is the
29-D observation (SPEC 1.4) followed by the command (v, ω), z ∈ R^31 (the elevator).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from pioneer.errors import DataError, expect
from pioneer.reward.dataset import Dataset
from pioneer.sim.lidar import observation_names

__all__ = ["FEATURE_MAPS", "FeatureMap", "default_feature_map", "feature_map"]

FEATURE_MAPS = ("xy", "obs_action")


@dataclasses.dataclass(frozen=True)
class FeatureMap:
    """Turns (pose, observation, action) rows into reward features z."""

    name: str  # "xy" (static study) or "obs_action" (elevator, R^31)
    names: tuple[str, ...]

    def from_arrays(
        self, xy: NDArray[np.floating], obs: NDArray[np.floating], action: NDArray[np.floating]
    ) -> NDArray[np.float64]:
        """Features of N rows, ``(N, D)``, from positions ``(N, 2)`` [m], observations
        ``(N, 29)`` and actions ``(N, 2)`` (only the columns the map uses are read)."""
        if self.name == "xy":
            return np.asarray(xy, dtype=np.float64)
        return np.concatenate([obs.astype(np.float64), action], axis=1)

    def from_rollout(
        self, robot: NDArray[np.floating], obs: NDArray[np.floating], commands: NDArray[np.floating]
    ) -> NDArray[np.float64]:
        """Features of every rollout state, ``(C·L, D)``, from poses ``(C, L, 3)``, observations
        ``(C, L, 29)`` and each candidate's constant command ``(C, 2)``."""
        c, n_l = robot.shape[:2]
        return self.from_arrays(
            robot[:, :, :2].reshape(c * n_l, 2),
            obs.reshape(c * n_l, -1),
            np.repeat(commands, n_l, axis=0),
        )

    def from_dataset(self, d: Dataset) -> NDArray[np.float64]:
        """Features of every row, ``(N, D)``."""
        return self.from_arrays(d.pose[:, :2], d.obs, d.action)


def feature_map(name: str) -> FeatureMap:
    """``xy`` → (x, y); ``obs_action`` → (o, u) ∈ R^31."""
    if name == "xy":
        return FeatureMap("xy", ("x", "y"))
    if name == "obs_action":
        return FeatureMap("obs_action", (*observation_names(), "v", "omega"))
    raise DataError(expect("feature map", f"one of {list(FEATURE_MAPS)}", name, "pick one"))


def default_feature_map(scenarios: Sequence[str]) -> str:
    """``xy`` when every scenario is the static study, else ``obs_action`` (the elevator)."""
    return "xy" if scenarios and all(s.startswith("static") for s in scenarios) else "obs_action"
