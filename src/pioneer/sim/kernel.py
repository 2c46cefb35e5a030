"""The step's numba kernels: one step of every copy, or L steps of every copy recorded.

- :func:`step_kernel` — one step of every copy (``pioneer.sim.world.step``): the humans in
  substeps of the social-force model (:func:`~pioneer.sim.humans.sfm_substep`), the robot
  along its exact arc, and the swept collision checks (module docstring of
  :mod:`pioneer.sim.world`);
- :func:`trajectory_kernel` — L calls of ``step_kernel`` in one call, recording each step's
  robot pose, the humans as LiDAR circles and the running minimum gaps (the teacher's
  rollout, ``pioneer.sim.world.advance``): the same values without L Python calls, L state
  copies and L argument packs. Optionally a copy stops at its first collision (the teacher
  discards a colliding candidate, so a quarter of its copy-steps need not be simulated).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from pioneer.sim.geometry import (
    norm2d,
    segment_segment_distance,
    swept_point_distance,
    wall_offsets,
)
from pioneer.sim.humans import GONE, sfm_substep
from pioneer.sim.robot import integrate_unicycle

__all__ = ["step_kernel", "trajectory_kernel"]

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]
B8 = NDArray[np.bool_]


@njit(cache=True, error_model="numpy")
def step_kernel(
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
    skip_collided: bool,
) -> None:
    """One step of every copy, in place (the arguments of ``world.step_kernel_args``).

    With ``skip_collided`` a copy whose ``collided`` flag is already set is left as it is
    (the teacher's rollout: a candidate stops at its predicted collision).
    """
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
        if skip_collided and collided[b]:
            continue
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
                v,
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


@njit(cache=True, error_model="numpy")
def trajectory_kernel(
    step_args: tuple[Any, ...],  # the arguments of step_kernel (world.step_kernel_args)
    robot: F64,  # (B, 3) the same arrays as in step_args, read after each step
    hpos: F64,  # (B, N, 2)
    hrad: F64,  # (B, N)
    hstatus: NDArray[np.int8],  # (B, N)
    collided: B8,  # (B,)
    clear_out: F64,  # (B,)
    wclear_out: F64,  # (B,)
    poses: F64,  # (B, L, 3) out: the robot pose after each step
    circles: F64,  # (B, L, N, 3) out: the humans after each step as x, y, r (0: gone)
    clear_min: F64,  # (B,) out: the minimum of ``clear_out`` over the L steps
    wclear_min: F64,  # (B,) out: the minimum of ``wclear_out`` over the L steps
    live_steps: I64,  # (B,) out: how many records of each copy are distinct (L, or fewer
    # when step_args skips collided copies: 1 + the step of its collision)
) -> None:
    """L = ``poses.shape[1]`` calls of ``step_kernel(*step_args)``, each step recorded from the
    state arrays it advances in place.

    Where ``step_args`` skips collided copies, the records of a copy after its collision step
    repeat that step's (the copy is left as it is); ``live_steps`` says how many records of
    each copy are distinct.
    """
    stop = step_args[-1]  # step_kernel's skip_collided
    n_b = robot.shape[0]
    n_h = hpos.shape[1]
    n_l = poses.shape[1]
    for b in range(n_b):
        clear_min[b] = np.inf
        wclear_min[b] = np.inf
        live_steps[b] = n_l
    for k in range(n_l):
        step_kernel(*step_args)
        for b in range(n_b):
            poses[b, k, 0] = robot[b, 0]
            poses[b, k, 1] = robot[b, 1]
            poses[b, k, 2] = robot[b, 2]
            for i in range(n_h):
                circles[b, k, i, 0] = hpos[b, i, 0]
                circles[b, k, i, 1] = hpos[b, i, 1]
                circles[b, k, i, 2] = hrad[b, i] if hstatus[b, i] != GONE else 0.0
            clear_min[b] = min(clear_min[b], clear_out[b])
            wclear_min[b] = min(wclear_min[b], wclear_out[b])
            if stop and collided[b] and live_steps[b] == n_l:
                live_steps[b] = k + 1
