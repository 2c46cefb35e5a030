"""What every benchmark shares: the plan (repeat counts), interleaved timing, the statistics
(median, quartiles, IQR, best repeat), targets and their verdicts, the host probe, and the
seeded elevator scene the benchmarks time."""

from __future__ import annotations

import dataclasses
import gc
import logging
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from pioneer.sim import State, get_scenario, sample_state

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
DEFAULT_OUTPUT = HERE / "results" / "latest.json"
ENV_ID = "pioneer/ElevatorHRRL-v1"
SCENARIO = "hr-rl"
SEED = 20240601  # every random draw comes from np.random.default_rng(SEED + k)

log = logging.getLogger("pioneer.bench")

Result = dict[str, Any]  # {"metrics": {name: metric}, "info": {...}} of one benchmark
Target = tuple[str, float]  # (">=" | "<=" | "<", value), judged on the median


# --------------------------------------------------------------------------------------------
# Plan


@dataclasses.dataclass(frozen=True)
class Plan:
    """Repeat counts and work sizes (``--quick`` shrinks the repeats, never the work)."""

    env_steps: int = 2000  # env steps per timed run
    env_repeats: int = 21
    psf_steps: int = 1000  # pysocialforce steps per timed run
    psf_repeats: int = 15
    raycast_repeats: int = 301
    batch_repeats: int = 101
    breakdown_calls: int = 2000  # calls per run in the per-step breakdown
    breakdown_repeats: int = 9
    memory_repeats: int = 3
    fit_repeats: int = 7
    fit_large_repeats: int = 3
    cvar_episodes: int = 4
    equivalence_seeds: int = 8  # teacher episodes per scenario in teacher_equivalence (work)
    vec_steps: int = 100  # vector steps per timed run (x num_envs env steps)
    vec_repeats: int = 11
    scaling_repeats: int = 3  # rounds of the harness_scaling runs (each ≈ 1 min)


FULL = Plan()
QUICK = Plan(
    env_repeats=5,
    psf_repeats=3,
    raycast_repeats=50,
    batch_repeats=15,
    breakdown_repeats=3,
    memory_repeats=1,
    fit_repeats=3,
    fit_large_repeats=1,
    cvar_episodes=1,
    vec_repeats=3,
    scaling_repeats=1,
)


def mode(plan: Plan) -> str:
    """``"quick"`` or ``"full"``, as recorded in the JSON."""
    return "quick" if plan == QUICK else "full"


# --------------------------------------------------------------------------------------------
# Statistics and verdicts


def summarize(samples: list[float] | np.ndarray, unit: str) -> dict[str, Any]:
    """Median, quartiles and IQR of a list of per-run measurements."""
    a = np.asarray(samples, dtype=np.float64)
    q1, med, q3 = np.percentile(a, [25.0, 50.0, 75.0])
    return {
        "median": float(med),
        "q1": float(q1),
        "q3": float(q3),
        "iqr": float(q3 - q1),
        "min": float(a.min()),
        "max": float(a.max()),
        "n": int(a.size),
        "unit": unit,
    }


def metric(
    samples: list[float] | np.ndarray, unit: str, target: Target | None = None
) -> dict[str, Any]:
    """A summarized metric with an optional target ``(">=" | "<=" | "<", value)``; the
    verdict (``passed``) is taken on the median."""
    m = summarize(samples, unit)
    if target is not None:
        op, value = target
        med = m["median"]
        ok = {">=": med >= value, "<=": med <= value, "<": med < value}[op]
        m["target"] = f"{op} {value:g} {unit}"
        m["passed"] = bool(ok)
    return m


def median_ratio(a: np.ndarray, b: np.ndarray) -> float:
    """The median over rounds of ``a / b``: a speed-up of b over a, when both were timed in the
    same rounds (:func:`time_cases`: round k of each from the same time window)."""
    return float(np.median(np.asarray(a) / np.asarray(b)))


def best(m: dict[str, Any]) -> float:
    """The best repeat of a metric: the largest for rates (``/s``, ``>=`` targets), else the
    smallest. A median far from it means the shared host was busy during the run."""
    higher = "/s" in m["unit"] or str(m.get("target", "")).startswith(">")
    return float(m["max"] if higher else m["min"])


def missed_targets(results: dict[str, Result]) -> list[str]:
    """``benchmark.metric`` of every metric whose median missed its target."""
    return [
        f"{name}.{mname}"
        for name, res in results.items()
        for mname, m in res["metrics"].items()
        if m.get("passed") is False
    ]


# --------------------------------------------------------------------------------------------
# Interleaved timing


