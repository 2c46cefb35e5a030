"""Aggregate episode records into the paper's metrics with 95% confidence intervals (SPEC 7).

Per scenario and policy, every metric is computed per seed (over that seed's trials), then
reported as the mean over seeds with a 95% confidence interval from Student's t with
n_seeds − 1 degrees of freedom (half-width; 0 with a single seed).

- ``success_rate``, ``collision_rate``, ``timeout_rate`` [%];
- ``time_mean_s``, ``path_length_mean_m``: over successful episodes (the paper's TT and PL),
  and ``time_mean_all_s``, ``path_length_mean_all_m`` over all episodes;
- ``min_clearance_m``: mean of each episode's minimum clearance to any human;
- ``time_close_s``: mean time per episode with clearance below 0.8 m.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np
from scipy.stats import t as student_t

__all__ = ["METRICS", "mean_ci", "summarize"]

METRICS = (
    "success_rate",
    "collision_rate",
    "timeout_rate",
    "time_mean_s",
    "path_length_mean_m",
    "time_mean_all_s",
    "path_length_mean_all_m",
    "min_clearance_m",
    "time_close_s",
)


def mean_ci(values: Iterable[float], level: float = 0.95) -> tuple[float, float]:
    """Mean and CI half-width (Student's t) of finite values; NaN mean if there are none."""
    v = np.array([x for x in values if x is not None and math.isfinite(x)], dtype=np.float64)
    if v.size == 0:
        return float("nan"), float("nan")
    if v.size == 1:
        return float(v[0]), 0.0
    half = float(student_t.ppf(0.5 + level / 2, v.size - 1) * v.std(ddof=1) / math.sqrt(v.size))
    return float(v.mean()), half


def _per_seed(recs: list[Mapping[str, Any]]) -> dict[str, float]:
    n = len(recs)
    ok = [r for r in recs if r["event"] == "success"]

    def avg(key: str, rows: list[Mapping[str, Any]]) -> float:
        vals = [r[key] for r in rows if r.get(key) is not None]
        return float(np.mean(vals)) if vals else float("nan")

    return {
        "success_rate": 100.0 * len(ok) / n,
        "collision_rate": 100.0 * sum(r["event"] == "collision" for r in recs) / n,
        "timeout_rate": 100.0 * sum(r["event"] == "timeout" for r in recs) / n,
        "time_mean_s": avg("time_s", ok),
        "path_length_mean_m": avg("path_length_m", ok),
        "time_mean_all_s": avg("time_s", recs),
        "path_length_mean_all_m": avg("path_length_m", recs),
        "min_clearance_m": avg("min_clearance_m", recs),
        "time_close_s": avg("time_close_s", recs),
    }


def summarize(records: Iterable[Mapping[str, Any]]) -> dict[str, dict[str, Any]]:
    """``{"<scenario>/<policy>": {"episodes", "seeds", metric: {"mean", "ci95"}, …}}``."""
    groups: dict[tuple[str, str], dict[int, list[Mapping[str, Any]]]] = defaultdict(
        lambda: defaultdict(list)
    )
    for r in records:
        groups[(r["scenario"], r["policy"])][int(r["seed"])].append(r)
    out: dict[str, dict[str, Any]] = {}
    for (scen, pol), by_seed in sorted(groups.items()):
        per_seed = [_per_seed(v) for _, v in sorted(by_seed.items())]
        entry: dict[str, Any] = {
            "scenario": scen,
            "policy": pol,
            "episodes": sum(len(v) for v in by_seed.values()),
            "seeds": len(by_seed),
        }
        for m in METRICS:
            mean, ci = mean_ci(p[m] for p in per_seed)
            entry[m] = {"mean": mean, "ci95": ci}
        out[f"{scen}/{pol}"] = entry
    return out
