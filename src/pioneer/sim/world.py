"""The pure simulation core: a static :class:`World`, a batched :class:`State` and ``step``.

``step(world, state, command) -> state`` never mutates its input. Every array in a
:class:`State` has a leading batch axis B, so the same function advances one world (B = 1,
the Gymnasium env) or many copies of it under different commands at once (the lookahead
teacher's 120 candidate rollouts).

Within a step of length Δt the humans are integrated in substeps of at most
``SocialForceConfig.max_substep`` and the robot moves along its exact arc. Collisions are
checked on the swept motion of every substep (docs/simulator.md): the closest approach of the robot
and each human moving linearly over the substep, and the distance between the robot's chord
and every wall segment, both made conservative by the chord–arc deviation v·h·|ω·h|/8.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pioneer.bounds import Positive
from pioneer.config import Config, check_positive
from pioneer.errors import ConfigError, expect
from pioneer.sim.humans import GONE, SocialForceConfig
from pioneer.sim.kernel import step_kernel, trajectory_kernel
from pioneer.sim.kernel_simd import trajectory_kernel_lanes
from pioneer.sim.lidar import (
    RAY_PRECISION,
    LidarConfig,
    RayPrecision,
    cast_rays,
    cast_rays_into,
    observation_from_ranges,
    ray_dtype,
)
from pioneer.sim.robot import RobotConfig, validate_command

__all__ = [
    "SimConfig",
    "State",
    "World",
    "WorldTrace",
    "advance",
    "clearance",
    "goal_bearing",
    "observe",
    "observe_arrays",
    "observe_states",
    "scan",
    "step",
]

F64 = NDArray[np.float64]


@dataclasses.dataclass(frozen=True)
class SimConfig(Config):
    """Timing, termination and the sub-models' parameters."""

    dt: Positive = 0.1  # [s] control period Δt_ctrl (10 Hz)
    time_limit: Positive = 30.0  # [s] episode length before truncation
    goal_tolerance: Positive = 0.3  # [m] success when ‖p_r − goal‖ < this
    robot: RobotConfig = RobotConfig()
    social_force: SocialForceConfig = SocialForceConfig()
    lidar: LidarConfig = LidarConfig()


@dataclasses.dataclass(frozen=True, eq=False)
class World:
    """The static part of a simulation: walls, map bounds and parameters."""

    walls: F64  # (M, 4) segments x1, y1, x2, y2 [m]
    bounds: F64  # (4,) xmin, xmax, ymin, ymax [m]; humans whose body leaves it are removed
    sim: SimConfig = SimConfig()

    def __post_init__(self) -> None:
        walls = np.ascontiguousarray(self.walls, dtype=np.float64).reshape(-1, 4)
        bounds = np.ascontiguousarray(self.bounds, dtype=np.float64)
        if not np.all(np.isfinite(walls)) or bounds.shape != (4,):
            raise ConfigError(
                expect("World", "finite walls (M, 4) and bounds (4,)", bounds.shape, "fix the map")
            )
        walls.setflags(write=False)
        bounds.setflags(write=False)
        object.__setattr__(self, "walls", walls)
        object.__setattr__(self, "bounds", bounds)
        object.__setattr__(self, "_sfm_params", self.sim.social_force.as_array())
        object.__setattr__(self, "_wall_table", wall_soa(walls))

    @property
    def sfm_params(self) -> F64:
        """Packed social-force parameters for the kernels."""
        return self._sfm_params  # type: ignore[attr-defined]

    @property
    def wall_table(self) -> F64:
        """The walls as rows x1, y1, ex, ey, ‖e‖² for the social-force kernel (see wall_soa)."""
        return self._wall_table  # type: ignore[attr-defined]


WALL_LANES = 4  # the wall table is padded to a multiple of this (one AVX2 vector of float64)
FAR = 1.0e12  # [m] where padding walls sit: never in range of any force, never the nearest


