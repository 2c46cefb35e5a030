"""``vector_env``: env steps/s of 64 HR-RL copies in the native vector env
(``gymnasium.make_vec(…, vectorization_mode="vector_entry_point")``, the batched world step
behind one ``VectorEnv``) against Gymnasium's ``SyncVectorEnv`` over 64 ``NavEnv``s
(``vectorization_mode="sync"``), timed round-robin with the same seeded random actions."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from benchmarks.common import ENV_ID, SEED, Case, Plan, Result, log, metric, time_cases

N_ENVS = 64
RATIO_TARGET = (">=", 5.0)  # native ≥ 5 × sync


def _random_actions(envs: gym.vector.VectorEnv, n: int, seed: int) -> list[np.ndarray]:
    """``n`` batched actions drawn from ``envs.action_space`` seeded with ``seed``."""
    envs.action_space.seed(seed)
    return [envs.action_space.sample() for _ in range(n)]


def _vector_case(envs: gym.vector.VectorEnv, actions: list[np.ndarray]) -> Case:
    """Every action of ``actions`` from the seeded reset (episodes that end autoreset)."""

    def setup() -> gym.vector.VectorEnv:
        envs.reset(seed=SEED + 80)
        return envs

    def run(e: gym.vector.VectorEnv) -> None:
        for a in actions:
            e.step(a)

    return Case(run, setup)


def _autoreset_mode(envs: gym.vector.VectorEnv) -> str:
    m = envs.metadata.get("autoreset_mode")
    return str(getattr(m, "value", m))


def _skipped(exc: Exception) -> Result:
    reason = f"native vector env not registered ({type(exc).__name__}: {exc})"
    log.warning("vector_env skipped: %s", reason)
    return {"metrics": {}, "info": {"status": "skipped", "reason": reason, "num_envs": N_ENVS}}


def bench_vector_env(plan: Plan) -> Result:
    """Steps/s of the native vector env and of ``SyncVectorEnv``, 64 envs each, and their
    ratio per round (sync time / native time for the same steps); skipped when ``make_vec``
    cannot build the native one."""
    try:
        native = gym.make_vec(ENV_ID, num_envs=N_ENVS, vectorization_mode="vector_entry_point")
    except Exception as exc:  # not registered (yet), or its module does not import
        return _skipped(exc)
    envs = {"native": native}
    try:
        envs["sync"] = gym.make_vec(ENV_ID, num_envs=N_ENVS, vectorization_mode="sync")
        actions = {k: _random_actions(e, plan.vec_steps, SEED + 81) for k, e in envs.items()}
        cases = {k: _vector_case(e, actions[k]) for k, e in envs.items()}
        secs = time_cases(cases, plan.vec_repeats)
        info: dict[str, Any] = {
            "status": "ok",
            "num_envs": N_ENVS,
            "vector_steps_per_run": plan.vec_steps,
            "env_steps_per_run": N_ENVS * plan.vec_steps,
            "same_actions": all(
                np.array_equal(a, b) for a, b in zip(*actions.values(), strict=True)
            ),
            **{f"class_{k}": type(e.unwrapped).__qualname__ for k, e in envs.items()},
            **{f"autoreset_{k}": _autoreset_mode(e) for k, e in envs.items()},
        }
    finally:
        for e in envs.values():
            e.close()
    n = N_ENVS * plan.vec_steps
    return {
        "metrics": {
            "steps_per_s_native": metric(n / secs["native"], "steps/s"),
            "steps_per_s_sync": metric(n / secs["sync"], "steps/s"),
            "ratio_native_over_sync": metric(secs["sync"] / secs["native"], "x", RATIO_TARGET),
        },
        "info": info,
    }
