"""The pure simulation core: a static :class:`World`, a batched :class:`State` and ``step``.

``step(world, state, command) -> state`` never mutates its input. Every array in a
:class:`State` has a leading batch axis B, so the same function advances one world (B = 1,
the Gymnasium env) or many copies of it under different commands at once (the lookahead
teacher's 120 candidate rollouts).

Within a step of length Δt the humans are integrated in substeps of at most
``SocialForceConfig.max_substep`` and the robot moves along its exact arc. Collisions are
checked on the swept motion of every substep (SPEC 1.3): the closest approach of the robot
and each human moving linearly over the substep, and the distance between the robot's chord
and every wall segment, both made conservative by the chord–arc deviation v·h·|ω·h|/8.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from pioneer.config import Config, check_positive
from pioneer.errors import ConfigError, expect
from pioneer.sim.geometry import (
    norm2d,
    segment_segment_distance,
    swept_point_distance,
    wall_offsets,
)
from pioneer.sim.humans import GONE, SocialForceConfig, sfm_substep
from pioneer.sim.lidar import LidarConfig, cast_rays, observation_from_ranges
from pioneer.sim.robot import RobotConfig, integrate_unicycle, validate_command

__all__ = [
    "SimConfig",
    "State",
    "World",
    "goal_bearing",
    "observe",
    "observe_states",
    "scan",
    "step",
]

F64 = NDArray[np.float64]


@dataclasses.dataclass(frozen=True)
class SimConfig(Config):
    """Timing, termination and the sub-models' parameters."""

    dt: float = 0.1  # [s] control period Δt_ctrl (10 Hz)
    time_limit: float = 30.0  # [s] episode length before truncation
    goal_tolerance: float = 0.3  # [m] success when ‖p_r − goal‖ < this
    robot: RobotConfig = RobotConfig()
    social_force: SocialForceConfig = SocialForceConfig()
    lidar: LidarConfig = LidarConfig()

    def __post_init__(self) -> None:
        check_positive("SimConfig", "dt", self.dt)
        check_positive("SimConfig", "time_limit", self.time_limit)
        check_positive("SimConfig", "goal_tolerance", self.goal_tolerance)


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
    clearance: F64  # (B,) min swept human clearance over the last step [m] (inf: no humans)
    wall_clearance: F64  # (B,) min swept wall clearance over the last step [m]
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
        return State(**{k: np.repeat(v, n, axis=0) for k, v in self._arrays().items()})

    @staticmethod
    def concat(states: Sequence[State]) -> State:
        """One state holding every copy of ``states`` in order (B = ΣB_i, equal N)."""
        if not states:
            raise ConfigError(expect("State.concat", "at least one state", 0, "pass states"))
        names = [f.name for f in dataclasses.fields(State)]
        return State(**{k: np.concatenate([getattr(s, k) for s in states]) for k in names})

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
        """A deep copy (states are treated as values; the kernels work on copies).

        Built without ``__init__``: the frozen dataclass's per-field ``object.__setattr__``
        cost as much as copying the arrays, and ``step`` copies a state on every call.
        """
        new = object.__new__(State)
        fields = new.__dict__
        mine = self.__dict__
        for k in _STATE_FIELDS:
            fields[k] = mine[k].copy()
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
    _step_kernel(*_step_kernel_args(world, new, u, h_dt, n_sub))  # clips u into new.command
    return new


def _step_kernel_args(world: World, s: State, u: F64, dt: float, n_sub: int) -> tuple[Any, ...]:
    """The arguments of ``_step_kernel`` advancing ``s`` in place (also used by benchmarks)."""
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
        s.clearance,
        s.wall_clearance,
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
    )