def wall_soa(walls: F64) -> F64:
    """Walls ``(M, 4)`` as a ``(5, M')`` table: x1, y1, ex = x2 − x1, ey = y2 − y1 and ‖e‖².

    Column-major per quantity and padded to a multiple of ``WALL_LANES`` with point walls far
    away, so the social-force kernel's wall loop runs whole SIMD vectors on contiguous rows.
    ‖e‖² of a point wall is stored as 1 (its e = 0, so the closest point is its end point).
    The values are computed exactly as the scalar primitive computes them.
    """
    m = walls.shape[0]
    m_pad = max(WALL_LANES, -(-m // WALL_LANES) * WALL_LANES)
    table = np.zeros((5, m_pad))
    table[0] = FAR
    table[1] = FAR
    table[4] = 1.0
    ex = walls[:, 2] - walls[:, 0]
    ey = walls[:, 3] - walls[:, 1]
    ll = ex * ex + ey * ey
    table[0, :m] = walls[:, 0]
    table[1, :m] = walls[:, 1]
    table[2, :m] = ex
    table[3, :m] = ey
    table[4, :m] = np.where(ll > 0.0, ll, 1.0)
    table.setflags(write=False)
    return table


@dataclasses.dataclass(frozen=True, eq=False)
class State:
    """Dynamic state of B world copies with N humans each (all arrays lead with B)."""

    robot: F64  # (B, 3) px, py, θ [m, m, rad]
    command: F64  # (B, 2) last applied (v, ω) [m/s, rad/s]
    goal: F64  # (B, 2) robot goal [m]
    start: F64  # (B, 2) robot start position [m] (d_total = ‖goal − start‖)
    t: F64  # (B,) time [s]
    path_length: F64  # (B,) distance travelled [m]
    collided: NDArray[np.bool_]  # (B,) a collision happened (sticky)
    reached: NDArray[np.bool_]  # (B,) the goal was reached without collision (sticky)
    gap: F64  # (B,) min swept human gap (surface to surface) over the last step [m] (inf: none)
    wall_gap: F64  # (B,) min swept robot-surface-to-wall gap over the last step [m]
    h_pos: F64  # (B, N, 2) human positions [m]
    h_vel: F64  # (B, N, 2) human velocities [m/s]
    h_radius: F64  # (B, N) [m]
    h_vpref: F64  # (B, N) preferred speed [m/s]
    h_waypoints: F64  # (B, N, W, 2) waypoints, the last valid one is the goal [m]
    h_n_waypoints: NDArray[np.int64]  # (B, N)
    h_wp_index: NDArray[np.int64]  # (B, N) current waypoint
    h_status: NDArray[np.int8]  # (B, N) WALKING / ARRIVED / GONE
    h_delay: F64  # (B, N) time at which each human starts walking [s]
    h_wait_for: NDArray[np.int64]  # (B, N, N) 1: human i waits until human j left/arrived
    h_home: F64  # (B, N, 2) position a waiting human holds [m]
    h_release: NDArray[np.int64]  # (B, N) j's waiters go once j's waypoint index >= this
    h_reacts: NDArray[np.bool_]  # (B, N) the human reacts to the robot (False: ignores it)

    def __eq__(self, other: object) -> bool:
        """Value equality: every array equal (states are values, e.g. in ``info``)."""
        if not isinstance(other, State):
            return NotImplemented
        mine, theirs = self._arrays(), other._arrays()
        return all(np.array_equal(mine[k], theirs[k]) for k in mine)

    __hash__ = None  # type: ignore[assignment]

    @property
    def batch_size(self) -> int:
        """B, the number of world copies."""
        return int(self.robot.shape[0])

    @property
    def n_humans(self) -> int:
        """N, human slots per copy (removed humans keep their slot with status GONE)."""
        return int(self.h_pos.shape[1])

    def repeat(self, n: int) -> State:
        """``n`` copies of a single-copy state (B = 1 → B = n)."""
        if self.batch_size != 1:
            raise ConfigError(
                expect("State.repeat", "a state with B = 1", self.batch_size, "take(i)")
            )
        return self._each(lambda a: a.repeat(n, axis=0))

    @staticmethod
    def fields() -> tuple[str, ...]:
        """The names of the state's arrays in declaration order: the keys of a checkpoint
        that stores a state array by array (the trainers, :mod:`pioneer.learn.layout_env`)."""
        return _STATE_FIELDS

    @staticmethod
    def concat(states: Sequence[State]) -> State:
        """One state holding every copy of ``states`` in order (B = ΣB_i, equal N)."""
        if not states:
            raise ConfigError(expect("State.concat", "at least one state", 0, "pass states"))
        return State(**{k: np.concatenate([getattr(s, k) for s in states]) for k in _STATE_FIELDS})

    def put(self, index: int, single: State) -> None:
        """Overwrite copy ``index`` in place with the B = 1 state ``single`` (an episode that
        restarts inside a batch)."""
        for k, v in self._arrays().items():
            v[index] = getattr(single, k)[0]

    def take(self, index: int | NDArray[np.int64]) -> State:
        """The copies at ``index`` (an int keeps a batch axis of 1)."""
        idx = np.atleast_1d(np.asarray(index))
        return State(**{k: v[idx].copy() for k, v in self._arrays().items()})

    def copy(self) -> State:
        """A deep copy (states are treated as values; the kernels work on copies)."""
        return self._each(np.ndarray.copy)

    def _each(self, fn: Callable[[NDArray[Any]], NDArray[Any]]) -> State:
        """A new state whose every array is ``fn`` of this one's. Built without ``__init__``:
        the frozen dataclass's per-field ``object.__setattr__`` cost as much as copying the
        arrays, and ``step`` copies a state on every call (the planner repeats one too)."""
        new = object.__new__(State)
        fields = new.__dict__
        mine = self.__dict__
        for k in _STATE_FIELDS:
            fields[k] = fn(mine[k])
        return new

    def _arrays(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in _STATE_FIELDS}

    @property
    def humans_present(self) -> NDArray[np.bool_]:
        """(B, N) mask of humans still in the map."""
        return self.h_status != GONE


_STATE_FIELDS = tuple(f.name for f in dataclasses.fields(State))


def step(world: World, state: State, command: F64 | list[float], dt: float | None = None) -> State:
    """Advance every copy by ``dt`` (default: the control period) under its command.

    ``command`` is ``(B, 2)`` (or ``(2,)`` when B = 1); it is validated (finite, shape) and
    clipped to the robot's limits. Returns a new :class:`State`.
    """
    h_dt = world.sim.dt if dt is None else float(dt)
    check_positive("step", "dt", h_dt)
    u = validate_command(command, state.batch_size)
    new = state.copy()
    n_sub = max(1, math.ceil(h_dt / world.sim.social_force.max_substep - 1e-9))
    step_kernel(*step_kernel_args(world, new, u, h_dt, n_sub))  # clips u into new.command
    return new


@dataclasses.dataclass(frozen=True, eq=False)
class WorldTrace:
    """L steps of B copies under constant commands (:func:`advance`), every step recorded.

    A copy stopped at its collision (``advance(…, stop_at_collision=True)``) keeps its
    collision state: its records after the collision step repeat that step's.
    """

    final: State  # the copies after the L-th step (or at their collision step)
    poses: F64  # (B, L, 3) robot pose after each step
    circles: F64  # (B, L, N, 3) the humans after each step as LiDAR circles x, y, r (0: gone)
    gap: F64  # (B,) minimum swept human gap (surface to surface) over the simulated steps [m]
    wall_gap: F64  # (B,) minimum swept robot-to-wall gap over the simulated steps [m]
    live_steps: NDArray[np.int64]  # (B,) distinct records per copy: L, or 1 + its collision step

    def observations(
        self,
        world: World,
        which: NDArray[np.bool_] | None = None,
        precision: RayPrecision = RAY_PRECISION,
    ) -> NDArray[np.float32]:
        """The noise-free observation after every step, ``(B, L, 29)`` float32: the values of
        :func:`observe_states` of the L recorded states (the teacher plans on noise-free rays,
        see there). ``which (B,)`` observes only those copies, ``(B', L, 29)`` in their order.
        A stopped copy's repeated records are observed once and repeated. ``precision``: of
        the ray casting (:func:`observe_arrays`)."""
        n_l = self.poses.shape[1]
        n_h = self.circles.shape[2]
        poses, circles, goal, live = self.poses, self.circles, self.final.goal, self.live_steps
        if which is not None:
            poses, circles, goal, live = poses[which], circles[which], goal[which], live[which]
        n_b = poses.shape[0]
        if np.all(live == n_l):
            return observe_arrays(
                world,
                poses.reshape(n_b * n_l, 3),
                circles.reshape(n_b * n_l, n_h, 3),
                np.repeat(goal, n_l, axis=0),
                precision,
            ).reshape(n_b, n_l, -1)
        distinct = np.arange(n_l)[None, :] < live[:, None]  # (B, L)
        obs = observe_arrays(
            world, poses[distinct], circles[distinct], np.repeat(goal, live, axis=0), precision
        )
        # Record (b, k) is distinct record min(k, live_b − 1) of copy b; copy b's distinct
        # records start at Σ_{b' < b} live_b' in ``obs``.
        first = np.cumsum(live) - live
        return obs[first[:, None] + np.minimum(np.arange(n_l)[None, :], live[:, None] - 1)]


def advance(
    world: World,
    state: State,
    command: F64,
    dt: float,
    n_steps: int,
    stop_at_collision: bool = False,
    lanes: bool = False,
    vector_exp: bool = False,
    in_place: bool = False,
) -> WorldTrace:
    """``n_steps`` calls of :func:`step` with the commands ``(B, 2)`` held, in one kernel call,
    recording every step (bit for bit the values of the repeated ``step``; tested).

    With ``stop_at_collision`` a copy is not advanced once it has collided (a planner discards
    a colliding candidate): every copy that never collides gets the same values, bit for bit.
    With ``lanes`` the copies run in SIMD lanes (:mod:`pioneer.sim.kernel_simd`): the same
    values, bit for bit, faster for many copies; with ``vector_exp`` too, its social forces take
    e^z from ``vecmath.exp64_lanes`` (within 2 ulp of ``math.exp``): faster still, no longer
    bit for bit.
    With ``in_place`` the trace's final state is ``state`` itself, advanced (for a caller that
    made ``state`` for this call alone, as a planner's repeated copies: no copy is made).
    """
    if vector_exp and not lanes:
        raise ConfigError(
            expect("advance vector_exp", "lanes=True with it", "lanes=False", "pass lanes=True")
        )
    h_dt = float(dt)
    check_positive("advance", "dt", h_dt)
    if n_steps < 1:
        raise ConfigError(expect("advance n_steps", ">= 1", n_steps, "pass at least 1"))
    u = validate_command(command, state.batch_size)
    new = state if in_place else state.copy()
    n_sub = max(1, math.ceil(h_dt / world.sim.social_force.max_substep - 1e-9))
    n_b, n_h = state.batch_size, state.n_humans
    poses = np.empty((n_b, n_steps, 3))
    circles = np.empty((n_b, n_steps, n_h, 3))
    clear = np.empty(n_b)
    wclear = np.empty(n_b)
    live = np.empty(n_b, dtype=np.int64)
    args = step_kernel_args(world, new, u, h_dt, n_sub, stop_at_collision)
    if lanes:
        trajectory_kernel_lanes(args, poses, circles, clear, wclear, live, vector_exp)
    else:
        trajectory_kernel(
            args, new.robot, new.h_pos, new.h_radius, new.h_status, new.collided, new.gap,
            new.wall_gap, poses, circles, clear, wclear, live,
        )  # fmt: skip
    return WorldTrace(new, poses, circles, clear, wclear, live)


def step_kernel_args(
    world: World, s: State, u: F64, dt: float, n_sub: int, skip_collided: bool = False
) -> tuple[Any, ...]:
    """The arguments of ``kernel.step_kernel`` advancing ``s`` in place (also for benchmarks)."""
    robot = world.sim.robot
    return (
        s.robot,
        u,
        s.command,
        robot.v_min,
        robot.v_max,
        robot.omega_max,
        s.goal,
        s.t,
        s.path_length,
        s.collided,
        s.reached,
        s.gap,
        s.wall_gap,
        s.h_pos,
        s.h_vel,
        s.h_radius,
        s.h_vpref,
        s.h_waypoints,
        s.h_n_waypoints,
        s.h_wp_index,
        s.h_status,
        s.h_delay,
        s.h_wait_for,
        s.h_release,
        s.h_reacts,
        s.h_home,
        world.walls,
        world.wall_table,
        world.bounds,
        world.sfm_params,
        robot.radius,
        world.sim.goal_tolerance,
        dt,
        n_sub,
        skip_collided,
    )


def _circles(state: State) -> F64:
    """The humans as LiDAR circles ``(B, N, 3)``: x, y, radius (0 for a removed human)."""
    return np.concatenate(
        [state.h_pos, np.where(state.humans_present, state.h_radius, 0.0)[..., None]], axis=-1
    )


def scan(world: World, state: State, rng: np.random.Generator | None = None) -> F64:
    """LiDAR ranges [m] of every copy, shape ``(B, G)``; Gaussian noise if configured."""
    lid = world.sim.lidar
    ranges = cast_rays(state.robot, _circles(state), world.walls, lid.n_beams, lid.max_range)
    if lid.noise_std > 0.0:
        if rng is None:
            raise ConfigError(
                expect("scan rng", "a numpy Generator when noise_std > 0", None, "pass env rng")
            )
        ranges = np.clip(ranges + rng.normal(0.0, lid.noise_std, ranges.shape), 0.0, lid.max_range)
    return ranges


def clearance(state: State, robot_radius: float) -> F64:
    """``(B,)`` the paper's clearance: from the robot's centre to the nearest human's surface
    [m], the least over the last step — the swept :attr:`State.gap` (surface to surface) plus
    the robot's radius; ``inf`` with no humans. The one place the two distances meet."""
    return state.gap + robot_radius


def goal_bearing(state: State) -> F64:
    """Goal direction relative to the heading [rad], unwrapped, shape ``(B,)``."""
    d = state.goal - state.robot[:, :2]
    return np.arctan2(d[:, 1], d[:, 0]) - state.robot[:, 2]


def observe(
    world: World, state: State, rng: np.random.Generator | None = None
) -> NDArray[np.float32]:
    """The 29-D observation of every copy (paper §III-A, eq. 2), shape ``(B, 29)`` float32."""
    return observation_from_ranges(scan(world, state, rng), goal_bearing(state), world.sim.lidar)


def observe_states(
    world: World, states: Sequence[State], precision: RayPrecision = RAY_PRECISION
) -> NDArray[np.float32]:
    """``observe`` of several states at once without sensor noise, shape
    ``(len(states), B, 29)``; ``precision``: of the ray casting (:func:`observe_arrays`).

    The same values as observing each state alone with a noise-free LiDAR, with one
    ray-casting call for all of them. The world's ``lidar.noise_std`` is not applied: a planner
    predicts the expected scan of a future state, so the teacher plans on noise-free rays even
    in a world whose LiDAR is noisy (the noise reaches the policies that act on the
    observation).
    """
    lid = world.sim.lidar
    if not states:
        return np.empty((0, 0, lid.obs_dim), dtype=np.float32)
    n_b = states[0].batch_size
    if any(s.batch_size != n_b or s.n_humans != states[0].n_humans for s in states):
        raise ConfigError(
            expect("observe_states", "states of equal B and N", "mixed shapes", "observe apart")
        )
    robot = np.concatenate([s.robot for s in states])
    circles = np.concatenate([_circles(s) for s in states])
    goal = np.concatenate([s.goal for s in states])
    return observe_arrays(world, robot, circles, goal, precision).reshape(len(states), n_b, -1)


def observe_arrays(
    world: World, poses: F64, circles: F64, goal: F64, precision: RayPrecision = RAY_PRECISION
) -> NDArray[np.float32]:
    """The noise-free observation of robots at ``poses (P, 3)`` among ``circles (P, N, 3)``
    (x, y, r; r = 0 for a removed human) heading for ``goal (P, 2)``, shape ``(P, 29)``.

    ``precision`` is that of the ray casting (:func:`~pioneer.sim.lidar.cast_rays_into`):
    "float64", the reference, or "float32" for a planner that accepts its ranges (the last
    bits differ; a beam that all but grazes an obstacle may hit in one and miss in the
    other): the teacher's ``TeacherConfig.precision``."""
    lid = world.sim.lidar
    ranges = cast_rays_into(
        poses,
        circles,
        world.walls,
        lid.max_range,
        np.empty((poses.shape[0], lid.n_beams), ray_dtype(precision)),
    )
    d = goal - poses[:, :2]
    bearing = np.arctan2(d[:, 1], d[:, 0]) - poses[:, 2]
    return observation_from_ranges(ranges, bearing, lid)
