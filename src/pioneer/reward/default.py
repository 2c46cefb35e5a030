"""The teacher's default density reward: fitted on the shipped demonstrations of a scenario."""

from __future__ import annotations

import functools

from pioneer.data import base_scenario, shipped_demos
from pioneer.reward.dataset import Dataset
from pioneer.reward.density import DensityReward
from pioneer.reward.features import default_feature_map, feature_map

__all__ = ["default_features", "default_reward"]


@functools.lru_cache(maxsize=8)
def default_reward(scenario: str) -> DensityReward:
    """The density reward fitted on the shipped demos of ``scenario`` (cached per process)."""
    d = Dataset.load(shipped_demos(scenario))
    fm = feature_map(default_features(scenario))
    model = DensityReward().fit(fm.from_dataset(d), d.gamma, list(fm.names))
    model.info_.update({"demos": f"shipped:{base_scenario(scenario)}", "features": fm.name})
    return model


def default_features(scenario: str) -> str:
    """``xy`` for the static study, ``obs_action`` for the elevator scenarios (a variant is
    judged by the built-in scenario whose demos it uses)."""
    return default_feature_map([base_scenario(scenario)])
