"""Social-force humans (Helbing & Molnár 1995; paper §V-B), vectorised in numba.

For a walking human i with position p_i, velocity v_i, radius r_i and preferred speed
v_pref,i heading to its current waypoint w_i:

    f_i = (v_pref,i · e_i − v_i) / τ                                    (driving, HM95 eq. 2)
        + Σ_j A   · exp((r_i + r_j − d_ij) / B)   · n_ij                 (other humans)
        + A_r · exp((r_i + r_r − d_ir) / B_r) · n_ir                    (the robot)
        + Σ_w A_w · exp((r_i − d_iw) / B_w)       · n_iw                 (closest wall point)

with e_i = (w_i − p_i)/‖w_i − p_i‖ and n the unit vector pointing away from the other body.
This is the exponential circular-specification form used by CrowdNav++ and the CVaR-BF
experiments (their public code, docs/simulator.md); A = 2.0 m/s², B = 0.5 m is the CVaR-BF
preset. Walls use the same strength with Helbing–Molnár's shorter range (0.2 m): with the
paper's 0.6 m body radius a 0.5 m wall range makes the 1.8 m door repel people more than
their own drive pulls them.

Integration is semi-implicit Euler: v ← cap(v + f h), p ← p + v h, with the speed cap
‖v‖ ≤ 1.3 · v_pref (never a cap on the *initial* speed, so a human starting at rest moves).

Deviations from a bare social-force model, all documented in docs/simulator.md:

- Walls are hard: after the update a human whose body overlaps a wall is projected back to
  contact and loses its velocity into the wall, so a human can never cross a wall.
- A human that reaches its final goal stops (v = 0) and stays as a static obstacle. A human
  that stalls (speed < settle_speed) within settle_distance of its current target takes it as
  reached: with 0.6 m bodies two boarders cannot both reach spots in a 1.25 m-wide half cabin.
- A human on its last leg whose body has fully left the map bounds is removed (GONE).
- A human may have a start delay and may wait until given other humans have left the map,
  arrived, or passed their release waypoint (boarders let the exiting passenger out of the
  doorway first); until then it holds its start position with the same social-force drive,
  so it can be nudged aside. Pure social force with the paper's 0.6 m bodies deadlocks in a
  1.8 m door when both flows meet there.
- The robot term is per human: a human whose ``reacts`` flag is 0 ignores the robot (the
  robot is invisible to it, CrowdNav++'s ``robot.visible = False``); A_r = 0 makes every
  human ignore it. The paper's humans are uncooperative (§V-B), see docs/simulator.md.
- Optionally a *standing* robot (its commanded speed |v| below ``standing_speed``) repels
  with its own strength ``a_robot_standing`` (people avoid an obstacle standing in their
  way as they avoid a standing person); unset, it repels like a moving one. A setting for
  the baselines' study (docs/baselines.md), off in the paper world.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from pioneer.bounds import NonNegative, Positive
from pioneer.config import Config
from pioneer.errors import ConfigError, expect
from pioneer.sim.geometry import closest_point_on_segment, norm2d, wall_offsets

__all__ = [
    "ARRIVED",
    "A_ROBOT_WEAK",
    "GONE",
    "PRESETS",
    "WALKING",
    "SocialForceConfig",
    "next_waypoint",
    "push_out_of_walls",
    "sfm_substep",
]

WALKING = 0  # moves toward its waypoints
ARRIVED = 1  # reached its final goal; stays as a static obstacle
GONE = 2  # left the map; ignored by forces, sensing and collisions
EXP_CUTOFF = -12.0  # repulsion terms below A·e^-12 (< 1e-5 m/s²) are skipped


A_ROBOT_WEAK = 0.5  # [m/s²] the paper world's human–robot strength (docs/calibration.md)

# Named parameter sets: overrides of the defaults (the ``paper`` preset).
PRESETS: dict[str, dict[str, float]] = {
    "paper": {},
    # The paper's prior implementations, CrowdNav++ and CVaR-BF (their public code,
    # docs/simulator.md), both use K = 1 (τ = 1 s).
    "cvar-bf": {"tau": 1.0, "a_robot": 2.0},  # reacting humans: same A, B for the robot
    "crowdnav": {"tau": 1.0, "b_human": 1.0, "a_robot": 0.0, "b_robot": 1.0, "b_wall": 1.0},
    # The earlier default (the compact world): humans make way for the robot as for a human.
    "compact": {"a_robot": 2.0},
    # Sensitivity study (docs/results.md): how humans react to the robot.
    "robot-invisible": {"a_robot": 0.0},
    "robot-as-human": {"a_robot": 2.0},
    # The baselines' study (docs/baselines.md): a standing robot repelled like a person.
    "standing-robot": {"a_robot_standing": 2.0},
}


@dataclasses.dataclass(frozen=True)
class SocialForceConfig(Config):
    """Parameters of the social-force model; the defaults are the ``paper`` preset.

    The paper's humans are uncooperative (§V-B): they avoid each other and the walls, and the
    robot adds only a weak repulsive term, so a robot that barges in is not given way to.
    ``a_robot`` and ``tau`` of the paper world were fixed by world statistics
    (docs/calibration.md): with the prior implementations' τ = 1 s (K = 1) the paper's 0.6 m
    humans jam in the 4 m lobby even without a robot, with Helbing–Molnár's 0.5 s they do not.
    """

    tau: Positive = 0.5  # [s] relaxation time τ of the driving term (Helbing–Molnár)
    a_human: Positive = 2.0  # [m/s²] A, human–human repulsion strength
    b_human: Positive = 0.5  # [m] B, human–human repulsion range
    a_robot: NonNegative = A_ROBOT_WEAK  # [m/s²] human–robot repulsion strength; 0: robot invisible
    b_robot: Positive = 0.5  # [m] human–robot repulsion range
    a_robot_standing: NonNegative | None = None  # [m/s²] A_r for a standing robot; None: a_robot
    standing_speed: NonNegative = 0.05  # [m/s] a robot commanded slower than this is standing
    a_wall: Positive = 2.0  # [m/s²] human–wall repulsion strength
    b_wall: Positive = 0.2  # [m] human–wall repulsion range (Helbing–Molnár's R = 0.2 m)
    speed_cap_factor: Positive = 1.3  # [-] ‖v‖ ≤ factor · v_pref
    waypoint_tolerance: Positive = 0.3  # [m] distance at which an intermediate waypoint is passed
    goal_tolerance: Positive = 0.3  # [m] distance at which the final goal is reached (then stop)
    max_substep: Positive = 0.1  # [s] longest integration step; longer steps are subdivided
    settle_speed: Positive = 0.05  # [m/s] a walking human slower than this has stalled …
    settle_distance: Positive = 1.0  # [m] … and within this of its target counts as there

    @classmethod
    def preset(cls, name: str) -> SocialForceConfig:
        """A named parameter set (see :data:`PRESETS`)."""
        if name not in PRESETS:
            raise ConfigError(
                expect("social_force preset", f"one of {sorted(PRESETS)}", name, "pick a preset")
            )
        return cls(**PRESETS[name])

    def as_array(self) -> NDArray[np.float64]:
        """Packed parameters for the numba kernels (order fixed by ``_P_*`` indices)."""
        return np.array(
            [
                self.tau,
                self.a_human,
                self.b_human,
                self.a_robot,
                self.b_robot,
                self.a_wall,
                self.b_wall,
                self.speed_cap_factor,
                self.waypoint_tolerance,
                self.goal_tolerance,
                self.settle_speed,
                self.settle_distance,
                self.a_robot if self.a_robot_standing is None else self.a_robot_standing,
                self.standing_speed,
            ]
        )


@njit(cache=True, error_model="numpy", inline="always")
def push_out_of_walls(
    px: float, py: float, vx: float, vy: float, r: float, walls: NDArray[np.float64]
) -> tuple[float, float, float, float]:
    """Hard walls: a body of radius ``r`` at ``(px, py)`` overlapping a wall is projected back
    to contact and loses its velocity into the wall; a second pass only if the first one moved
    it (corners). Returns the position [m] and velocity [m/s]."""
    for _ in range(2):
        moved = False
        for w in range(walls.shape[0]):
            cx, cy = closest_point_on_segment(
                px, py, walls[w, 0], walls[w, 1], walls[w, 2], walls[w, 3]
            )
            dx = px - cx
            dy = py - cy
            d = norm2d(dx, dy)
            if d < r and d > 1e-12:
                nx = dx / d
                ny = dy / d
                px = cx + nx * r
                py = cy + ny * r
                moved = True
                vn = vx * nx + vy * ny
                if vn < 0.0:
                    vx -= vn * nx
                    vy -= vn * ny
        if not moved:
            break
    return px, py, vx, vy


@njit(cache=True, error_model="numpy", inline="always")
def next_waypoint(
    waypoints: NDArray[np.float64],  # (B, N, W, 2) [m]
    b: int,
    i: int,
    n_waypoints: int,  # of human i of copy b
    k: int,  # its current waypoint
    px: float,
    py: float,  # its position [m]
    tol: float,  # [m] an intermediate waypoint this close is passed
) -> tuple[int, float, float, float, bool]:
    """The waypoint human ``i`` of copy ``b`` heads for: intermediate waypoints within ``tol``
    are passed. Returns its index, position, distance and whether it is the final goal."""
    while True:
        gx = waypoints[b, i, k, 0]
        gy = waypoints[b, i, k, 1]
        dg = norm2d(gx - px, gy - py)
        last = k >= n_waypoints - 1
        if last or not dg < tol:
            return k, gx, gy, dg, last
        k += 1


@njit(cache=True, error_model="numpy", inline="always")
def sfm_substep(
    b: int,  # which world copy of the batch to advance
    pos: NDArray[np.float64],  # (B, N, 2) [m], updated in place
    vel: NDArray[np.float64],  # (B, N, 2) [m/s], updated in place
    radius: NDArray[np.float64],  # (B, N) [m]
    vpref: NDArray[np.float64],  # (B, N) [m/s]
    waypoints: NDArray[np.float64],  # (B, N, W, 2) [m]
    n_waypoints: NDArray[np.int64],  # (B, N)
    wp_index: NDArray[np.int64],  # (B, N), updated in place
    status: NDArray[np.int8],  # (B, N), updated in place
    delay: NDArray[np.float64],  # (B, N) [s] a human starts walking at t >= delay
    wait_for: NDArray[np.int64],  # (B, N, N) 1 where human i waits until human j left/arrived
    release: NDArray[np.int64],  # (B, N) human j's waiters go once its waypoint index >= this
    reacts: NDArray[np.bool_],  # (B, N) False: human i ignores the robot
    home: NDArray[np.float64],  # (B, N, 2) [m] where a waiting human holds its position
    fx: NDArray[np.float64],  # (N,) scratch: force x (no allocation per substep)
    fy: NDArray[np.float64],  # (N,) scratch: force y
    ready: NDArray[np.float64],  # (N,) scratch: 1 = walking to its waypoints, 0 = waiting
    wall_d: NDArray[np.float64],  # (N,) scratch: nearest-wall distance at the substep start
    wall_scr: NDArray[np.float64],  # (3, M') scratch: offset x, y and distance to each wall
    t_now: float,  # [s] time at the start of the substep
    rx: float,
    ry: float,
    r_robot: float,  # robot position and radius [m]
    v_robot: float,  # [m/s] the robot's commanded speed in this step
    walls: NDArray[np.float64],  # (M, 4) [m]
    wall_tab: NDArray[np.float64],  # (5, M') World.wall_table: x1, y1, ex, ey, ‖e‖² (padded)
    bounds: NDArray[np.float64],  # (4,) xmin, xmax, ymin, ymax [m]
    params: NDArray[np.float64],  # SocialForceConfig.as_array()
    h: float,  # [s]
) -> None:
    """Advance all humans of world copy ``b`` by one substep ``h`` (in place).

    Whole batch arrays and an index are passed (not per-copy slices): slicing 11 arrays per
    call cost more than the physics in the teacher's 120 × 30 substeps.
    """
    tau = params[0]
    a_h = params[1]
    b_h = params[2]
    a_r = params[3]
    b_r = params[4]
    a_w = params[5]
    b_w = params[6]
    cap = params[7]
    wp_tol = params[8]
    goal_tol = params[9]
    settle_v = params[10]
    settle_d = params[11]
    if abs(v_robot) < params[13]:
        a_r = params[12]  # a standing robot
    n = pos.shape[1]
    m_pad = wall_tab.shape[1]
    if fx.shape[0] < n or fy.shape[0] < n or ready.shape[0] < n or wall_d.shape[0] < n:
        raise ValueError("sfm_substep: scratch arrays must have length >= N")
    for i in range(n):
        fx[i] = 0.0
        fy[i] = 0.0
        wall_d[i] = np.inf
        r_i = status[b, i] == WALKING and t_now >= delay[b, i]
        for j in range(n):
            if wait_for[b, i, j] and status[b, j] == WALKING and wp_index[b, j] < release[b, j]:
                r_i = False
        ready[i] = 1.0 if r_i else 0.0
    # Forces are computed from the positions at the start of the substep for every human.
    for i in range(n):
        if status[b, i] != WALKING:
            continue
        px = pos[b, i, 0]
        py = pos[b, i, 1]
        if ready[i] > 0.0:
            # Waypoint bookkeeping: pass intermediate waypoints, stop at the final goal.
            k, gx, gy, dg, last = next_waypoint(
                waypoints, b, i, n_waypoints[b, i], wp_index[b, i], px, py, wp_tol
            )
            wp_index[b, i] = k
            if last and dg < goal_tol:
                status[b, i] = ARRIVED
                vel[b, i, 0] = 0.0
                vel[b, i, 1] = 0.0
                continue
        else:
            # Waiting: hold the home position by the same social-force drive.
            gx = home[b, i, 0]
            gy = home[b, i, 1]
            dg = norm2d(gx - px, gy - py)
            if dg < 0.05:
                dg = 0.0
        ex = (gx - px) / dg if dg > 0.0 else 0.0
        ey = (gy - py) / dg if dg > 0.0 else 0.0
        ax = (vpref[b, i] * ex - vel[b, i, 0]) / tau
        ay = (vpref[b, i] * ey - vel[b, i, 1]) / tau
        for j in range(n):
            if j == i or status[b, j] == GONE:
                continue
            dx = px - pos[b, j, 0]
            dy = py - pos[b, j, 1]
            d = norm2d(dx, dy)
            z = (radius[b, i] + radius[b, j] - d) / b_h
            if d > 1e-9 and z > EXP_CUTOFF:
                mag = a_h * math.exp(z)
                ax += mag * dx / d
                ay += mag * dy / d
        if reacts[b, i] and a_r > 0.0:
            dx = px - rx
            dy = py - ry
            d = norm2d(dx, dy)
            z = (radius[b, i] + r_robot - d) / b_r
            if d > 1e-9 and z > EXP_CUTOFF:
                mag = a_r * math.exp(z)
                ax += mag * dx / d
                ay += mag * dy / d
        # Walls in two passes: first the geometry of every wall, branch-free so that LLVM
        # vectorises it, then the repulsion of the walls in range, in wall order (the same
        # operations as one scalar pass, so bit-for-bit the same forces).
        rad_i = radius[b, i]
        wall_offsets(px, py, wall_tab, wall_scr)
        for w in range(m_pad):
            d = wall_scr[2, w]
            wall_d[i] = min(wall_d[i], d)
            z = (rad_i - d) / b_w
            if d > 1e-9 and z > EXP_CUTOFF:
                mag = a_w * math.exp(z)
                ax += mag * wall_scr[0, w] / d
                ay += mag * wall_scr[1, w] / d
        fx[i] = ax
        fy[i] = ay
    for i in range(n):
        if status[b, i] != WALKING:
            continue
        vx = vel[b, i, 0] + fx[i] * h
        vy = vel[b, i, 1] + fy[i] * h
        sp = norm2d(vx, vy)
        vmax = cap * vpref[b, i]
        if sp > vmax:
            vx *= vmax / sp
            vy *= vmax / sp
        px = pos[b, i, 0] + vx * h
        py = pos[b, i, 1] + vy * h
        # Hard walls: project an overlapping body back to contact and drop its inward velocity
        # (skipped when the body was clear of every wall by more than its step).
        if wall_d[i] - norm2d(vx * h, vy * h) <= radius[b, i]:
            px, py, vx, vy = push_out_of_walls(px, py, vx, vy, radius[b, i], walls)
        pos[b, i, 0] = px
        pos[b, i, 1] = py
        vel[b, i, 0] = vx
        vel[b, i, 1] = vy
        if ready[i] > 0.0 and norm2d(vx, vy) < settle_v:
            # Stalled near its target (a jam in a full cabin): take the target as reached.
            k = wp_index[b, i]
            dg = math.hypot(waypoints[b, i, k, 0] - px, waypoints[b, i, k, 1] - py)
            if dg < settle_d:
                if k >= n_waypoints[b, i] - 1:
                    status[b, i] = ARRIVED
                    vel[b, i, 0] = 0.0
                    vel[b, i, 1] = 0.0
                else:
                    wp_index[b, i] = k + 1
        # Leaving: only a human on its last leg, once its body is fully outside the map.
        r = radius[b, i]
        outside = (
            px < bounds[0] - r or px > bounds[1] + r or py < bounds[2] - r or py > bounds[3] + r
        )
        if outside and ready[i] > 0.0 and wp_index[b, i] >= n_waypoints[b, i] - 1:
            status[b, i] = GONE
            vel[b, i, 0] = 0.0
            vel[b, i, 1] = 0.0
