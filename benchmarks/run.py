"""PioneeR performance benchmarks (``make bench`` → ``.venv/bin/python benchmarks/run.py``).

Every benchmark is warmed up first (numba compilation and cache loading are excluded), then
timed with :func:`time.perf_counter` over repeated runs. The table shows medians and
interquartile ranges; ``benchmarks/results/latest.json`` gets the same numbers plus the
machine description and a timestamp (written atomically: temp file + ``os.replace``).

    .venv/bin/python benchmarks/run.py                 # everything (≈ 1–2 minutes)
    .venv/bin/python benchmarks/run.py --quick         # fewer repeats
    .venv/bin/python benchmarks/run.py --only env_step # one benchmark (others kept in the JSON)

By default the script re-runs itself with ``NUMBA_CACHE_DIR`` set to an empty temporary
directory, so the kernels are compiled from the current source (numba's cache does not notice
edits to functions in other files); ``--reuse-numba-cache`` skips that.

Benchmarks and targets (docs/performance.md explains them):

- ``env_step``            Gymnasium env steps/s, raw and ``gym.make``-wrapped   >= 5,000 /s
- ``pysocialforce_step``  the same scene in the ``pysocialforce`` package, and ours/theirs
- ``raycast_batch``       ``cast_rays`` for 1,200 poses x 72 beams              <= 2 ms
- ``world_step_batch``    ``step`` on 120 copies x 10 steps of 0.3 s            <= 3 ms
- ``student_decision``    student scan → command via ONNX Runtime              <= 0.2 ms
                          obs → command via PyTorch                            <= 1 ms
                          and the teacher/student decision-time ratio
- ``deploy_memory``       peak RSS of the torch-free deploy runtime, 1,000 scans < 200 MB
- ``memory``              peak RSS of a fresh process doing 1,000 env steps     < 300 MB
- ``dagger_run``          a full DAgger run (550 episodes), opt-in via --only   <= 15 min
- ``crowdnav_decision``   CrowdNav++ policy.act, shipped weights, 1 thread      <= 1 ms
- ``crowdnav_train_throughput``  PPO trainer env steps/s, 16 and 32 envs       >= 2,000 /s (32)
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import datetime
import gc
import hashlib
import importlib.metadata
import json
import logging
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import gymnasium as gym
import numba
import numpy as np

import pioneer
from pioneer.envs.env import NavEnv
from pioneer.sim import (
    ElevatorLayout,
    State,
    cast_rays,
    get_scenario,
    observation_from_ranges,
    observe,
    sample_state,
    scan,
    step,
)

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
DEFAULT_OUTPUT = HERE / "results" / "latest.json"
ENV_ID = "pioneer/ElevatorHRRL-v0"
SCENARIO = "hr-rl"
SEED = 20240601  # every random draw below comes from np.random.default_rng(SEED + k)
SCHEMA = 1

log = logging.getLogger("pioneer.bench")


# --------------------------------------------------------------------------------------------
# Statistics and timing


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
)


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


@dataclasses.dataclass(frozen=True)
class Case:
    """One timed thing: ``run(setup())``, where ``setup`` (untimed) may be omitted."""

    run: Callable[[Any], object]
    setup: Callable[[], Any] | None = None


def time_cases(cases: dict[str, Case], repeats: int, warmup: int = 1) -> dict[str, np.ndarray]:
    """Seconds per run of every case, ``repeats`` times each, after ``warmup`` untimed rounds.

    The cases are timed round-robin (a, b, c, a, b, c, …), so a burst of load from another
    process on this shared machine hits every case alike and ratios between them stay fair.
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


def metric(
    samples: list[float] | np.ndarray,
    unit: str,
    target: tuple[str, float] | None = None,
) -> dict[str, Any]:
    """A summarized metric with an optional target ``(">=" | "<=" | "<", value)``."""
    m = summarize(samples, unit)
    if target is not None:
        op, value = target
        med = m["median"]
        ok = {">=": med >= value, "<=": med <= value, "<": med < value}[op]
        m["target"] = f"{op} {value:g} {unit}"
        m["passed"] = bool(ok)
    return m


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


# --------------------------------------------------------------------------------------------
# 1. env_step


def _env_rollout(env: gym.Env, actions: np.ndarray) -> int:
    """Step through ``actions``, resetting on termination/truncation; returns #resets."""
    resets = 0
    for a in actions:
        _, _, terminated, truncated, _ = env.step(a)
        if terminated or truncated:
            env.reset()
            resets += 1
    return resets


def _env_case(env: gym.Env, actions: np.ndarray, resets: list[int]) -> Case:
    """A full rollout of ``actions`` from the seeded reset state (identical work every run)."""

    def setup() -> gym.Env:
        env.reset(seed=SEED)
        return env

    def run(e: gym.Env) -> None:
        resets.append(_env_rollout(e, actions))

    return Case(run, setup)


def bench_env_step(plan: Plan) -> dict[str, Any]:
    """Steps/s of the Gymnasium env, raw and wrapped, plus a per-step cost breakdown."""
    envs = {"raw": gym.make(ENV_ID).unwrapped, "wrapped": gym.make(ENV_ID)}
    actions = seeded_actions(envs["raw"].action_space, plan.env_steps, SEED + 1)
    resets: dict[str, list[int]] = {k: [] for k in envs}
    secs = time_cases(
        {k: _env_case(e, actions, resets[k]) for k, e in envs.items()}, plan.env_repeats
    )
    metrics = {
        f"steps_per_s_{k}": metric(plan.env_steps / secs[k], "steps/s", (">=", 5000.0))
        for k in envs
    }
    info: dict[str, Any] = {"steps_per_run": plan.env_steps}
    for k, e in envs.items():
        info[f"resets_per_run_{k}"] = resets[k][-1]
        info[f"wrappers_{k}"] = str(e)
        e.close()
    metrics.update(_env_breakdown(plan))
    return {"metrics": metrics, "info": info}


