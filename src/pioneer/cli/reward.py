"""``pioneer reward fit|show`` (the learned density reward) and ``pioneer study static``
(paper Fig. 3, the reward on the synthetic static study).

The fit's options are the ``RewardRecipe`` it follows, with its ``DensityConfig``, nested as a
group of flags (flags, defaults, bounds and help from the configs).
"""

from __future__ import annotations

import dataclasses
import sys
from typing import TYPE_CHECKING, Annotated, Any

import tyro

from pioneer.cli._files import InFile, Input, OutDir, OutFile
from pioneer.cli._options import Flag, optional
from pioneer.cli._parse import config_flags
from pioneer.data import DEMOS_DIR
from pioneer.errors import ConfigError, DataError, expect
from pioneer.io import to_json
from pioneer.reward.density import DensityConfig
from pioneer.reward.features import FEATURE_MAPS
from pioneer.reward.recipe import RewardRecipe

if TYPE_CHECKING:
    from pioneer.reward.density import DensityReward

__all__ = ["RewardFit", "RewardShow", "StudyStatic"]

# mirror: set by --mirror-demos (the mirror scenario's dataset)
config_flags(
    RewardRecipe,
    mirror=None,
    features=optional("{" + ",".join(FEATURE_MAPS) + "}", "by scenario"),
)
config_flags(DensityConfig, length_scale=optional("L", "the median heuristic"))


@dataclasses.dataclass(frozen=True)
class RewardFit:
    """Fit the density reward on a dataset and save the model (.npz); prints a summary."""

    demos: InFile
    """the dataset (.npz)"""
    out: OutFile
    """output model .npz"""
    recipe: tyro.conf.OmitArgPrefixes[RewardRecipe] = RewardRecipe()
    """how the reward is made from the demonstrations"""
    select_length: Flag = False
    """pick l by held-out AUROC"""
    min_gamma: Annotated[float | None, optional("G", "keep all")] = None
    """drop samples with γ below this"""
    mirror_demos: Annotated[
        str | None, optional("FILE", "no mirror augmentation"), Input("file")
    ] = None
    """the mirror scenario's dataset (.npz), added mirrored (hl-rr's for hr-rl)"""
    allow_one_sided: Flag = False
    """fit a dataset without positives or without negatives (a warning instead of a refusal)"""
    overwrite: Flag = False
    """replace an existing --out (otherwise refused: a file you made is never replaced)"""

    def run(self) -> int:
        """Fit (selecting l if asked) and save."""
        from pioneer.reward.dataset import Dataset
        from pioneer.reward.features import default_feature_map, feature_map
        from pioneer.reward.length_scale import select_length_scale
        from pioneer.reward.recipe import fit_reward

        self._check_min_gamma()
        d = Dataset.load(self.demos)
        if self.min_gamma is not None:
            kept = d.filter(min_gamma=self.min_gamma)
            lost = kept.one_sided() is not None and d.one_sided() is None  # the flag's doing
            if lost and (not self.allow_one_sided or len(kept) == 0):
                raise ConfigError(
                    expect(
                        "--min-gamma",
                        "a threshold that keeps positive and negative samples",
                        f"{self.min_gamma} (keeps {kept.n_positive} positive, "
                        f"{kept.n_negative} negative of {len(d)})",
                        "lower it so that samples of both signs remain, drop it, or pass "
                        "--allow-one-sided",
                    )
                )
            d = kept
        lacking = d.one_sided()
        if lacking is not None:
            what = f"{self.demos}: labels"
            got = f"{lacking} ({d.n_positive} positive, {d.n_negative} negative)"
            if not self.allow_one_sided or len(d) == 0:
                fix = "add demonstrations of the other kind, or pass --allow-one-sided"
                raise DataError(expect(what, "positive and negative samples", got, fix))
            print(
                f"pioneer: warning: {what}: {got}; the reward cannot contrast them (Eq. 1)",
                file=sys.stderr,
            )
        mirror = Dataset.load(self.mirror_demos) if self.mirror_demos else None
        fm = feature_map(self.recipe.features or default_feature_map(d.scenarios))
        cfg = self.recipe.density
        records = None
        if self.select_length:
            z = fm.from_dataset(d)
            length, records = select_length_scale(z, d.gamma, d.episode, cfg)
            cfg = cfg.replace(length_scale=length)
        recipe = self.recipe.replace(mirror=mirror is not None, features=fm.name, density=cfg)
        model = fit_reward(d, recipe, mirror)
        model.info_["demos"] = str(self.demos)
        if mirror is not None:
            model.info_["mirror_demos"] = str(self.mirror_demos)
        if records is not None:
            model.info_["length_selection"] = records
        model.save(self.out)
        fitted = {"length_scale": model.length_, "scale": model.scale_, "n_train": model.n_train_}
        print(to_json({"out": self.out, **fitted, **model.info_}))
        return 0

    def _check_min_gamma(self) -> None:
        """γ lies in [−1, 1]: a threshold outside it is the flag's mistake, not the data's."""
        g = self.min_gamma
        if g is not None and not -1.0 <= g <= 1.0:
            raise ConfigError(
                expect("--min-gamma", "a number in [-1, 1] (γ's range)", g, "pick one in [-1, 1]")
            )


