"""Batched lookahead rollouts through the pure world step (paper §IV-A.2).

Each candidate command is held for the horizon T; the world (robot and humans) is advanced
at Δt = 0.3 s for L = ⌊T / Δt⌋ = 10 states by :func:`pioneer.sim.world.advance`: the L steps
of every candidate in one kernel call, each step recorded, with the values of L calls of
:func:`~pioneer.sim.world.step`. Humans follow the privileged simulator model (they react to
the robot) or, as an option, a constant-velocity prediction.

A candidate predicted to collide is discarded by the teacher, so the privileged rollout stops
it at its collision step: its records after that step repeat the collision state (a quarter
of the teacher's copy-steps in the paper world are not simulated or observed; every
non-colliding candidate's rollout is the same, bit for bit). The constant-velocity option
keeps stepping colliding candidates.

The privileged rollout runs its copies in SIMD lanes (``advance(..., lanes=True)``, bit for
bit the reference kernel's values; tested). Its arithmetic has three precisions
(:data:`RolloutPrecision`, docs/performance.md): ``"float64"``, the reference; ``"float32"``,
float32 beam loops in the observation of the rollout states (the observations, float32
either way, then differ in the last bits); ``"fast"``, the default, float32 beams and the
social forces' exponentials by a vectorised e^x within 2 ulp of libm's (the rollouts then
differ in the last bits too). The teacher's choice differs only where candidates nearly tie
(:mod:`pioneer.control.precision_check` measures how often: in none of 2,153 recorded states).
The simulator's own steps and observations always use the reference arithmetic.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import typing
from collections.abc import Callable
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from pioneer.errors import ConfigError, expect
from pioneer.sim.humans import ARRIVED, GONE
from pioneer.sim.lidar import RayPrecision
from pioneer.sim.world import State, World, advance, observe_states, step

__all__ = [
    "HORIZON",
    "HUMAN_MODEL",
    "ROLLOUT_PRECISION",
    "STEP",
    "HumanModel",
    "Rollout",
    "RolloutPrecision",
    "ray_precision",
    "rollout",
]

F64 = NDArray[np.float64]
HumanModel = Literal["privileged", "constant_velocity"]  # how rollouts move the people
# The teacher's rollouts (paper §IV-A.2; the defaults of TeacherConfig):
HORIZON = 3.0  # [s] T, each candidate held this long
STEP = 0.3  # [s] Δt of a rollout step
HUMAN_MODEL: HumanModel = "privileged"
# The arithmetic of the rollouts (module docstring); "float64" is the reference, "fast" the
# default (the same choices in every checked state, 1.3× faster teacher episodes).
RolloutPrecision = Literal["float64", "float32", "fast"]
ROLLOUT_PRECISION: RolloutPrecision = "fast"


def ray_precision(precision: RolloutPrecision) -> RayPrecision:
    """The ray casting of a rollout precision (``"fast"`` casts float32 beams); an unknown
    precision is refused."""
    if precision not in typing.get_args(RolloutPrecision):
        raise ConfigError(
            expect("rollout precision", "'float64', 'float32' or 'fast'", precision, "pick one")
        )
    return "float64" if precision == "float64" else "float32"


@dataclasses.dataclass(frozen=True)
class Rollout:
    """The predicted futures of C candidate commands over L steps.

    The observations are cast when asked for: :attr:`obs` of every candidate, or
    :meth:`observations` of some (the teacher observes only its feasible candidates; in the
    paper world half of them collide).
    """

    commands: F64  # (C, 2)
    robot: F64  # (C, L, 3) poses x_1 … x_L (a colliding candidate stops: module docstring)
    collided: NDArray[np.bool_]  # (C,) a predicted collision (humans or walls)
    min_gap: F64  # (C,) minimum swept gap (surface to surface) to any human [m]
    min_wall_gap: F64  # (C,) minimum swept gap to walls [m]
    final: State  # the C states at the horizon (a colliding candidate: at its collision)
    collision_step: NDArray[np.int64]  # (C,) 1-based step of the first collision (L + 1: none)
    observe: Callable[[NDArray[np.bool_] | None], NDArray[np.float32]] = dataclasses.field(
        repr=False, compare=False
    )  # which (C,) or None → their observations (C', L, 29)

    @functools.cached_property
    def obs(self) -> NDArray[np.float32]:
        """Observations o_1 … o_L of every candidate, (C, L, 29) float32."""
        return self.observe(None)

    def observations(self, which: NDArray[np.bool_]) -> NDArray[np.float32]:
        """Observations of the candidates in ``which (C,)``, (C', L, 29) float32, in order."""
        return self.obs[which] if "obs" in self.__dict__ else self.observe(which)

    @property
    def final_goal_distance(self) -> F64:
        """‖x_L − goal‖ for every candidate, (C,)."""
        return np.linalg.norm(self.final.goal - self.robot[:, -1, :2], axis=1)


def rollout(
    world: World,
    state: State,
    commands: F64,
    horizon: float = HORIZON,
    dt: float = STEP,
    human_model: HumanModel = HUMAN_MODEL,
    precision: RolloutPrecision = ROLLOUT_PRECISION,
) -> Rollout:
    """Roll every command of ``commands (C, 2)`` forward from ``state`` (B = 1); ``precision``
    is that of the rollout's arithmetic (module docstring)."""
    if state.batch_size != 1:
        raise ConfigError(
            expect("rollout state", "a single state (B = 1)", state.batch_size, "take(i)")
        )
    if human_model not in typing.get_args(HumanModel):
        raise ConfigError(
            expect("human_model", "'privileged' or 'constant_velocity'", human_model, "pick one")
        )
    rays = ray_precision(precision)  # an unknown precision is refused here, not when observing
    n_steps = math.floor(horizon / dt + 1e-9)
    if n_steps < 1:
        raise ConfigError(
            expect("rollout horizon", f">= the rollout step dt = {dt} s", horizon, "lengthen it")
        )
    c = commands.shape[0]
    s = state.repeat(c)
    if human_model == "privileged":
        tr = advance(
            world, s, commands, dt, n_steps, stop_at_collision=True, lanes=True,
            vector_exp=precision == "fast", in_place=True,
        )  # fmt: skip
        hit = tr.final.collided
        return Rollout(
            commands, tr.poses, hit.copy(), tr.gap, tr.wall_gap, tr.final,
            np.where(hit, tr.live_steps, n_steps + 1),
            functools.partial(tr.observations, world, precision=rays),
        )  # fmt: skip
    # Constant velocity: freeze the social-force model and move the humans along their current
    # velocity after each step, then check the robot against the moved humans too.
    moving = s.h_status != GONE
    s.h_status[moving] = ARRIVED
    v0 = state.h_vel.copy()
    robot = np.empty((c, n_steps, 3))
    states = []
    clear = np.full(c, np.inf)
    wclear = np.full(c, np.inf)
    first = np.full(c, n_steps + 1, dtype=np.int64)
    for k in range(n_steps):
        s = step(world, s, commands, dt=dt)
        if state.n_humans:
            s.h_pos[moving] = (state.h_pos + v0 * (dt * (k + 1))).repeat(c, axis=0)[moving]
            gap = np.linalg.norm(s.h_pos - s.robot[:, None, :2], axis=2) - s.h_radius
            gap = np.where(moving, gap - world.sim.robot.radius, np.inf).min(axis=1)
            np.minimum(s.gap, gap, out=s.gap)
            np.logical_or(s.collided, gap < 0.0, out=s.collided)
        robot[:, k] = s.robot
        first[s.collided & (first > n_steps)] = k + 1
        states.append(s)
        np.minimum(clear, s.gap, out=clear)
        np.minimum(wclear, s.wall_gap, out=wclear)
    obs = observe_states(world, states, rays)
    obs = np.ascontiguousarray(obs.transpose(1, 0, 2))  # (C, L, 29)
    return Rollout(
        commands, robot, s.collided.copy(), clear, wclear, s, first,
        lambda which: obs if which is None else obs[which],
    )  # fmt: skip