def _env_breakdown(plan: Plan) -> dict[str, Any]:
    """µs per call of the pieces of one env step (B = 1), to locate Python overhead."""
    n = plan.breakdown_calls
    env = gym.make(ENV_ID).unwrapped
    assert isinstance(env, NavEnv), f"expected {ENV_ID} to be a NavEnv, got {type(env)}"
    env.reset(seed=SEED)
    world = env.world
    s0: State = env.state
    u = np.array([[0.4, 0.3]])
    lid = world.sim.lidar
    circles = np.concatenate(
        [s0.h_pos, np.where(s0.humans_present, s0.h_radius, 0.0)[..., None]], axis=-1
    )
    ranges = scan(world, s0)
    gb = np.zeros(1)
    actions = seeded_actions(env.action_space, n, SEED + 1)

    def world_steps(_: object) -> None:
        s = s0
        for _ in range(n):
            s = step(world, s, u)

    def observes(_: object) -> None:
        for _ in range(n):
            observe(world, s0)

    def raycasts(_: object) -> None:
        for _ in range(n):
            cast_rays(s0.robot, circles, world.walls, lid.n_beams, lid.max_range)

    def obs_from_ranges(_: object) -> None:
        for _ in range(n):
            observation_from_ranges(ranges, gb, lid)

    cases = {
        "env_step_raw": _env_case(env, actions, []),
        "world_step_b1": Case(world_steps),
        "observe_b1": Case(observes),
        "cast_rays_b1": Case(raycasts),
        "observation_from_ranges_b1": Case(obs_from_ranges),
    }
    kernel = _step_kernel_case(world, s0, u, n)
    if kernel is not None:
        cases["step_kernel_b1"] = kernel
    secs = time_cases(cases, plan.breakdown_repeats)
    env.close()
    return {f"us_per_call_{k}": metric(v / n * 1e6, "us") for k, v in secs.items()}


def _step_kernel_case(
    world: Any, s0: State, u: np.ndarray, n: int, dt: float | None = None
) -> Case | None:
    """``n`` chained in-place calls of the bare step kernel (None if its signature changed)."""
    try:
        from pioneer.sim.world import _step_kernel, _step_kernel_args
    except ImportError:
        return None
    h_dt = world.sim.dt if dt is None else dt
    n_sub = max(1, math.ceil(h_dt / world.sim.social_force.max_substep - 1e-9))
    uc = np.ascontiguousarray(u, dtype=np.float64)

    def setup() -> tuple:
        return _step_kernel_args(world, s0.copy(), uc, h_dt, n_sub)

    def run(args: tuple) -> None:
        for _ in range(n):
            _step_kernel(*args)

    try:
        run(setup())
    except Exception as exc:  # the kernel is private: skip the diagnostic if it moved
        log.warning("step-kernel diagnostic skipped: %s", exc)
        return None
    return Case(run, setup)


# --------------------------------------------------------------------------------------------
# 2. pysocialforce_step

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


def _psf_scene(state: State, walls: np.ndarray) -> tuple[np.ndarray, list[tuple]]:
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


def bench_pysocialforce_step(plan: Plan) -> dict[str, Any]:
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
        scenario, world, state = elevator_setup(SEED + 2)
        psf_state, obstacles = _psf_scene(state, np.asarray(scenario.walls))
        env = gym.make(ENV_ID).unwrapped
        actions = seeded_actions(env.action_space, n, SEED + 1)
        u = np.array([[0.4, 0.3]])
        with tempfile.TemporaryDirectory(prefix="pioneer-bench-psf-") as tmp:
            cfg = Path(tmp) / "bench.toml"
            cfg.write_text(PSF_CONFIG)

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
                    "env_raw": _env_case(env, actions, []),
                    "world_step_b1": Case(world_run),
                },
                plan.psf_repeats,
            )
            last = psf_setup().step(n)
            info["final_positions"] = np.round(last.peds.pos(), 3).tolist()
            info["goals"] = np.round(psf_state[:, 4:6], 3).tolist()
            info["forces"] = [type(f).__name__ for f in last.forces]
            info["config"] = PSF_CONFIG
        env.close()
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


# --------------------------------------------------------------------------------------------
# 3. raycast_batch


def elevator_poses(n: int, seed: int, margin: float) -> np.ndarray:
    """``n`` robot poses (x, y, θ): half in the lobby, half in the cabin, ``margin`` off walls."""
    lay = ElevatorLayout()
    rng = np.random.default_rng(seed)
    n_lobby = n // 2
    n_cabin = n - n_lobby
    lobby = np.column_stack(
        [
            rng.uniform(-lay.lobby_width / 2 + margin, lay.lobby_width / 2 - margin, n_lobby),
            rng.uniform(-lay.lobby_depth + margin, -margin, n_lobby),
        ]
    )
    cabin = np.column_stack(
        [
            rng.uniform(-lay.cabin_width / 2 + margin, lay.cabin_width / 2 - margin, n_cabin),
            rng.uniform(margin, lay.cabin_depth - margin, n_cabin),
        ]
    )
    xy = np.concatenate([lobby, cabin])
    theta = rng.uniform(-math.pi, math.pi, n)
    return np.ascontiguousarray(np.column_stack([xy, theta]))


def bench_raycast_batch(plan: Plan) -> dict[str, Any]:
    """``cast_rays`` for 1,200 poses x 72 beams, 3 humans per pose."""
    n_poses = 1200
    scenario, world, state = elevator_setup(SEED + 3)
    lid = scenario.sim.lidar
    poses = elevator_poses(n_poses, SEED + 4, scenario.sim.robot.radius)
    one = np.concatenate(
        [state.h_pos, np.where(state.humans_present, state.h_radius, 0.0)[..., None]], axis=-1
    )  # (1, 3, 3)
    circles = np.ascontiguousarray(np.broadcast_to(one, (n_poses, *one.shape[1:])))
    walls = world.walls
    out = cast_rays(poses, circles, walls, lid.n_beams, lid.max_range)
    assert out.shape == (n_poses, lid.n_beams), out.shape

    def run(_: object) -> None:
        cast_rays(poses, circles, walls, lid.n_beams, lid.max_range)

    secs = time_cases({"cast_rays": Case(run)}, plan.raycast_repeats, warmup=3)["cast_rays"]
    rays = n_poses * lid.n_beams
    return {
        "metrics": {
            "ms_per_call": metric(secs * 1e3, "ms", ("<=", 2.0)),
            "ns_per_ray": metric(secs / rays * 1e9, "ns"),
        },
        "info": {
            "poses": n_poses,
            "beams": lid.n_beams,
            "walls": int(walls.shape[0]),
            "circles_shape": list(circles.shape),
            "mean_range_m": float(out.mean()),
        },
    }