@dataclasses.dataclass(frozen=True)
class RewardShow:
    """The summary of a fitted model, scored on a dataset (JSON)."""

    model: InFile
    """the fitted model (.npz)"""
    demos: Annotated[str | None, optional("FILE", "the training set"), Input("file")] = None
    """dataset to score"""

    def run(self) -> int:
        """Load, score and print."""
        from pioneer.reward.density import DensityReward

        m = DensityReward.load(self.model)
        out: dict[str, Any] = {
            "model": self.model,
            "features": m.info_.get("features", "?"),
            "feature_dim": len(m.feature_names),
            "n_train": m.n_train_,
            "n_inducing": int(m.alpha_.shape[0]) if m.alpha_ is not None else 0,
            "length_scale": m.length_,
            "scale": m.scale_,
            "hyperparameters": m.config.to_dict(),
        }
        demos = self.demos or m.info_.get("demos")
        if demos:
            out.update(_scores(m, str(demos)))
        print(to_json(out, indent=2))
        return 0


def _scores(m: DensityReward, demos: str) -> dict[str, Any]:
    """Mean reward of the positives and the negatives of ``demos``, and the AUROC between."""
    import numpy as np

    from pioneer.reward.dataset import Dataset
    from pioneer.reward.features import default_feature_map, feature_map
    from pioneer.stats import auroc

    d = Dataset.load(demos)
    fm = feature_map(str(m.info_.get("features", default_feature_map(d.scenarios))))
    r = m(fm.from_dataset(d))
    pos, neg = d.gamma > 0, d.gamma < 0
    return {
        "demos": demos,
        "reward_positive_mean": float(np.mean(r[pos])) if pos.any() else None,
        "reward_negative_mean": float(np.mean(r[neg])) if neg.any() else None,
        "auroc_pos_vs_neg": auroc(r[pos | neg], pos[pos | neg]),
    }


@dataclasses.dataclass(frozen=True)
class StudyStatic:
    """The synthetic static study (paper Fig. 3): rewards fitted on positives only and on
    positives + negatives, and teacher runs; prints the summary (JSON)."""

    out: OutDir
    """output folder"""
    demos: InFile = str(DEMOS_DIR / "static.npz")
    """static-study demos"""

    def run(self) -> int:
        """Run the study."""
        from pioneer.experiments.static_study import run_static_study
        from pioneer.reward.dataset import Dataset

        summary = run_static_study(Dataset.load(self.demos), self.out)
        print(to_json(summary, indent=2))
        return 0