@njit(cache=True, error_model="numpy")
def _step_kernel(
    robot: F64,
    cmd: F64,
    cmd_out: F64,
    v_min: float,
    v_max: float,
    omega_max: float,
    goal: F64,
    t: F64,
    path: F64,
    collided: NDArray[np.bool_],
    reached: NDArray[np.bool_],
    clear_out: F64,
    wclear_out: F64,
    hpos: F64,
    hvel: F64,
    hrad: F64,
    hvpref: F64,
    hwp: F64,
    hnwp: NDArray[np.int64],
    hwpi: NDArray[np.int64],
    hstatus: NDArray[np.int8],
    hdelay: F64,
    hwait: NDArray[np.int64],
    hrelease: NDArray[np.int64],
    hreacts: NDArray[np.bool_],
    hhome: F64,
    walls: F64,
    wall_tab: F64,
    bounds: F64,
    params: F64,
    r_robot: float,
    goal_tol: float,
    dt: float,
    n_sub: int,
) -> None:
    n_b = robot.shape[0]
    n_h = hpos.shape[1]
    m = walls.shape[0]
    h = dt / n_sub
    old = np.empty((n_h, 2))
    fx = np.empty(n_h)
    fy = np.empty(n_h)
    ready = np.empty(n_h)
    wall_d = np.empty(n_h)
    wall_scr = np.empty((3, wall_tab.shape[1]))
    was_present = np.empty(n_h, dtype=np.bool_)
    for b in range(n_b):
        x = robot[b, 0]
        y = robot[b, 1]
        th = robot[b, 2]
        # clip_command's np.clip, element by element (the same values)
        v = min(max(cmd[b, 0], v_min), v_max)
        w = min(max(cmd[b, 1], -omega_max), omega_max)
        cmd_out[b, 0] = v
        cmd_out[b, 1] = w
        sag = v * h * abs(w * h) / 8.0
        cmin = np.inf
        wmin = np.inf
        for s in range(n_sub):
            for i in range(n_h):
                old[i, 0] = hpos[b, i, 0]
                old[i, 1] = hpos[b, i, 1]
                was_present[i] = hstatus[b, i] != GONE
            sfm_substep(
                b,
                hpos,
                hvel,
                hrad,
                hvpref,
                hwp,
                hnwp,
                hwpi,
                hstatus,
                hdelay,
                hwait,
                hrelease,
                hreacts,
                hhome,
                fx,
                fy,
                ready,
                wall_d,
                wall_scr,
                t[b] + s * h,
                x,
                y,
                r_robot,
                walls,
                wall_tab,
                bounds,
                params,
                h,
            )
            x1, y1, th1 = integrate_unicycle(x, y, th, v, w, h)
            for i in range(n_h):
                if not was_present[i]:
                    continue
                d = swept_point_distance(
                    old[i, 0] - x, old[i, 1] - y, hpos[b, i, 0] - x1, hpos[b, i, 1] - y1
                )
                cmin = min(cmin, d - r_robot - hrad[b, i] - sag)
            half = 0.5 * norm2d(x1 - x, y1 - y)
            mx = 0.5 * (x + x1)
            my = 0.5 * (y + y1)
            wall_offsets(mx, my, wall_tab, wall_scr)
            # The wall nearest the chord's midpoint first: its distance makes the cheap bound
            # below skip most of the others (a minimum does not depend on the order).
            near = 0
            for k in range(1, m):
                near = k if wall_scr[2, k] < wall_scr[2, near] else near
            for j in range(m):
                k = near if j == 0 else (j - 1 if j <= near else j)
                # Cheap bound first: the chord lies within `half` of its midpoint.
                if wall_scr[2, k] - half - r_robot - sag >= wmin:
                    continue
                d = segment_segment_distance(
                    x, y, x1, y1, walls[k, 0], walls[k, 1], walls[k, 2], walls[k, 3]
                )
                wmin = min(wmin, d - r_robot - sag)
            x = x1
            y = y1
            th = th1
        robot[b, 0] = x
        robot[b, 1] = y
        robot[b, 2] = th
        t[b] += dt
        path[b] += v * dt
        clear_out[b] = cmin
        wclear_out[b] = wmin
        if cmin < 0.0 or wmin < 0.0:
            collided[b] = True
        if not collided[b] and math.hypot(goal[b, 0] - x, goal[b, 1] - y) < goal_tol:
            reached[b] = True


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


def goal_bearing(state: State) -> F64:
    """Goal direction relative to the heading [rad], unwrapped, shape ``(B,)``."""
    d = state.goal - state.robot[:, :2]
    return np.arctan2(d[:, 1], d[:, 0]) - state.robot[:, 2]


def observe(
    world: World, state: State, rng: np.random.Generator | None = None
) -> NDArray[np.float32]:
    """The 29-D observation of every copy (SPEC 1.4), shape ``(B, 29)`` float32."""
    return observation_from_ranges(scan(world, state, rng), goal_bearing(state), world.sim.lidar)


def observe_states(world: World, states: Sequence[State]) -> NDArray[np.float32]:
    """``observe`` of several states at once without sensor noise, shape
    ``(len(states), B, 29)``.

    The same values as observing each state alone with a noise-free LiDAR, with one
    ray-casting call for all of them (the teacher observes its 10 rollout states of 120 copies
    this way). The world's ``lidar.noise_std`` is not applied: a planner predicts the expected
    scan of a future state, so the teacher plans on noise-free rays even in a world whose
    LiDAR is noisy (the noise reaches the policies that act on the observation).
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
    ranges = cast_rays(robot, circles, world.walls, lid.n_beams, lid.max_range)
    bearing = np.concatenate([goal_bearing(s) for s in states])
    return observation_from_ranges(ranges, bearing, lid).reshape(len(states), n_b, -1)
