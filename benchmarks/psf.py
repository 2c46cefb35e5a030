"""``pysocialforce_step``: the same 3-pedestrian elevator scene in the ``pysocialforce``
package (no LiDAR), timed round-robin with our raw env and our bare ``world.step``."""

from __future__ import annotations

import contextlib
import importlib.metadata
import logging
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from benchmarks.common import (
    ENV_ID,
    SEED,
    Case,
    Plan,
    Result,
    elevator_setup,
    env_case,
    log,
    metric,
    seeded_actions,
    time_cases,
)
from pioneer.sim import State, step

# agent_radius stays at their default 0.35 m: it only offsets their obstacle force (their
# ped-ped force has no body radius), and with our 0.6 m all three pedestrians jam against the
# door posts instead of walking through; the cost per step is the same within noise.
PSF_CONFIG = """\
# pysocialforce reads these top-level keys in PedState / EnvState.
step_width = 0.1      # [s] same Δt as the pioneer env
agent_radius = 0.35   # [m] their default (see above)
resolution = 10.0     # obstacle samples per metre (their default)

[scene]
enable_group = false  # social force only: no group forces
"""


@contextlib.contextmanager
def _quarantined_logging_and_cwd() -> Iterator[Path]:
    """Run in a temporary cwd and undo any change to the root logger afterwards.

    ``pysocialforce.utils.logging`` sets the root logger to DEBUG and attaches a stream
    handler and a ``FileHandler("file.log")`` in the current directory at import time.
    """
    root = logging.getLogger()
    level, handlers = root.level, list(root.handlers)
    disabled = root.manager.disable
    cwd = os.getcwd()
    with tempfile.TemporaryDirectory(prefix="pioneer-bench-psf-") as tmp:
        os.chdir(tmp)
        logging.disable(logging.INFO)  # silence DEBUG chatter (numba, matplotlib) meanwhile
        try:
            yield Path(tmp)
        finally:
            os.chdir(cwd)
            for h in list(root.handlers):
                if h not in handlers:
                    root.removeHandler(h)
                    h.close()
            root.setLevel(level)
            logging.disable(disabled)


def _import_pysocialforce() -> Any:
    with _quarantined_logging_and_cwd():
        import pysocialforce

    return pysocialforce


def _psf_scene(state: State, walls: np.ndarray) -> tuple[np.ndarray, list[tuple[Any, ...]]]:
    """pysocialforce state ``(N, 6)`` and obstacles from a pioneer state and wall list.

    State rows are ``(x, y, vx, vy, goal_x, goal_y)``; pysocialforce has no waypoints, so
    each pedestrian heads straight for its final goal (through the door) and starts at its
    preferred speed (their max speed is 1.3 x the initial speed, like our speed cap).
    Obstacles are ``(x_start, x_end, y_start, y_end)`` (scene.py: EnvState.obstacles), not
    our ``(x1, y1, x2, y2)``.
    """
    pos = state.h_pos[0]
    n = pos.shape[0]
    goal = state.h_waypoints[0, np.arange(n), state.h_n_waypoints[0] - 1]
    d = goal - pos
    e = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
    vel = e * state.h_vpref[0][:, None]
    psf_state = np.column_stack([pos, vel, goal]).astype(np.float64)
    obstacles = [(x1, x2, y1, y2) for x1, y1, x2, y2 in np.asarray(walls).tolist()]
    return psf_state, obstacles


def _time_against_pioneer(
    psf: Any, cfg: Path, n: int, repeats: int, info: dict[str, Any]
) -> dict[str, np.ndarray]:
    """Seconds per ``n`` steps of pysocialforce, our raw env and our ``world.step`` (B = 1),
    round-robin; what pysocialforce's last run did goes into ``info``."""
    scenario, world, state = elevator_setup(SEED + 2)
    psf_state, obstacles = _psf_scene(state, np.asarray(scenario.walls))
    env = gym.make(ENV_ID).unwrapped
    actions = seeded_actions(env.action_space, n, SEED + 1)
    u = np.array([[0.4, 0.3]])

    def psf_setup() -> Any:
        return psf.Simulator(
            psf_state.copy(), groups=None, obstacles=obstacles, config_file=str(cfg)
        )

    def psf_run(sim: Any) -> None:
        sim.step(n)

    def world_run(_: object) -> None:
        s = state
        for _ in range(n):
            s = step(world, s, u)

    secs = time_cases(
        {
            "pysocialforce": Case(psf_run, psf_setup),
            "env_raw": env_case(env, actions, []),
            "world_step_b1": Case(world_run),
        },
        repeats,
    )
    last = psf_setup().step(n)
    info["final_positions"] = np.round(last.peds.pos(), 3).tolist()
    info["goals"] = np.round(psf_state[:, 4:6], 3).tolist()
    info["forces"] = [type(f).__name__ for f in last.forces]
    env.close()
    return secs


def bench_pysocialforce_step(plan: Plan) -> Result:
    """Steps/s of the same 3-pedestrian elevator scene in ``pysocialforce`` (no LiDAR).

    Timed round-robin with our raw env (LiDAR, observation, reward) and our bare
    ``world.step`` (B = 1, social force + robot, no LiDAR) over the same number of steps, so
    the ratios ours/theirs come from the same time window.
    """
    n = plan.psf_steps
    info: dict[str, Any] = {"steps_per_run": n}
    try:
        info["pysocialforce_version"] = importlib.metadata.version("pysocialforce")
    except importlib.metadata.PackageNotFoundError:
        info["pysocialforce_version"] = None
    try:
        psf = _import_pysocialforce()
        with tempfile.TemporaryDirectory(prefix="pioneer-bench-psf-") as tmp:
            cfg = Path(tmp) / "bench.toml"
            cfg.write_text(PSF_CONFIG)
            secs = _time_against_pioneer(psf, cfg, n, plan.psf_repeats, info)
            info["config"] = PSF_CONFIG
    except Exception as exc:  # report why instead of inventing a number
        reason = f"{type(exc).__name__}: {exc}"
        log.warning("pysocialforce benchmark unavailable: %s", reason)
        info["status"] = "unavailable"
        info["reason"] = reason
        return {"metrics": {}, "info": info}
    info["status"] = "ok"
    theirs = secs["pysocialforce"]
    return {
        "metrics": {
            "steps_per_s_pysocialforce": metric(n / theirs, "steps/s"),
            "steps_per_s_env_raw": metric(n / secs["env_raw"], "steps/s"),
            "steps_per_s_world_step_b1": metric(n / secs["world_step_b1"], "steps/s"),
            # per round: their time / our time for the same number of steps
            "ratio_env_raw_over_psf": metric(theirs / secs["env_raw"], "x"),
            "ratio_world_step_b1_over_psf": metric(theirs / secs["world_step_b1"], "x"),
        },
        "info": info,
    }
