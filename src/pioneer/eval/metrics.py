"""Aggregate episode records into the paper's metrics with 95 % confidence intervals.

Per scenario and policy, each metric gets a mean and a 95 % interval ``[lo, hi]``, computed
one of two ways (``"interval"`` in each summary entry says which):

- ``"seeds"`` — with :data:`MIN_SEEDS` or more seeds, as the paper reports: the metric is
  computed per seed (over that seed's trials), and the interval is Student's t over the
  seed values with n_seeds − 1 degrees of freedom (``ci95`` is its half-width);
- ``"episodes"`` — with fewer seeds, a t interval over seeds would be meaningless (two seeds
  give t(0.975, 1) = 12.7, an interval wider than 0–100 %), so the episodes are pooled: the
  rates get the Wilson score interval over episodes, the times, lengths and gaps a
  Student-t interval over episodes.

Either way the interval is clipped to the quantity's range (:data:`RANGES`), so no interval
exceeds it. The metrics:

- ``success_rate``, ``collision_rate``, ``timeout_rate`` [%];
- ``time_mean_s``, ``path_length_mean_m``: over successful episodes (the paper's TT and PL),
  and ``time_mean_all_s``, ``path_length_mean_all_m`` over all episodes;
- ``min_gap_m``: mean of each episode's minimum gap (surface to surface) to any human;
- ``time_close_s``: mean time per episode with a gap below 0.8 m.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Iterable, Mapping, Sequence
from typing import Any, Literal

import numpy as np
from scipy.stats import t as student_t

from pioneer.stats import wilson_interval

__all__ = ["METRICS", "MIN_SEEDS", "RANGES", "RATES", "interval_kind", "mean_ci", "summarize"]

RATES = ("success_rate", "collision_rate", "timeout_rate")
METRICS = (
    *RATES,
    "time_mean_s",
    "path_length_mean_m",
    "time_mean_all_s",
    "path_length_mean_all_m",
    "min_gap_m",
    "time_close_s",
)
RANGES: dict[str, tuple[float, float]] = {
    **{m: (0.0, 100.0) for m in RATES},  # [%]
    "time_mean_s": (0.0, math.inf),
    "path_length_mean_m": (0.0, math.inf),
    "time_mean_all_s": (0.0, math.inf),
    "path_length_mean_all_m": (0.0, math.inf),
    "min_gap_m": (-math.inf, math.inf),  # negative at a collision (overlap)
    "time_close_s": (0.0, math.inf),
}
MIN_SEEDS = 3  # fewer seeds: intervals over episodes instead of over seeds
_EVENT = {"success_rate": "success", "collision_rate": "collision", "timeout_rate": "timeout"}

IntervalKind = Literal["seeds", "episodes"]


def mean_ci(values: Iterable[float | None], level: float = 0.95) -> tuple[float, float]:
    """Mean and CI half-width (Student's t) of finite values; NaN mean if there are none,
    half-width 0 for a single value."""
    v = np.array([x for x in values if x is not None and math.isfinite(x)], dtype=np.float64)
    if v.size == 0:
        return float("nan"), float("nan")
    if v.size == 1:
        return float(v[0]), 0.0
    half = float(student_t.ppf(0.5 + level / 2, v.size - 1) * v.std(ddof=1) / math.sqrt(v.size))
    return float(v.mean()), half


def interval_kind(n_seeds: int) -> IntervalKind:
    """``"seeds"`` with :data:`MIN_SEEDS` or more seeds, else ``"episodes"``."""
    return "seeds" if n_seeds >= MIN_SEEDS else "episodes"


def _entry(metric: str, mean: float, half: float) -> dict[str, float]:
    """A symmetric interval ``mean ± half``, clipped to the metric's range."""
    low, high = RANGES[metric]
    if not math.isfinite(mean):
        return {"mean": mean, "ci95": half, "lo": math.nan, "hi": math.nan}
    return {
        "mean": mean,
        "ci95": half,
        "lo": max(low, mean - half),
        "hi": min(high, mean + half),
    }


def _episode_values(recs: Sequence[Mapping[str, Any]], metric: str) -> list[float | None]:
    """The per-episode values whose mean is ``metric`` (times and lengths of successes only
    for the paper's TT and PL)."""
    ok = [r for r in recs if r["event"] == "success"]
    source = {
        "time_mean_s": ("time_s", ok),
        "path_length_mean_m": ("path_length_m", ok),
        "time_mean_all_s": ("time_s", recs),
        "path_length_mean_all_m": ("path_length_m", recs),
        "min_gap_m": ("min_gap_m", recs),
        "time_close_s": ("time_close_s", recs),
    }
    key, rows = source[metric]
    return [r.get(key) for r in rows]


def _per_seed(recs: Sequence[Mapping[str, Any]]) -> dict[str, float]:
    n = len(recs)
    out = {m: 100.0 * sum(r["event"] == _EVENT[m] for r in recs) / n for m in RATES}
    for m in METRICS[len(RATES) :]:
        vals = [v for v in _episode_values(recs, m) if v is not None]
        out[m] = float(np.mean(vals)) if vals else float("nan")
    return out


def _over_seeds(by_seed: Mapping[int, list[Mapping[str, Any]]]) -> dict[str, dict[str, float]]:
    per_seed = [_per_seed(v) for _, v in sorted(by_seed.items())]
    return {m: _entry(m, *mean_ci(p[m] for p in per_seed)) for m in METRICS}


def _over_episodes(recs: Sequence[Mapping[str, Any]]) -> dict[str, dict[str, float]]:
    out: dict[str, dict[str, float]] = {}
    n = len(recs)
    for m in RATES:
        k = sum(r["event"] == _EVENT[m] for r in recs)
        lo, hi = wilson_interval(k, n)
        out[m] = {
            "mean": 100.0 * k / n,
            "ci95": 50.0 * (hi - lo),  # half the (asymmetric) interval's width
            "lo": 100.0 * lo,
            "hi": 100.0 * hi,
        }
    for m in METRICS[len(RATES) :]:
        out[m] = _entry(m, *mean_ci(_episode_values(recs, m)))
    return out


def summarize(records: Iterable[Mapping[str, Any]]) -> dict[str, dict[str, Any]]:
    """``{"<scenario>/<policy>": {"episodes", "seeds", "interval", metric: {"mean", "ci95",
    "lo", "hi"}, …}}``; ``interval`` is ``"seeds"`` or ``"episodes"`` (module docstring)."""
    groups: dict[tuple[str, str], dict[int, list[Mapping[str, Any]]]] = defaultdict(
        lambda: defaultdict(list)
    )
    for r in records:
        groups[(r["scenario"], r["policy"])][int(r["seed"])].append(r)
    out: dict[str, dict[str, Any]] = {}
    for (scen, pol), by_seed in sorted(groups.items()):
        kind = interval_kind(len(by_seed))
        pooled = [r for _, v in sorted(by_seed.items()) for r in v]
        entry: dict[str, Any] = {
            "scenario": scen,
            "policy": pol,
            "episodes": len(pooled),
            "seeds": len(by_seed),
            "interval": kind,
        }
        entry.update(_over_seeds(by_seed) if kind == "seeds" else _over_episodes(pooled))
        out[f"{scen}/{pol}"] = entry
    return out
