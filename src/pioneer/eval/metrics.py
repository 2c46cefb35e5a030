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
- ``time_close_s``: mean time per episode with a gap below 0.8 m;
- the social-navigation measures of :data:`MEASURES` (docs/metrics.md), from each record's
  ``measures`` (:mod:`pioneer.eval.social`): rates of episodes [%] (collisions by kind,
  failures to progress) and means of per-episode values. A record written before the
  measures (format < 3) has none: it counts for the paper's metrics only, and ``measured``
  in each entry says how many episodes the measures are over (a group without any: NaN).
"""

from __future__ import annotations

import dataclasses
import math
from collections import defaultdict
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any, Literal

import numpy as np
from scipy.stats import t as student_t

from pioneer.stats import wilson_interval

__all__ = [
    "ALL_METRICS",
    "MEASURES",
    "MEASURE_LIST",
    "METRICS",
    "MIN_SEEDS",
    "RANGES",
    "RATES",
    "Measure",
    "interval_kind",
    "mean_ci",
    "summarize",
]

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


@dataclasses.dataclass(frozen=True)
class Measure:
    """A summary metric of the social-navigation measures: a rate of episodes [%] whose
    ``measures`` pass ``test``, or the mean of the per-episode value ``measures[key]``."""

    key: str  # the summary key (= the record's measures key for a mean)
    low: float  # the quantity's range (intervals are clipped to it)
    high: float
    successes_only: bool = False  # a mean over successful episodes only (like TT and PL)
    test: Callable[[Mapping[str, Any]], bool] | None = None  # a rate: which episodes count
    # a rate of a measure added later: records whose measures lack this key are left out
    since_key: str | None = None

    @property
    def is_rate(self) -> bool:
        """Whether the metric is a rate of episodes [%]."""
        return self.test is not None


_ROLES = ("exiting", "boarding")
_INF = math.inf
MEASURE_LIST: tuple[Measure, ...] = (
    # collisions by kind [% of episodes]; a collision touching a wall and a person counts twice
    Measure("wall_collision_rate", 0.0, 100.0, test=lambda m: m.get("wall_hit") is True),
    Measure(
        "robot_into_person_rate",
        0.0,
        100.0,
        test=lambda m: m.get("person_hit") == "robot-into-person",
    ),
    Measure(
        "person_into_robot_rate",
        0.0,
        100.0,
        test=lambda m: m.get("person_hit") == "person-into-robot",
    ),
    Measure("exiting_collision_rate", 0.0, 100.0, test=lambda m: m.get("person_role") == "exiting"),
    Measure(
        "boarding_collision_rate", 0.0, 100.0, test=lambda m: m.get("person_role") == "boarding"
    ),
    Measure(
        "other_person_collision_rate",
        0.0,
        100.0,
        test=lambda m: m.get("person_hit") is not None and m.get("person_role") not in _ROLES,
    ),
    # efficiency
    Measure("spl", 0.0, 1.0),
    Measure("path_efficiency", 0.0, 1.0, successes_only=True),
    Measure("time_still_s", 0.0, _INF),
    Measure("stall_rate", 0.0, 100.0, test=lambda m: (m.get("stalls") or 0) > 0),
    # timeouts whose end left the robot no way to its goal (people standing where they were)
    Measure(
        "blocked_timeout_rate",
        0.0,
        100.0,
        test=lambda m: m.get("blocked") is True,
        since_key="blocked",
    ),
    # smoothness
    Measure("accel_mean_m_s2", 0.0, _INF),
    Measure("accel_max_m_s2", 0.0, _INF),
    Measure("jerk_mean_m_s3", 0.0, _INF),
    Measure("jerk_max_m_s3", 0.0, _INF),
    Measure("heading_change_rad", 0.0, _INF, successes_only=True),
    Measure("path_irregularity_rad_m", 0.0, _INF, successes_only=True),
    # social
    Measure("min_clearance_m", -_INF, _INF),  # negative at a collision (overlap)
    Measure("intimate_share", 0.0, 1.0),
    Measure("personal_share", 0.0, 1.0),
    Measure("social_share", 0.0, 1.0),
    Measure("space_compliance", 0.0, 1.0),
    Measure("min_ttc_s", 0.0, _INF),  # over the episodes that were ever on a collision course
)
MEASURES = tuple(m.key for m in MEASURE_LIST)
_MEASURE = {m.key: m for m in MEASURE_LIST}
ALL_METRICS = (*METRICS, *MEASURES)
RANGES.update({m.key: (m.low, m.high) for m in MEASURE_LIST})
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


def _measured(recs: Sequence[Mapping[str, Any]]) -> list[tuple[Mapping[str, Any], str]]:
    """(measures, event) of the records that carry measures (format 3 on)."""
    out = []
    for r in recs:
        m = r.get("measures")
        if isinstance(m, Mapping):
            out.append((m, str(r["event"])))
    return out


def _measure_values(measured: Sequence[tuple[Mapping[str, Any], str]], key: str) -> list[Any]:
    """The per-episode values of the mean ``key`` (successes only where it says so)."""
    only_ok = _MEASURE[key].successes_only
    return [m.get(key) for m, event in measured if not only_ok or event == "success"]


def _hits(measured: Sequence[tuple[Mapping[str, Any], str]], key: str) -> tuple[int, int]:
    """(episodes counted by the rate ``key``, episodes measured)."""
    measure = _MEASURE[key]
    test, since = measure.test, measure.since_key
    assert test is not None
    rows = [m for m, _ in measured if since is None or since in m]
    return sum(bool(test(m)) for m in rows), len(rows)


def _finite_mean(values: Iterable[Any]) -> float:
    v = [float(x) for x in values if x is not None and math.isfinite(x)]
    return float(np.mean(v)) if v else float("nan")


def _per_seed(recs: Sequence[Mapping[str, Any]]) -> dict[str, float]:
    n = len(recs)
    out = {m: 100.0 * sum(r["event"] == _EVENT[m] for r in recs) / n for m in RATES}
    for m in METRICS[len(RATES) :]:
        vals = [v for v in _episode_values(recs, m) if v is not None]
        out[m] = float(np.mean(vals)) if vals else float("nan")
    measured = _measured(recs)
    for meas in MEASURE_LIST:
        if meas.is_rate:
            k, n_m = _hits(measured, meas.key)
            out[meas.key] = 100.0 * k / n_m if n_m else float("nan")
        else:
            out[meas.key] = _finite_mean(_measure_values(measured, meas.key))
    return out


def _over_seeds(by_seed: Mapping[int, list[Mapping[str, Any]]]) -> dict[str, dict[str, float]]:
    per_seed = [_per_seed(v) for _, v in sorted(by_seed.items())]
    return {m: _entry(m, *mean_ci(p[m] for p in per_seed)) for m in ALL_METRICS}


def _wilson_entry(k: int, n: int) -> dict[str, float]:
    """A rate [%] of ``k`` in ``n`` episodes with its Wilson score interval (NaN for n = 0)."""
    if n == 0:
        return {"mean": math.nan, "ci95": math.nan, "lo": math.nan, "hi": math.nan}
    lo, hi = wilson_interval(k, n)
    return {
        "mean": 100.0 * k / n,
        "ci95": 50.0 * (hi - lo),  # half the (asymmetric) interval's width
        "lo": 100.0 * lo,
        "hi": 100.0 * hi,
    }


def _over_episodes(recs: Sequence[Mapping[str, Any]]) -> dict[str, dict[str, float]]:
    out: dict[str, dict[str, float]] = {}
    n = len(recs)
    for m in RATES:
        out[m] = _wilson_entry(sum(r["event"] == _EVENT[m] for r in recs), n)
    for m in METRICS[len(RATES) :]:
        out[m] = _entry(m, *mean_ci(_episode_values(recs, m)))
    measured = _measured(recs)
    for meas in MEASURE_LIST:
        if meas.is_rate:
            out[meas.key] = _wilson_entry(*_hits(measured, meas.key))
        else:
            out[meas.key] = _entry(meas.key, *mean_ci(_measure_values(measured, meas.key)))
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
            "measured": len(_measured(pooled)),  # episodes with the social measures
        }
        entry.update(_over_seeds(by_seed) if kind == "seeds" else _over_episodes(pooled))
        out[f"{scen}/{pol}"] = entry
    return out
