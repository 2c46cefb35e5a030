"""How a density reward is made from demonstrations, and the teacher's default one.

:class:`RewardRecipe` names every choice between the demonstrations and the fitted model —
the fidelities (the ±1 labels or graded by quality), mirror augmentation, the feature map and
the density's hyperparameters — and :func:`fit_reward` applies it. ``pioneer reward fit``
takes the same options, so every setting compared on validation seeds (docs/reward.md) is a
command. :func:`default_reward` fits a scenario's shipped demonstrations with
:data:`DEFAULT_RECIPE` (the paper world's elevator scenarios) or :data:`PLAIN_RECIPE` (the
compact world, kept as it was so its results reproduce, and the static study).
"""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path
from typing import Literal

from pioneer.config import Config
from pioneer.data import base_scenario, shipped_demos
from pioneer.errors import DataError, expect
from pioneer.reward.dataset import Dataset
from pioneer.reward.density import DensityConfig, DensityReward
from pioneer.reward.features import (
    FEATURE_MAPS,
    FeatureName,
    default_feature_map,
    feature_map,
)
from pioneer.reward.grading import graded_gamma

__all__ = [
    "DEFAULT_RECIPE",
    "MIRROR_OF",
    "PLAIN_RECIPE",
    "RewardRecipe",
    "check_reward_fits",
    "default_features",
    "default_reward",
    "default_reward_demos",
    "fit_reward",
]

# The scenario whose demonstrations, mirrored, are this one's (the paper world is symmetric).
MIRROR_OF = {"hr-rl": "hl-rr", "hl-rr": "hr-rl"}


@dataclasses.dataclass(frozen=True)
class RewardRecipe(Config):
    """Every choice from demonstrations to a fitted density reward."""

    # the demos' ±1 labels, or γ graded by each episode's quality (time, margin, smoothness;
    # pioneer.reward.grading)
    gamma: Literal["labels", "graded"] = "labels"
    mirror: bool = False  # add the mirror scenario's demonstrations, mirrored
    features: FeatureName | None = None  # the feature map (None: by scenario)
    density: DensityConfig = DensityConfig()  # the density model's hyperparameters


# Chosen on validation seeds (docs/reward.md, "Settings chosen on validation seeds"): the
# other scenario's demonstrations mirrored in, the bearings as (cos, sin), 300 k-means
# inducing points (as good as all 1,758 rows, and the teacher's density costs a sixth).
DEFAULT_RECIPE = RewardRecipe(
    mirror=True, features="obs_action_sincos", density=DensityConfig(max_inducing=300)
)
PLAIN_RECIPE = RewardRecipe()  # ±1 labels, no mirror: the compact world and the static study


def fit_reward(
    demos: Dataset, recipe: RewardRecipe, mirror_demos: Dataset | None = None
) -> DensityReward:
    """The density reward of ``demos`` (plus ``mirror_demos`` mirrored, when the recipe
    mirrors) made as ``recipe`` says."""
    d = demos
    if recipe.mirror:
        if mirror_demos is None:
            raise DataError(
                expect(
                    "mirror augmentation",
                    "the mirror scenario's demonstrations",
                    None,
                    "pass them (--mirror-demos), or fit without mirroring",
                )
            )
        d = Dataset.merge([demos, mirror_demos.mirrored()])
    if recipe.gamma == "graded":
        d = d.with_gamma(graded_gamma(d))
    fm = feature_map(recipe.features or default_feature_map(demos.scenarios))
    model = DensityReward(recipe.density).fit(fm.from_dataset(d), d.gamma, list(fm.names))
    model.info_.update(
        {"features": fm.name, "gamma": recipe.gamma, "mirror": recipe.mirror, "rows": len(d)}
    )
    return model


def _default_recipe(scenario: str) -> RewardRecipe:
    return DEFAULT_RECIPE if base_scenario(scenario) in MIRROR_OF else PLAIN_RECIPE


def default_reward_demos(scenario: str) -> dict[str, Path]:
    """The shipped files :func:`default_reward` fits for ``scenario``: ``{"demos": …}`` and,
    when its recipe mirrors, ``{"mirror_demos": …}`` (what a run records it loaded)."""
    files = {"demos": shipped_demos(scenario)}
    if _default_recipe(scenario).mirror:
        files["mirror_demos"] = shipped_demos(MIRROR_OF[base_scenario(scenario)])
    return files


@functools.lru_cache(maxsize=8)
def default_reward(scenario: str) -> DensityReward:
    """The density reward fitted on the shipped demos of ``scenario`` (cached per process)."""
    files = default_reward_demos(scenario)
    mirror = Dataset.load(files["mirror_demos"]) if "mirror_demos" in files else None
    model = fit_reward(Dataset.load(files["demos"]), _default_recipe(scenario), mirror)
    model.info_["demos"] = f"shipped:{base_scenario(scenario)}"
    return model


def check_reward_fits(model: DensityReward, scenario: str, where: str) -> str:
    """The feature map the teacher of ``scenario`` evaluates ``model`` with (the model's own,
    else the scenario's default), after checking that the model fits it: for a scenario of a
    known family — a built-in one, or a variant with a built-in ``base`` — a reward on the
    static study's (x, y) plane cannot score an elevator rollout, nor an elevator reward a
    static one; and the model's width must be its feature map's. Raises :class:`DataError`
    naming ``where`` (the model file)."""
    own = model.info_.get("features")
    wanted = default_features(scenario)
    name = str(own) if own is not None else wanted
    fix = f"fit a reward on {scenario}'s demonstrations (pioneer reward fit) and pass that"
    if name not in FEATURE_MAPS:
        raise DataError(
            expect(f"reward model {where}", f"features of one of {FEATURE_MAPS}", name, fix)
        )
    if _known_family(scenario) and (name == "xy") != (wanted == "xy"):
        fitted = "the static study's (x, y) position" if name == "xy" else f"{name} (elevator)"
        needed = "the (x, y) position" if wanted == "xy" else "the observation and command"
        raise DataError(
            expect(f"reward model {where}", f"features of {needed} for {scenario}", fitted, fix)
        )
    width = len(feature_map(name).names)
    if len(model.feature_names) != width:
        raise DataError(
            expect(
                f"reward model {where}",
                f"{width} features ({name})",
                f"{len(model.feature_names)} features",
                fix,
            )
        )
    return name


def _known_family(scenario: str) -> bool:
    """Whether ``scenario`` is a static study or an elevator by its base's shipped demos (a
    variant registered without a base is a world of its own: its reward is the caller's)."""
    try:
        shipped_demos(scenario)
    except DataError:
        return False
    return True


def default_features(scenario: str) -> str:
    """``xy`` for the static study, ``obs_action`` for the elevator scenarios (a variant is
    judged by the built-in scenario whose demos it uses)."""
    return default_feature_map([base_scenario(scenario)])