# --------------------------------------------------------------------------------------------
# 4. world_step_batch


def concat_states(states: list[State]) -> State:
    """One state holding every copy of ``states`` (B = ΣB_i)."""
    return State(
        **{
            f.name: np.concatenate([getattr(s, f.name) for s in states])
            for f in dataclasses.fields(State)
        }
    )


def bench_world_step_batch(plan: Plan) -> dict[str, Any]:
    """``step`` on 120 copies x 10 steps of 0.3 s (the teacher's rollout), then ``observe``."""
    n_copies, n_steps, dt = 120, 10, 0.3
    scenario, world, state = elevator_setup(SEED + 5)
    batch = state.repeat(n_copies)
    rng = np.random.default_rng(SEED + 6)
    robot = scenario.sim.robot
    cmds = rng.uniform(robot.command_low, robot.command_high, size=(n_copies, 2))

    def rollout() -> list[State]:
        s = batch
        out = []
        for _ in range(n_steps):
            s = step(world, s, cmds, dt=dt)
            out.append(s)
        return out

    states = rollout()
    big = concat_states(states)

    def observe_each(_: object) -> None:
        for s in states:
            observe(world, s)

    def observe_once(_: object) -> None:
        observe(world, big)

    cases = {"step": Case(lambda _: rollout())}
    kernel = _step_kernel_case(world, batch, cmds, n_steps, dt=dt)
    if kernel is not None:
        cases["kernel_only"] = kernel
    cases["observe_10x120"] = Case(observe_each)
    cases["observe_1x1200"] = Case(observe_once)
    secs = time_cases(cases, plan.batch_repeats, warmup=2)
    n_sub = max(1, math.ceil(dt / scenario.sim.social_force.max_substep - 1e-9))
    metrics: dict[str, Any] = {
        "ms_10_steps": metric(secs["step"] * 1e3, "ms", ("<=", 3.0)),
        "ns_per_copy_substep": metric(secs["step"] / (n_copies * n_steps * n_sub) * 1e9, "ns"),
    }
    if "kernel_only" in secs:
        metrics["ms_10_steps_kernel_only"] = metric(secs["kernel_only"] * 1e3, "ms")
    metrics["ms_observe_10x120"] = metric(secs["observe_10x120"] * 1e3, "ms")
    metrics["ms_observe_1x1200"] = metric(secs["observe_1x1200"] * 1e3, "ms")
    final = states[-1]
    return {
        "metrics": metrics,
        "info": {
            "copies": n_copies,
            "steps": n_steps,
            "dt_s": dt,
            "substeps_per_step": n_sub,
            "observed_states": int(big.batch_size),
            "collided_copies": int(final.collided.sum()),
            "final_time_s": float(final.t[0]),
        },
    }


# --------------------------------------------------------------------------------------------
# 5. memory

MEMORY_CHILD = """
import json, resource, sys
rss_start = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
import numpy as np
import gymnasium as gym
import pioneer
rss_import = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
env = gym.make({env_id!r})
rng = np.random.default_rng({seed})
actions = rng.uniform(env.action_space.low, env.action_space.high, size=({n}, 2))
env.reset(seed={seed})
for a in actions.astype(np.float32):
    _, _, terminated, truncated, _ = env.step(a)
    if terminated or truncated:
        env.reset()
env.close()
rss_peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
hwm = None
try:
    with open("/proc/self/status") as f:
        hwm = next(int(ln.split()[1]) for ln in f if ln.startswith("VmHWM:"))
except (OSError, StopIteration):
    pass
heavy = sorted(m for m in ("torch", "matplotlib") if m in sys.modules)
print(json.dumps({{"rss_start_kb": rss_start, "rss_import_kb": rss_import, "rss_peak_kb": rss_peak,
                  "vm_hwm_kb": hwm, "heavy": heavy, "n_modules": len(sys.modules)}}))
assert not heavy, f"heavy modules imported: {{heavy}}"
"""


# Linux carries the RSS high-water mark of the address space a process replaces across
# execve into ru_maxrss, so a child spawned straight from this (large) benchmark process would
# report at least our own RSS. A bare ``python -S`` launcher (≈ 10 MB) spawns the real child.
MEMORY_LAUNCHER = (
    "import subprocess, sys; "
    "sys.exit(subprocess.run([sys.executable, '-c', sys.argv[1]]).returncode)"
)


def bench_memory(plan: Plan) -> dict[str, Any]:
    """Peak RSS (ru_maxrss) of a fresh interpreter that imports pioneer and runs 1,000 steps."""
    n_steps = 1000
    code = MEMORY_CHILD.format(env_id=ENV_ID, seed=SEED + 7, n=n_steps)
    peaks, imports, starts, hwms, heavy_all, n_modules = [], [], [], [], set(), []
    for k in range(plan.memory_repeats + 1):  # run 0 only fills the numba cache
        proc = subprocess.run(
            [sys.executable, "-S", "-c", MEMORY_LAUNCHER, code],
            cwd=REPO,
            capture_output=True,
            text=True,
            check=False,
        )
        lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
        if not lines:
            raise RuntimeError(f"memory child failed ({proc.returncode}): {proc.stderr[-2000:]}")
        rec = json.loads(lines[-1])
        if k == 0:
            continue
        # ru_maxrss is in KiB on Linux (bytes on macOS).
        scale = 1.0 / (1024 * 1024) if sys.platform == "darwin" else 1.0 / 1024
        peaks.append(rec["rss_peak_kb"] * scale)
        imports.append(rec["rss_import_kb"] * scale)
        starts.append(rec["rss_start_kb"] * scale)
        if rec["vm_hwm_kb"] is not None:
            hwms.append(rec["vm_hwm_kb"] / 1024)
        heavy_all.update(rec["heavy"])
        n_modules.append(rec["n_modules"])
    peak = metric(peaks, "MB", ("<", 300.0))
    heavy = sorted(heavy_all)
    if heavy:
        peak["passed"] = False
    return {
        "metrics": {
            "peak_rss_mb": peak,
            "rss_after_import_mb": metric(imports, "MB"),
            **({"vm_hwm_mb": metric(hwms, "MB")} if hwms else {}),
        },
        "info": {
            "env_steps": n_steps,
            "ru_maxrss_at_child_start_mb": float(np.median(starts)),
            "torch_imported": "torch" in heavy,
            "matplotlib_imported": "matplotlib" in heavy,
            "modules_loaded": int(np.median(n_modules)),
        },
    }


