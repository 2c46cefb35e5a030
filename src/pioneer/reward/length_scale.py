"""Choosing the density reward's length scale by validation on the positive/negative split."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pioneer.errors import DataError, expect
from pioneer.reward.density import DensityConfig, DensityReward
from pioneer.stats import auroc

__all__ = ["episode_split", "select_length_scale"]


def episode_split(
    episode: NDArray[np.int64], val_fraction: float, rng: np.random.Generator
) -> NDArray[np.bool_]:
    """A validation mask holding out whole episodes (no frame of an episode on both sides)."""
    eps = np.unique(episode)
    n_val = max(1, round(val_fraction * eps.size))
    val_eps = rng.choice(eps, size=n_val, replace=False)
    return np.isin(episode, val_eps)


def select_length_scale(
    features: NDArray[np.float64],
    gamma: NDArray[np.float64],
    episode: NDArray[np.int64],
    config: DensityConfig | None = None,
    factors: tuple[float, ...] = (0.25, 0.5, 1.0, 2.0),
    val_fraction: float = 0.3,
) -> tuple[float, list[dict[str, Any]]]:
    """Pick l among ``factors`` × the median-distance default by held-out AUROC (pos vs neg).

    Whole episodes are held out. Returns the chosen length scale (standardised units) and one
    record per candidate.
    """
    cfg = config or DensityConfig()
    rng = np.random.default_rng(cfg.seed)
    for _ in range(20):
        val = episode_split(episode, val_fraction, rng)
        if (gamma[val] > 0).any() and (gamma[val] < 0).any() and (~val).sum() > 1:
            break
    else:
        raise DataError(
            expect(
                "select_length_scale",
                "positives and negatives in held-out episodes",
                "none",
                "add negative demos",
            )
        )
    base = DensityReward(cfg).fit(features[~val], gamma[~val])
    records = []
    for f in factors:
        length = base.length_ * f
        m = DensityReward(dataclasses.replace(cfg, length_scale=length)).fit(
            features[~val], gamma[~val]
        )
        score = auroc(m(features[val]), gamma[val] > 0)
        records.append({"factor": f, "length_scale": length, "val_auroc": score})
    best = max(records, key=lambda r: (r["val_auroc"], -abs(np.log(r["factor"]))))
    return float(best["length_scale"]), records