@dataclasses.dataclass(frozen=True)
class Case:
    """One timed thing: ``run(setup())``, where ``setup`` (untimed) may be omitted."""

    run: Callable[[Any], object]
    setup: Callable[[], Any] | None = None


def time_cases(cases: dict[str, Case], repeats: int, warmup: int = 1) -> dict[str, np.ndarray]:
    """Seconds per run of every case, ``repeats`` times each, after ``warmup`` untimed rounds.

    The cases are timed round-robin (a, b, c, a, b, c, …), so a burst of load from another
    process on this shared machine hits every case alike and ratios between them stay fair
    (round ``k`` of every case comes from the same time window).
    The garbage collector stays on, but everything alive beforehand is frozen out of its
    scans (``gc.freeze``), so the odd full collection costs what the timed code allocated,
    not what earlier benchmarks (e.g. matplotlib via pysocialforce) left in the heap.
    """
    for _ in range(warmup):
        for c in cases.values():
            c.run(c.setup() if c.setup is not None else None)
    out: dict[str, list[float]] = {k: [] for k in cases}
    gc.collect()
    gc.freeze()
    try:
        for _ in range(repeats):
            for k, c in cases.items():
                arg = c.setup() if c.setup is not None else None
                t0 = time.perf_counter()
                c.run(arg)
                out[k].append(time.perf_counter() - t0)
    finally:
        gc.unfreeze()
    return {k: np.asarray(v) for k, v in out.items()}


# --------------------------------------------------------------------------------------------
# Host probe


def host_probe(repeats: int = 15) -> dict[str, Any]:
    """A fixed reference workload, timed before and after the benchmarks: how fast and how
    busy the host was. ``busy`` = median / best over all three parts; ≈ 1 on an idle machine.
    Compare a run's probe with another's before comparing their medians."""
    x = np.random.default_rng(0).random(200_000)

    def py_loop() -> None:
        total = 0
        for i in range(100_000):
            total += i

    cases = {
        "sort_200k_ms": Case(lambda _: np.sort(x)),
        "sgemm_256_ms": sgemm_256_case(),
        "python_loop_ms": Case(lambda _: py_loop()),
    }
    out: dict[str, Any] = {}
    ratios = []
    for name, secs in time_cases(cases, repeats).items():
        fastest, med = float(secs.min()) * 1e3, float(np.median(secs)) * 1e3
        out[name] = {"best": round(fastest, 4), "median": round(med, 4)}
        ratios.append(med / fastest)
    out["busy"] = round(float(np.mean(ratios)), 2)
    return out


def sgemm_256_case() -> Case:
    """The host probe's GEMM, a 256 × 256 float32 matrix times itself (33.5 Mflop): also the
    unit of the decision benchmarks' host-independent ratios (decision time / this time)."""
    a = np.random.default_rng(1).random((256, 256), dtype=np.float32)
    return Case(lambda _: a @ a)


def probe_line(tag: str, p: dict[str, Any]) -> str:
    """One printed line of a host probe's best times and its median/best ratio."""
    parts = ", ".join(f"{k} {v['best']:.3g}" for k, v in p.items() if isinstance(v, dict))
    return f"host probe {tag}: best {parts}; median/best {p['busy']}×"


# --------------------------------------------------------------------------------------------
# Shared scene


def elevator_setup(seed: int) -> tuple[Any, Any, State]:
    """The HR-RL scenario, its world and one seeded initial state (3 humans)."""
    scenario = get_scenario(SCENARIO)
    world = scenario.world()
    state = sample_state(scenario, np.random.default_rng(seed))
    return scenario, world, state


def seeded_actions(space: gym.spaces.Space[Any], n: int, seed: int) -> np.ndarray:
    """A fixed action sequence drawn uniformly from the action box, shape ``(n, 2)``."""
    assert isinstance(space, gym.spaces.Box), f"expected a Box action space, got {space}"
    rng = np.random.default_rng(seed)
    return rng.uniform(space.low, space.high, size=(n, 2)).astype(np.float32)


def env_rollout(env: gym.Env, actions: np.ndarray) -> int:
    """Step through ``actions``, resetting on termination/truncation; returns #resets."""
    resets = 0
    for a in actions:
        _, _, terminated, truncated, _ = env.step(a)
        if terminated or truncated:
            env.reset()
            resets += 1
    return resets


def env_case(env: gym.Env, actions: np.ndarray, resets: list[int]) -> Case:
    """A full rollout of ``actions`` from the seeded reset state (identical work every run)."""

    def setup() -> gym.Env:
        env.reset(seed=SEED)
        return env

    def run(e: gym.Env) -> None:
        resets.append(env_rollout(e, actions))

    return Case(run, setup)
