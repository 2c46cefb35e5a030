"""Reward features z of a state–action pair (paper §IV-A.1): one definition for the demonstrations
(dataset rows) and the teacher's rollouts.

``xy`` is the robot's position (the static study, paper §V-A); ``obs_action`` is the
29-D observation (paper eq. 2) followed by the command (v, ω), z ∈ R^31 (the elevator);
``obs_action_sincos`` encodes each of the three bearings φ_1, φ_2, φ_g as (cos φ, sin φ), so
that a bearing just past −π and one just short of π are near neighbours, z ∈ R^34.
"""

from __future__ import annotations

import dataclasses
import typing
from collections.abc import Sequence
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from pioneer.errors import DataError, expect
from pioneer.reward.dataset import Dataset
from pioneer.sim.lidar import observation_names

__all__ = ["FEATURE_MAPS", "FeatureMap", "FeatureName", "default_feature_map", "feature_map"]

FeatureName = Literal["xy", "obs_action", "obs_action_sincos"]
FEATURE_MAPS: tuple[str, ...] = typing.get_args(FeatureName)
_ANGLES = slice(26, 29)  # φ_1, φ_2, φ_g in the 29-D observation


@dataclasses.dataclass(frozen=True)
class FeatureMap:
    """Turns (pose, observation, action) rows into reward features z."""

    name: FeatureName  # "xy" (static study), "obs_action" (elevator, R^31) or its sincos form
    names: tuple[str, ...]

    def from_arrays(
        self, xy: NDArray[np.floating], obs: NDArray[np.floating], action: NDArray[np.floating]
    ) -> NDArray[np.float64]:
        """Features of N rows, ``(N, D)``, from positions ``(N, 2)`` [m], observations
        ``(N, 29)`` and actions ``(N, 2)`` (only the columns the map uses are read)."""
        if self.name == "xy":
            return np.asarray(xy, dtype=np.float64)
        o = obs.astype(np.float64)
        if self.name == "obs_action_sincos":
            phi = o[:, _ANGLES]
            trig = np.stack([np.cos(phi), np.sin(phi)], axis=2).reshape(len(o), -1)
            return np.concatenate([o[:, : _ANGLES.start], trig, action], axis=1)
        return np.concatenate([o, action], axis=1)

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
    """``xy`` → (x, y); ``obs_action`` → (o, u) ∈ R^31; ``obs_action_sincos`` → R^34."""
    if name == "xy":
        return FeatureMap("xy", ("x", "y"))
    if name == "obs_action":
        return FeatureMap("obs_action", (*observation_names(), "v", "omega"))
    if name == "obs_action_sincos":
        names = observation_names()
        trig = [f"{f}_{a}" for a in names[_ANGLES] for f in ("cos", "sin")]
        return FeatureMap("obs_action_sincos", (*names[: _ANGLES.start], *trig, "v", "omega"))
    raise DataError(expect("feature map", f"one of {list(FEATURE_MAPS)}", name, "pick one"))


def default_feature_map(scenarios: Sequence[str]) -> str:
    """``xy`` when every scenario is the static study, else ``obs_action`` (the elevator)."""
    return "xy" if scenarios and all(s.startswith("static") for s in scenarios) else "obs_action"
