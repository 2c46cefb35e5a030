"""The simulator: Gymnasium env steps (``env_step``), ray casting (``raycast_batch``) and the
teacher's batched rollout step (``world_step_batch``)."""

from __future__ import annotations

import math
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
    median_ratio,
    metric,
    seeded_actions,
    time_cases,
)
from pioneer.envs.env import NavEnv
from pioneer.sim import (
    ElevatorLayout,
    State,
    World,
    cast_rays,
    cast_rays_into,
    observation_from_ranges,
    observe,
    scan,
    step,
)
from pioneer.sim.world import _circles


def n_substeps(world: World, dt: float) -> int:
    """Social-force substeps of one ``step`` of ``dt`` seconds, as ``step`` computes them."""
    return max(1, math.ceil(dt / world.sim.social_force.max_substep - 1e-9))


def step_kernel_case(
    world: World, s0: State, u: np.ndarray, n: int, dt: float | None = None
) -> Case | None:
    """``n`` chained in-place calls of the bare step kernel (None if its signature changed)."""
    try:
        from pioneer.sim.kernel import step_kernel
        from pioneer.sim.world import step_kernel_args
    except ImportError:
        return None
    h_dt = world.sim.dt if dt is None else dt
    n_sub = n_substeps(world, h_dt)
    uc = np.ascontiguousarray(u, dtype=np.float64)

    def setup() -> tuple[Any, ...]:
        return step_kernel_args(world, s0.copy(), uc, h_dt, n_sub)

    def run(args: tuple[Any, ...]) -> None:
        for _ in range(n):
            step_kernel(*args)

    try:
        run(setup())
    except Exception as exc:  # the kernel is private: skip the diagnostic if it moved
        log.warning("step-kernel diagnostic skipped: %s", exc)
        return None
    return Case(run, setup)


# --------------------------------------------------------------------------------------------
# env_step


def bench_env_step(plan: Plan) -> Result:
    """Steps/s of the Gymnasium env, raw and wrapped, plus a per-step cost breakdown."""
    envs = {"raw": gym.make(ENV_ID).unwrapped, "wrapped": gym.make(ENV_ID)}
    actions = seeded_actions(envs["raw"].action_space, plan.env_steps, SEED + 1)
    resets: dict[str, list[int]] = {k: [] for k in envs}
    secs = time_cases(
        {k: env_case(e, actions, resets[k]) for k, e in envs.items()}, plan.env_repeats
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
    circles = _circles(s0)
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
        "env_step_raw": env_case(env, actions, []),
        "world_step_b1": Case(world_steps),
        "observe_b1": Case(observes),
        "cast_rays_b1": Case(raycasts),
        "observation_from_ranges_b1": Case(obs_from_ranges),
    }
    kernel = step_kernel_case(world, s0, u, n)
    if kernel is not None:
        cases["step_kernel_b1"] = kernel
    secs = time_cases(cases, plan.breakdown_repeats)
    env.close()
    return {f"us_per_call_{k}": metric(v / n * 1e6, "us") for k, v in secs.items()}


# --------------------------------------------------------------------------------------------
# raycast_batch


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


def bench_raycast_batch(plan: Plan) -> Result:
    """``cast_rays`` for 1,200 poses x 72 beams, 3 humans per pose; beside it, in the same
    rounds, ``cast_rays_into`` with float32 beam loops (the teacher's float32 rays)."""
    n_poses = 1200
    scenario, world, state = elevator_setup(SEED + 3)
    lid = scenario.sim.lidar
    poses = elevator_poses(n_poses, SEED + 4, scenario.sim.robot.radius)
    one = _circles(state)  # (1, 3, 3)
    circles = np.ascontiguousarray(np.broadcast_to(one, (n_poses, *one.shape[1:])))
    walls = world.walls
    out = cast_rays(poses, circles, walls, lid.n_beams, lid.max_range)
    assert out.shape == (n_poses, lid.n_beams), out.shape

    out32 = np.empty((n_poses, lid.n_beams), dtype=np.float32)

    def run(_: object) -> None:
        cast_rays(poses, circles, walls, lid.n_beams, lid.max_range)

    def run32(_: object) -> None:
        cast_rays_into(poses, circles, walls, lid.max_range, out32)

    cases = {"cast_rays": Case(run), "float32": Case(run32)}
    timed = time_cases(cases, plan.raycast_repeats, warmup=3)
    secs, secs32 = timed["cast_rays"], timed["float32"]
    rays = n_poses * lid.n_beams
    return {
        "metrics": {
            "ms_per_call": metric(secs * 1e3, "ms", ("<=", 2.0)),
            "ns_per_ray": metric(secs / rays * 1e9, "ns"),
            "ms_per_call_float32": metric(secs32 * 1e3, "ms"),
            "x_speedup_float32": metric([median_ratio(secs, secs32)], "x"),
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
# world_step_batch


def bench_world_step_batch(plan: Plan) -> Result:
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
    big = State.concat(states)

    def observe_each(_: object) -> None:
        for s in states:
            observe(world, s)

    def observe_once(_: object) -> None:
        observe(world, big)

    cases = {"step": Case(lambda _: rollout())}
    kernel = step_kernel_case(world, batch, cmds, n_steps, dt=dt)
    if kernel is not None:
        cases["kernel_only"] = kernel
    cases["observe_10x120"] = Case(observe_each)
    cases["observe_1x1200"] = Case(observe_once)
    secs = time_cases(cases, plan.batch_repeats, warmup=2)
    n_sub = n_substeps(world, dt)
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