# --------------------------------------------------------------------------------------------
# Driver

# --------------------------------------------------------------------------------------------
# 5–7. density reward and teacher (issues 3 and 4)


def _density_data(n: int, d: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Synthetic demos: features ~ N(0, I) in R^d, 80 % positive."""
    rng = np.random.default_rng(seed)
    return rng.normal(size=(n, d)), np.where(rng.random(n) < 0.8, 1.0, -1.0)


def bench_density_fit(plan: Plan) -> dict[str, Any]:
    """``DensityReward.fit`` on 1,000 samples (all inducing) and on 20,000 with 2,000 inducing."""
    from pioneer.reward import DensityConfig, DensityReward

    small = _density_data(1000, 31, SEED + 20)
    large = _density_data(20000, 31, SEED + 21)
    cases = {
        "fit_1000": Case(lambda _: DensityReward().fit(*small)),
        "fit_20000_2000": Case(
            lambda _: DensityReward(DensityConfig(max_inducing=2000)).fit(*large)
        ),
    }
    secs = time_cases({"fit_1000": cases["fit_1000"]}, plan.fit_repeats, warmup=1)
    secs |= time_cases(
        {"fit_20000_2000": cases["fit_20000_2000"]}, plan.fit_large_repeats, warmup=0
    )
    return {
        "metrics": {
            "s_fit_1000": metric(secs["fit_1000"], "s", ("<=", 0.5)),
            "s_fit_20000_2000_inducing": metric(secs["fit_20000_2000"], "s", ("<=", 10.0)),
        },
        "info": {"features": 31, "inducing_selection": "kmeans medoids"},
    }


def bench_density_eval(plan: Plan) -> dict[str, Any]:
    """Evaluate 1,200 queries (a teacher's 120 × 10 rollout states) against 1,000 inducing."""
    from pioneer.reward import DensityReward

    model = DensityReward().fit(*_density_data(1000, 31, SEED + 22))
    q = _density_data(1200, 31, SEED + 23)[0]
    model(q)
    secs = time_cases({"eval": Case(lambda _: model(q))}, plan.batch_repeats, warmup=3)["eval"]
    return {
        "metrics": {"ms_eval_1200x1000": metric(secs * 1e3, "ms", ("<=", 2.0))},
        "info": {"queries": 1200, "inducing": 1000, "dtype": "float32 evaluation"},
    }


def bench_teacher_decision(plan: Plan) -> dict[str, Any]:
    """One teacher decision (120 candidates × 10 states: world step, rays, density, scoring),
    and the same pieces alone, to show where the time goes."""
    from pioneer.control.rollout import rollout
    from pioneer.control.teacher import make_teacher
    from pioneer.reward.features import feature_map

    _, world, state = elevator_setup(SEED + 30)
    teacher = make_teacher("hr-rl")
    teacher.decide(world, state)
    ro = rollout(world, state, teacher.candidates)
    c, n_l = ro.robot.shape[:2]
    feats = feature_map("obs_action").from_arrays(
        ro.robot[:, :, :2].reshape(c * n_l, 2),
        ro.obs.reshape(c * n_l, -1),
        np.repeat(ro.commands, n_l, axis=0),
    )
    assert teacher.density is not None
    density = teacher.density
    cases = {
        "decision": Case(lambda _: teacher.decide(world, state)),
        "rollout": Case(lambda _: rollout(world, state, teacher.candidates)),
        "density": Case(lambda _: density(feats)),
    }
    secs = time_cases(cases, plan.batch_repeats, warmup=3)
    flops = 2 * feats.shape[0] * density.alpha_.shape[0] * feats.shape[1]  # type: ignore[union-attr]
    return {
        "metrics": {
            "ms_decision": metric(secs["decision"] * 1e3, "ms", ("<=", 10.0)),
            "ms_rollout_120x10": metric(secs["rollout"] * 1e3, "ms"),
            "ms_density_1200": metric(secs["density"] * 1e3, "ms"),
        },
        "info": {
            "candidates": int(teacher.candidates.shape[0]),
            "inducing": int(density.alpha_.shape[0]),  # type: ignore[union-attr]
            "density_matmul_mflop": flops / 1e6,
            "blas_threads": "1 (threadpoolctl, as the CLI and workers run)",
        },
    }


def episode_decision_times(
    policy_for: Callable[[int], Any], episodes: int, seed0: int, warmup: int = 0
) -> np.ndarray:
    """Seconds per ``policy.act`` over the states of ``episodes`` seeded HR-RL episodes;
    ``policy_for(ep)`` gives the policy of episode ``ep``, ``warmup`` untimed calls first."""
    from pioneer.envs.env import NavEnv

    env = NavEnv("hr-rl")
    times: list[float] = []
    for ep in range(episodes):
        policy = policy_for(ep)
        obs, info = env.reset(seed=seed0 + ep)
        policy.reset(info, np.random.default_rng(seed0 + ep))
        for _ in range(warmup):  # first calls allocate
            policy.act(obs, info)
        policy.reset(info, np.random.default_rng(seed0 + ep))
        done = False
        while not done:
            t0 = time.perf_counter()
            u = policy.act(obs, info)
            times.append(time.perf_counter() - t0)
            obs, _, term, trunc, info = env.step(u)
            done = term or trunc
    return np.asarray(times)


def bench_cvar_bf_decision(plan: Plan) -> dict[str, Any]:
    """CVaR-BF decision time over the states of seeded HR-RL episodes (as the original paper
    reports its solver time), next to the teacher's."""
    from pioneer.control.registry import build_policy

    secs = episode_decision_times(
        lambda _: build_policy("cvar-bf", "hr-rl"), plan.cvar_episodes, SEED + 40
    )
    return {
        "metrics": {
            "ms_decision": metric(secs * 1e3, "ms", ("<=", 20.0)),
            "ms_decision_p90": metric([float(np.percentile(secs, 90) * 1e3)], "ms"),
        },
        "info": {"decisions": int(secs.size), "episodes": plan.cvar_episodes},
    }


# --------------------------------------------------------------------------------------------
# Student (issue 6): decision time, teacher/student ratio, deploy memory, a full DAgger run


def _scan_360(seed: int) -> tuple[np.ndarray, float, float, float]:
    """A synthetic 360-beam laser scan (1° steps, range_max 10 m, a few ``inf`` returns)."""
    rng = np.random.default_rng(seed)
    ranges = rng.uniform(0.4, 6.0, size=360)
    ranges[rng.random(360) < 0.05] = np.inf
    return ranges, -math.pi, 2 * math.pi / 360, 10.0


def bench_student_decision(plan: Plan) -> dict[str, Any]:
    """Student decision (batch 1): scan → command through ONNX Runtime (the deploy runtime,
    resampling included), observation → command through PyTorch (uncertainty included), and
    the teacher's decision timed apart, for the teacher/student ratio. Weights do not change
    the cost, so a freshly initialised MDN of the SPEC architecture is timed."""
    import torch

    from pioneer.control.teacher import make_teacher
    from pioneer.deploy import StudentRuntime
    from pioneer.learn import build_student, export_onnx
    from pioneer.learn.policy import StudentPolicy

    torch.set_num_threads(1)
    model = build_student(seed=SEED + 50)
    policy = StudentPolicy(model)
    _, world, state = elevator_setup(SEED + 51)
    obs = observe(world, state)[0]
    teacher = make_teacher("hr-rl")
    ranges, amin, inc, rmax = _scan_360(SEED + 52)
    goal = np.array([2.0, 0.5])
    with tempfile.TemporaryDirectory(prefix="pioneer-bench-onnx-") as tmp:
        path = export_onnx(model, Path(tmp) / "student.onnx")
        runtime = StudentRuntime(path)
        # The students round-robin with each other; the teacher apart (its 1,200 rollout
        # states flush the caches, which would time a cold student, not a 10 Hz loop's).
        cases = {
            "onnx_scan": Case(lambda _: runtime.step(ranges, amin, inc, rmax, goal)),
            "torch_obs": Case(lambda _: policy.act(obs, {})),
        }
        secs = time_cases(cases, 10 * plan.batch_repeats, warmup=20)
        secs["teacher"] = time_cases(
            {"teacher": Case(lambda _: teacher.decide(world, state))}, plan.batch_repeats, 3
        )["teacher"]
    onnx_ms, torch_ms, teacher_ms = (
        float(np.median(secs[k])) * 1e3 for k in ("onnx_scan", "torch_obs", "teacher")
    )
    return {
        "metrics": {
            "ms_onnx_scan_to_command": metric(secs["onnx_scan"] * 1e3, "ms", ("<=", 0.2)),
            "ms_torch_obs_to_command": metric(secs["torch_obs"] * 1e3, "ms", ("<=", 1.0)),
            "ms_teacher_decision": metric(secs["teacher"] * 1e3, "ms"),
            "teacher_over_student_onnx": metric([teacher_ms / onnx_ms], "x"),
            "teacher_over_student_torch": metric([teacher_ms / torch_ms], "x"),
        },
        "info": {"scan_beams": 360, "threads": 1, "model": "MDN 29-128-128-K10"},
    }


DEPLOY_CHILD = """
import json, resource, sys, tempfile, math
sys.modules["torch"] = None  # the robot runtime must not need torch
import numpy as np
from pioneer.deploy import StudentRuntime
rt = StudentRuntime({onnx!r})
rng = np.random.default_rng({seed})
for _ in range({n}):
    ranges = rng.uniform(0.4, 6.0, size=360)
    rt.step(ranges, -math.pi, 2 * math.pi / 360, 10.0, np.array([2.0, 0.5]))
print(json.dumps({{"rss_peak_kb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss,
                  "torch": "torch" in sys.modules and sys.modules["torch"] is not None,
                  "numba": "numba" in sys.modules}}))
"""


def bench_deploy_memory(plan: Plan) -> dict[str, Any]:
    """Peak RSS of a fresh process running the torch-free deploy runtime for 1,000 scans."""
    from pioneer.learn import build_student, export_onnx

    peaks = []
    with tempfile.TemporaryDirectory(prefix="pioneer-bench-deploy-") as tmp:
        path = export_onnx(build_student(seed=SEED + 60), Path(tmp) / "student.onnx")
        code = DEPLOY_CHILD.format(onnx=str(path), seed=SEED + 61, n=1000)
        for k in range(plan.memory_repeats + 1):  # run 0 only warms the file cache
            proc = subprocess.run(
                [sys.executable, "-S", "-c", MEMORY_LAUNCHER, code],
                cwd=REPO,
                capture_output=True,
                text=True,
                check=False,
            )
            lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
            if not lines:
                raise RuntimeError(f"deploy child failed: {proc.stderr[-2000:]}")
            rec = json.loads(lines[-1])
            if k > 0:
                peaks.append(rec["rss_peak_kb"] / 1024)
    return {
        "metrics": {"peak_rss_mb": metric(peaks, "MB", ("<", 200.0))},
        "info": {
            "scans": 1000,
            "torch_imported": rec["torch"],  # as reported by the (last) child process
            "numba_imported": rec["numba"],
            "runtime": "onnxruntime, 1 thread",
        },
    }


def _same_checkpoint(a: Path, b: Path) -> bool:
    """Equal tensors and equal metadata (parsed: safetensors writes the metadata map in no
    fixed order, so the file bytes of equal checkpoints may differ). Configs are compared
    with their defaults filled in, so an option added later (default = the old behaviour)
    does not make a checkpoint written before it look different."""
    from safetensors import safe_open

    from pioneer.learn.dagger import DaggerConfig
    from pioneer.learn.models import StudentConfig

    def meta(f: Any) -> dict[str, Any]:
        m = {k: json.loads(v) if k in ("config", "info") else v for k, v in f.metadata().items()}
        m["config"] = StudentConfig.from_dict(m["config"]).to_dict()
        m.pop("torch_cpu_capability", None)  # where it was made, not what it is
        if isinstance(m.get("info"), dict) and "dagger" in m["info"]:
            m["info"]["dagger"] = DaggerConfig.from_dict(m["info"]["dagger"]).to_dict()
        return m

    with safe_open(str(a), framework="numpy") as fa, safe_open(str(b), framework="numpy") as fb:
        if set(fa.keys()) != set(fb.keys()):
            return False
        return meta(fa) == meta(fb) and all(
            np.array_equal(fa.get_tensor(k), fb.get_tensor(k))
            for k in fa.keys()  # noqa: SIM118
        )


def _torch_cpu_capability(checkpoint: Path) -> str:
    """torch's kernel family (e.g. "AVX2") where ``checkpoint`` was written (its metadata)."""
    from safetensors import safe_open

    with safe_open(str(checkpoint), framework="numpy") as f:
        return str((f.metadata() or {}).get("torch_cpu_capability", "unknown"))


def bench_dagger_run(plan: Plan) -> dict[str, Any]:
    """Wall time of a full DAgger run (50 + 10 × 50 episodes, HR-RL, MDN, 2 workers) through
    the CLI. Opt-in (``--only dagger_run``): it takes minutes."""
    with tempfile.TemporaryDirectory(prefix="pioneer-bench-dagger-") as tmp:
        t0 = time.perf_counter()
        proc = subprocess.run(
            [
                sys.executable,
                "-m",
                "pioneer.cli",
                "distill",
                "--scenario",
                SCENARIO,
                "--out",
                str(Path(tmp) / "dagger"),
                "--workers",
                "2",
            ],
            cwd=REPO,
            capture_output=True,
            text=True,
            check=False,
        )
        wall = time.perf_counter() - t0
        if proc.returncode != 0:
            raise RuntimeError(f"distill failed: {proc.stderr[-2000:]}")
        curves = (Path(tmp) / "dagger" / "curves.csv").read_text().splitlines()
        fresh = Path(tmp) / "dagger" / "student.safetensors"
        same = _same_checkpoint(
            fresh, REPO / "src" / "pioneer" / "data" / "students" / f"{SCENARIO}-mdn.safetensors"
        )
        capability = _torch_cpu_capability(fresh)
    return {
        "metrics": {"minutes_full_run": metric([wall / 60], "min", ("<=", 15.0))},
        "info": {
            "episodes": 550,
            "workers": 2,
            "last_round": curves[-1],
            # the shipped student was made by this very command: a fresh run matches it bit for
            # bit on a CPU where torch picks the same kernels (compare the two capabilities)
            "same_weights_as_shipped": same,
            "torch_cpu_capability": capability,
        },
    }


# --------------------------------------------------------------------------------------------
# CrowdNav++ (issue 5): decision time with the shipped weights, PPO trainer throughput


def bench_crowdnav_decision(plan: Plan) -> dict[str, Any]:
    """CrowdNav++ ``policy.act`` (graph observation from the privileged state, attention, GRU
    step, increments → command) over the states of seeded HR-RL episodes, shipped weights,
    one torch thread."""
    from pioneer.control.registry import build_policy

    policy = build_policy("crowdnav++", "hr-rl")  # sets torch to 1 thread
    # the same episode count as CVaR-BF's benchmark
    secs = episode_decision_times(lambda _: policy, plan.cvar_episodes, SEED + 70, warmup=5)
    return {
        "metrics": {
            "ms_decision": metric(secs * 1e3, "ms", ("<=", 1.0)),
            "ms_decision_p90": metric([float(np.percentile(secs, 90) * 1e3)], "ms"),
        },
        "info": {"decisions": int(secs.size), "episodes": plan.cvar_episodes, "threads": 1},
    }


def bench_crowdnav_train_throughput(plan: Plan) -> dict[str, Any]:
    """Environment steps/s of the CrowdNav++ PPO trainer (rollout + update, HR-RL, one torch
    thread), per update after a warm-up one, with 16 (the original's), 32 and 64 environments."""
    import torch

    from pioneer.baselines.crowdnav.network import CrowdNavConfig
    from pioneer.baselines.crowdnav.ppo import PPOConfig, RewardConfig, _Trainer

    torch.set_num_threads(1)
    metrics: dict[str, Any] = {}
    n_updates = 3 if plan == QUICK else 8
    targets: dict[int, tuple[str, float] | None] = {16: None, 32: (">=", 2000.0), 64: None}
    for n_envs, target in targets.items():
        tr = _Trainer(
            get_scenario(SCENARIO),
            PPOConfig(n_envs=n_envs, seed=SEED % 1000),
            CrowdNavConfig(max_humans=3),
            RewardConfig(),
        )
        tr.learn(tr.rollout())
        rates = []
        for _ in range(n_updates):
            t0 = time.perf_counter()
            tr.learn(tr.rollout())
            rates.append(tr.ppo.steps_per_update / (time.perf_counter() - t0))
        metrics[f"steps_per_s_{n_envs}_envs"] = metric(rates, "steps/s", target)
    return {
        "metrics": metrics,
        "info": {"rollout": 30, "epochs": 5, "minibatches": 2, "threads": 1, "updates": n_updates},
    }


BENCHMARKS = (
    "env_step",
    "pysocialforce_step",
    "raycast_batch",
    "world_step_batch",
    "density_fit",
    "density_eval",
    "teacher_decision",
    "cvar_bf_decision",
    "student_decision",
    "deploy_memory",
    "memory",
    "dagger_run",
    "crowdnav_decision",
    "crowdnav_train_throughput",
)
OPT_IN = ("dagger_run",)  # run only when named with --only (minutes long)


def machine_info() -> dict[str, Any]:
    """What the numbers were measured on."""
    cpu_model = None
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu_model = line.split(":", 1)[1].strip()
                break
    affinity = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None
    # What numba compiles for: the SIMD width decides how fast the vectorised kernels run
    # (cast_rays, the density reward's exp), so results from different hosts differ.
    import llvmlite.binding as llvm

    features = llvm.get_host_cpu_features()
    simd = [f for f in ("sse4.2", "avx", "avx2", "fma", "avx512f") if features.get(f, False)]

    def _version(dist: str) -> str | None:
        try:
            return importlib.metadata.version(dist)
        except importlib.metadata.PackageNotFoundError:
            return None

    return {
        "cpu_count": os.cpu_count(),
        "cpu_affinity": affinity,
        "cpu_model": cpu_model,
        "llvm_host_cpu": llvm.get_host_cpu_name(),
        "simd": simd,
        "platform": platform.platform(),
        "machine": platform.machine(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "numba": numba.__version__,
        "gymnasium": gym.__version__,
        "pioneer": pioneer.__version__,
        "pysocialforce": _version("pysocialforce"),
        "numba_threading_layer_env": os.environ.get("NUMBA_THREADING_LAYER"),
    }


def _now() -> str:
    return datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")


def run_benchmarks(names: list[str], plan: Plan) -> dict[str, dict[str, Any]]:
    """Run the selected benchmarks in a fixed order; failures are recorded, not raised."""
    results: dict[str, dict[str, Any]] = {}
    for name in BENCHMARKS:
        if name not in names:
            continue
        print(f"[bench] {name} …", file=sys.stderr, flush=True)
        t0 = time.perf_counter()
        try:
            if name == "env_step":
                res = bench_env_step(plan)
            elif name == "pysocialforce_step":
                res = bench_pysocialforce_step(plan)
            elif name == "raycast_batch":
                res = bench_raycast_batch(plan)
            elif name == "world_step_batch":
                res = bench_world_step_batch(plan)
            elif name == "density_fit":
                res = bench_density_fit(plan)
            elif name == "density_eval":
                res = bench_density_eval(plan)
            elif name == "teacher_decision":
                res = bench_teacher_decision(plan)
            elif name == "cvar_bf_decision":
                res = bench_cvar_bf_decision(plan)
            elif name == "student_decision":
                res = bench_student_decision(plan)
            elif name == "deploy_memory":
                res = bench_deploy_memory(plan)
            elif name == "dagger_run":
                res = bench_dagger_run(plan)
            elif name == "crowdnav_decision":
                res = bench_crowdnav_decision(plan)
            elif name == "crowdnav_train_throughput":
                res = bench_crowdnav_train_throughput(plan)
            else:
                res = bench_memory(plan)
        except Exception as exc:
            log.exception("benchmark %s failed", name)
            res = {"metrics": {}, "info": {"status": "error", "reason": repr(exc)}}
        res["timestamp"] = _now()
        res["mode"] = "quick" if plan == QUICK else "full"
        res["wall_time_s"] = round(time.perf_counter() - t0, 2)
        res["repeats"] = {m: v["n"] for m, v in res["metrics"].items()}
        res["load_average"] = list(os.getloadavg()) if hasattr(os, "getloadavg") else None
        results[name] = res
    return results


_PREVIOUS: dict[str, Any] = {}


def _fmt(v: float) -> str:
    if v == 0 or not math.isfinite(v):
        return f"{v:g}"
    if abs(v) >= 1000:
        return f"{v:,.0f}"
    if abs(v) >= 10:
        return f"{v:.1f}"
    return f"{v:.3g}"


def _best(m: dict[str, Any]) -> float:
    """The best repeat of a metric: the largest for rates (``/s``, ``>=`` targets), else the
    smallest. A median far from it means the shared host was busy during the run."""
    higher = "/s" in m["unit"] or str(m.get("target", "")).startswith(">")
    return float(m["max"] if higher else m["min"])


def print_table(results: dict[str, dict[str, Any]]) -> None:
    """Medians, IQRs, best repeats and pass/fail (on the median) of every metric."""
    rows = [("benchmark", "metric", "median", "IQR", "best", "unit", "target", "status")]
    notes: list[str] = []
    for name, res in results.items():
        for mname, m in res["metrics"].items():
            status = "" if "passed" not in m else ("PASS" if m["passed"] else "FAIL")
            rows.append(
                (
                    name,
                    mname,
                    _fmt(m["median"]),
                    _fmt(m["iqr"]),
                    _fmt(_best(m)),
                    m["unit"],
                    m.get("target", ""),
                    status,
                )
            )
        info = res.get("info", {})
        if info.get("status") in ("error", "unavailable"):
            rows.append((name, info["status"].upper(), "-", "", "", "", "", "see below"))
            notes.append(f"{name}: {info['status']}: {info.get('reason', '')}")
    widths = [max(len(str(r[i])) for r in rows) for i in range(len(rows[0]))]
    for i, row in enumerate(rows):
        print("  ".join(str(c).ljust(w) for c, w in zip(row, widths, strict=True)).rstrip())
        if i == 0:
            print("  ".join("-" * w for w in widths))
    for note in notes:
        print(note)


def write_json_atomic(path: Path, payload: dict[str, Any]) -> None:
    """Write JSON to a temp file in the same directory, fsync, then ``os.replace``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        umask = os.umask(0)
        os.umask(umask)
        os.fchmod(fd, 0o666 & ~umask)  # mkstemp creates 0600; give it a normal file's mode
        with os.fdopen(fd, "w") as f:
            json.dump(payload, f, indent=2, sort_keys=False)
            f.write("\n")
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


FRESH_CACHE_ENV = "PIONEER_BENCH_FRESH_NUMBA_CACHE"


def _rerun_with_fresh_numba_cache(argv: list[str]) -> int:
    """Run this script again with ``NUMBA_CACHE_DIR`` pointing at an empty temp directory.

    numba's on-disk cache is keyed on the source file of the jitted function only: after an
    edit to ``humans.py`` or ``geometry.py`` the cached ``world._step_kernel`` (which inlines
    them) is still loaded, so a benchmark would silently time the old code. Compiling afresh
    costs a few seconds (excluded from every timing by the warm-up runs).
    """
    with tempfile.TemporaryDirectory(prefix="pioneer-bench-numba-") as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache, FRESH_CACHE_ENV: "1"}
        cmd = [sys.executable, str(Path(__file__).resolve()), *argv]
        return subprocess.run(cmd, env=env, check=False).returncode


def source_fingerprint() -> dict[str, Any]:
    """SHA-256 over the sources (path + content): all of ``src/pioneer`` and ``sim`` alone."""
    src = REPO / "src" / "pioneer"
    out: dict[str, Any] = {}
    for label, root in (("package", src), ("sim", src / "sim")):
        digest = hashlib.sha256()
        newest = 0.0
        files = sorted(root.rglob("*.py"))
        for f in files:
            digest.update(str(f.relative_to(src)).encode())
            digest.update(f.read_bytes())
            newest = max(newest, f.stat().st_mtime)
        out[label] = {
            "sha256": digest.hexdigest(),
            "files": len(files),
            "newest_mtime": datetime.datetime.fromtimestamp(newest, datetime.UTC).isoformat(
                timespec="seconds"
            ),
        }
    return out


def host_probe(repeats: int = 15) -> dict[str, Any]:
    """A fixed reference workload, timed before and after the benchmarks: how fast and how
    busy the host was. ``busy`` = median / best over all three parts; ≈ 1 on an idle machine.
    Compare a run's probe with another's before comparing their medians."""
    rng = np.random.default_rng(0)
    x = rng.random(200_000)
    a = rng.random((256, 256), dtype=np.float32)

    def py_loop() -> None:
        total = 0
        for i in range(100_000):
            total += i

    cases = {
        "sort_200k_ms": Case(lambda _: np.sort(x)),
        "sgemm_256_ms": Case(lambda _: a @ a),
        "python_loop_ms": Case(lambda _: py_loop()),
    }
    out: dict[str, Any] = {}
    ratios = []
    for name, secs in time_cases(cases, repeats).items():
        best, med = float(secs.min()) * 1e3, float(np.median(secs)) * 1e3
        out[name] = {"best": round(best, 4), "median": round(med, 4)}
        ratios.append(med / best)
    out["busy"] = round(float(np.mean(ratios)), 2)
    return out


def _probe_line(tag: str, p: dict[str, Any]) -> str:
    parts = ", ".join(f"{k} {v['best']:.3g}" for k, v in p.items() if isinstance(v, dict))
    return f"host probe {tag}: best {parts}; median/best {p['busy']}×"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats (smoke run)")
    parser.add_argument(
        "--only",
        action="append",
        choices=BENCHMARKS,
        metavar="NAME",
        help=f"run only this benchmark (repeatable): {', '.join(BENCHMARKS)}",
    )
    parser.add_argument(
        "--output", type=Path, default=DEFAULT_OUTPUT, help="results JSON (default: %(default)s)"
    )
    parser.add_argument(
        "--strict", action="store_true", help="exit with status 1 if any target is missed"
    )
    parser.add_argument(
        "--reuse-numba-cache",
        action="store_true",
        help="use the kernels cached in src/**/__pycache__ instead of compiling afresh",
    )
    args = parser.parse_args(argv)
    if not args.reuse_numba_cache and FRESH_CACHE_ENV not in os.environ:
        return _rerun_with_fresh_numba_cache(sys.argv[1:] if argv is None else argv)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    names = list(args.only) if args.only else [b for b in BENCHMARKS if b not in OPT_IN]
    plan = QUICK if args.quick else FULL
    from threadpoolctl import threadpool_limits

    threadpool_limits(1, user_api="blas")  # as the CLI and the evaluation workers run

    if args.output.exists():
        with contextlib.suppress(OSError, ValueError):
            _PREVIOUS.update(json.loads(args.output.read_text()))

    source_before = source_fingerprint()
    probe_before = host_probe()
    t0 = time.perf_counter()
    results = run_benchmarks(names, plan)
    elapsed = time.perf_counter() - t0
    probe_after = host_probe()
    source = source_fingerprint()
    sim_changed = source["sim"]["sha256"] != source_before["sim"]["sha256"]
    if sim_changed:
        log.warning("src/pioneer/sim changed while the benchmarks ran: numbers may be mixed")

    print()
    print_table(results)
    print(f"\n{len(results)} benchmark(s) in {elapsed:.1f} s ({'quick' if args.quick else 'full'})")
    print(_probe_line("before", probe_before))
    print(_probe_line("after ", probe_after))

    # Keep earlier results of benchmarks not run this time (each carries its own timestamp).
    merged: dict[str, Any] = {}
    if _PREVIOUS.get("schema") == SCHEMA:
        merged.update(_PREVIOUS.get("benchmarks", {}))
    merged.update(results)
    payload = {
        "schema": SCHEMA,
        "timestamp": _now(),
        "mode": "quick" if args.quick else "full",
        "ran": names,
        "elapsed_s": round(elapsed, 2),
        "machine": machine_info(),
        "host_probe": {"before": probe_before, "after": probe_after},
        "source": source,
        "sim_source_changed_during_run": sim_changed,
        "numba_cache": "fresh" if os.environ.get(FRESH_CACHE_ENV) else "reused",
        "benchmarks": {name: merged[name] for name in BENCHMARKS if name in merged},
    }
    write_json_atomic(args.output, payload)
    print(f"results → {args.output}")

    missed = [
        f"{name}.{mname}"
        for name, res in results.items()
        for mname, m in res["metrics"].items()
        if m.get("passed") is False
    ]
    if missed:
        print("targets missed: " + ", ".join(missed))
    return 1 if (args.strict and missed) else 0


if __name__ == "__main__":
    sys.exit(main())
