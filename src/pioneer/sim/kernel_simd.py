"""The trajectory kernel with the world copies in SIMD lanes (the teacher's rollout, faster).

:func:`trajectory_kernel_lanes` computes what :func:`pioneer.sim.kernel.trajectory_kernel`
computes — L steps of every copy, each recorded — **bit for bit** (tested), in another loop
order. The reference runs copy by copy, each a scalar chain of square roots, divisions and
branches; here every quantity is an array over the copies (structure of arrays, humans ×
copies) and the innermost loops run over the copies, so the same arithmetic fills SIMD
vectors: with the teacher's 120 candidates, one instruction advances 4 of them (AVX2) or 8.

Bit-identity holds because each copy's value is made by the same IEEE operations in the same
order as in the reference (no fused multiply–add, no reassociation): a branch of the
reference becomes a select of both sides, a skipped term a select of the old sum. Three
parts stay scalar per copy, as in the reference: ``math.exp`` (no vector exp in the pip
build of llvmlite; the arguments are computed in lanes, the exponentials in a tight scalar
loop), the rare branches (waypoint bookkeeping, pushing a body out of a wall, settling,
leaving) and the robot's arc (sin/cos).

A copy that collides stops (``skip_collided``, the teacher's candidates): its lane takes
the last live copy's and the loops shrink, so stopped copies cost nothing, as in the
reference. ``pioneer.sim.world.advance(..., lanes=True)`` calls it (the teacher's privileged
rollout does); the reference stays the default of ``advance`` and the oracle of the tests.

The one exception to bit-identity is asked for by name: ``vector_exp`` takes the forces'
exponentials from :func:`pioneer.vecmath.exp64_lanes`, a vectorised e^x within 2 ulp of
libm's (the teacher's ``precision="fast"``; docs/performance.md, "The rollout in SIMD
lanes"); :func:`pioneer.vecmath.exp_where` chooses it or libm.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from pioneer.sim.geometry import norm2d, segment_segment_distance
from pioneer.sim.humans import (
    ARRIVED,
    EXP_CUTOFF,
    GONE,
    WALKING,
    next_waypoint,
    push_out_of_walls,
)
from pioneer.sim.robot import integrate_unicycle
from pioneer.vecmath import exp_where

__all__ = ["trajectory_kernel_lanes"]

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]
B8 = NDArray[np.bool_]


@njit(cache=True, error_model="numpy")
def _swap_lanes(a: Any, p: int, q: int) -> None:
    """Exchange lanes ``p`` and ``q`` of a lane-last array (any leading shape, 2-D or 3-D)."""
    flat = a.reshape(-1, a.shape[-1])
    for r in range(flat.shape[0]):
        tmp = flat[r, p]
        flat[r, p] = flat[r, q]
        flat[r, q] = tmp


@njit(cache=True, error_model="numpy")
def trajectory_kernel_lanes(
    step_args: tuple[Any, ...],  # the arguments of kernel.step_kernel (world.step_kernel_args)
    poses: F64,  # (B, L, 3) out: the robot pose after each step
    circles: F64,  # (B, L, N, 3) out: the humans after each step as x, y, r (0: gone)
    clear_min: F64,  # (B,) out: the minimum of the step gaps over the L steps
    wclear_min: F64,  # (B,) out: the minimum of the step wall gaps over the L steps
    live_steps: I64,  # (B,) out: how many records of each copy are distinct
    vector_exp: bool = False,  # e^z by vecmath.exp64_lanes (within 2 ulp), not math.exp
) -> None:
    """What ``kernel.trajectory_kernel`` computes from the same arguments, bit for bit: the
    state arrays of ``step_args`` advanced L = ``poses.shape[1]`` steps in place, and the same
    records (module docstring). With ``vector_exp`` the social forces' exponentials come from
    :func:`pioneer.vecmath.exp64_lanes` instead: the values then differ in their last bits."""
    (
        robot, cmd, cmd_out, v_min, v_max, omega_max, goal, t, path, collided, reached,
        clear_out, wclear_out, hpos, hvel, hrad, hvpref, hwp, hnwp, hwpi, hstatus, hdelay,
        hwait, hrelease, hreacts, hhome, walls, wall_tab, bounds, params, r_robot, goal_tol,
        dt, n_sub, stop,
    ) = step_args  # fmt: skip
    n_b = robot.shape[0]
    n_h = hpos.shape[1]
    n_l = poses.shape[1]
    m = walls.shape[0]
    m_pad = wall_tab.shape[1]
    h = dt / n_sub
    tau = params[0]
    a_h = params[1]
    b_h = params[2]
    b_r = params[4]
    a_w = params[5]
    b_w = params[6]
    cap = params[7]
    wp_tol = params[8]
    g_tol = params[9]
    settle_v = params[10]
    settle_d = params[11]

    for b in range(n_b):
        clear_min[b] = np.inf
        wclear_min[b] = np.inf
        live_steps[b] = n_l
    # Lanes: the copies still advanced. A copy collided on entry is left as it is (its
    # records repeat its state), as the reference's skip does.
    copy_of = np.empty(n_b, dtype=np.int64)
    n = 0
    for b in range(n_b):
        if stop and collided[b]:
            live_steps[b] = 1
            clear_min[b] = clear_out[b]
            wclear_min[b] = wclear_out[b]
            for k in range(n_l):
                _record(b, k, robot[b, 0], robot[b, 1], robot[b, 2], hpos, hrad, hstatus,
                        poses, circles)  # fmt: skip
            continue
        copy_of[n] = b
        n += 1
    dead_at = np.full(n_b, -1, dtype=np.int64)  # the step a copy stopped at (-1: never)

    # Lane-last copies of the state (humans × lanes).
    px = np.empty((n_h, n_b))
    py = np.empty((n_h, n_b))
    vx = np.empty((n_h, n_b))
    vy = np.empty((n_h, n_b))
    rad = np.empty((n_h, n_b))
    vpref = np.empty((n_h, n_b))
    delay = np.empty((n_h, n_b))
    homex = np.empty((n_h, n_b))
    homey = np.empty((n_h, n_b))
    status = np.empty((n_h, n_b), dtype=np.int8)
    wpi = np.empty((n_h, n_b), dtype=np.int64)
    nwp = np.empty((n_h, n_b), dtype=np.int64)
    release = np.empty((n_h, n_b), dtype=np.int64)
    reacts = np.empty((n_h, n_b), dtype=np.bool_)
    wait = np.empty((n_h, n_h, n_b), dtype=np.bool_)
    x = np.empty(n_b)
    y = np.empty(n_b)
    th = np.empty(n_b)
    v = np.empty(n_b)
    w = np.empty(n_b)
    tt = np.empty(n_b)
    pth = np.empty(n_b)
    for ln in range(n):
        b = copy_of[ln]
        x[ln] = robot[b, 0]
        y[ln] = robot[b, 1]
        th[ln] = robot[b, 2]
        # clip_command's np.clip, element by element (the same values)
        v[ln] = min(max(cmd[b, 0], v_min), v_max)
        w[ln] = min(max(cmd[b, 1], -omega_max), omega_max)
        tt[ln] = t[b]
        pth[ln] = path[b]
        for i in range(n_h):
            px[i, ln] = hpos[b, i, 0]
            py[i, ln] = hpos[b, i, 1]
            vx[i, ln] = hvel[b, i, 0]
            vy[i, ln] = hvel[b, i, 1]
            rad[i, ln] = hrad[b, i]
            vpref[i, ln] = hvpref[b, i]
            delay[i, ln] = hdelay[b, i]
            homex[i, ln] = hhome[b, i, 0]
            homey[i, ln] = hhome[b, i, 1]
            status[i, ln] = hstatus[b, i]
            wpi[i, ln] = hwpi[b, i]
            nwp[i, ln] = hnwp[b, i]
            release[i, ln] = hrelease[b, i]
            reacts[i, ln] = hreacts[b, i]
            for j in range(n_h):
                wait[i, j, ln] = hwait[b, i, j] != 0

    # Per-lane scratch.
    sag = np.empty(n_b)
    a_r = np.empty(n_b)
    t_now = np.empty(n_b)
    cmin = np.empty(n_b)
    wmin = np.empty(n_b)
    x1 = np.empty(n_b)
    y1 = np.empty(n_b)
    th1 = np.empty(n_b)
    ax = np.empty(n_b)
    ay = np.empty(n_b)
    dxs = np.empty(n_b)
    dys = np.empty(n_b)
    ds = np.empty(n_b)
    zs = np.empty(n_b)
    ok = np.empty(n_b, dtype=np.bool_)
    es = np.empty(n_b)
    e_scr = np.empty(n_b)
    ox = np.empty((n_h, n_b))
    oy = np.empty((n_h, n_b))
    present = np.empty((n_h, n_b), dtype=np.bool_)
    ready = np.empty((n_h, n_b), dtype=np.bool_)
    walking = np.empty((n_h, n_b), dtype=np.bool_)
    gx = np.empty((n_h, n_b))
    gy = np.empty((n_h, n_b))
    dg = np.empty((n_h, n_b))
    fx = np.empty((n_h, n_b))
    fy = np.empty((n_h, n_b))
    wall_d = np.empty((n_h, n_b))
    push = np.empty((n_h, n_b), dtype=np.bool_)
    half = np.empty(n_b)
    mxs = np.empty(n_b)
    mys = np.empty(n_b)
    best = np.empty(n_b)
    near = np.empty(n_b, dtype=np.int64)
    dmid = np.empty((m, n_b))

    for ln in range(n):
        sag[ln] = v[ln] * h * abs(w[ln] * h) / 8.0
        a_r[ln] = params[12] if abs(v[ln]) < params[13] else params[3]

    for k in range(n_l):
        for ln in range(n):
            cmin[ln] = np.inf
            wmin[ln] = np.inf
        for s in range(n_sub):
            for ln in range(n):
                t_now[ln] = tt[ln] + s * h
            for i in range(n_h):
                pxi, pyi, oxi, oyi, sti = px[i], py[i], ox[i], oy[i], status[i]
                pri = present[i]
                for ln in range(n):
                    oxi[ln] = pxi[ln]
                    oyi[ln] = pyi[ln]
                    pri[ln] = sti[ln] != GONE
            # Who walks to its waypoints (the others hold their home position).
            for i in range(n_h):
                rdy, sti, dli = ready[i], status[i], delay[i]
                for ln in range(n):
                    rdy[ln] = sti[ln] == WALKING and t_now[ln] >= dli[ln]
                for j in range(n_h):
                    wij, stj, wpj, rlj = wait[i, j], status[j], wpi[j], release[j]
                    for ln in range(n):
                        held = wij[ln] and stj[ln] == WALKING and wpj[ln] < rlj[ln]
                        rdy[ln] = rdy[ln] and not held
            # Targets (scalar: the waypoint bookkeeping branches).
            for i in range(n_h):
                for ln in range(n):
                    gx[i, ln] = px[i, ln]
                    gy[i, ln] = py[i, ln]
                    dg[i, ln] = 0.0
                    walking[i, ln] = False
                    if status[i, ln] != WALKING:
                        continue
                    qx = px[i, ln]
                    qy = py[i, ln]
                    if ready[i, ln]:
                        kk, tx, ty, dd, last = next_waypoint(
                            hwp, copy_of[ln], i, nwp[i, ln], wpi[i, ln], qx, qy, wp_tol
                        )
                        wpi[i, ln] = kk
                        if last and dd < g_tol:
                            status[i, ln] = ARRIVED
                            vx[i, ln] = 0.0
                            vy[i, ln] = 0.0
                            continue
                    else:
                        tx = homex[i, ln]
                        ty = homey[i, ln]
                        dd = norm2d(tx - qx, ty - qy)
                        if dd < 0.05:
                            dd = 0.0
                    gx[i, ln] = tx
                    gy[i, ln] = ty
                    dg[i, ln] = dd
                    walking[i, ln] = True
            # Forces from the positions at the substep's start, each sum in the reference's
            # order: drive, the other humans in index order, the robot, the walls in order.
            for i in range(n_h):
                pxi, pyi, ri = px[i], py[i], rad[i]
                gxi, gyi, dgi = gx[i], gy[i], dg[i]
                vxi, vyi, vpi = vx[i], vy[i], vpref[i]
                for ln in range(n):
                    d0 = dgi[ln]
                    ex = (gxi[ln] - pxi[ln]) / d0 if d0 > 0.0 else 0.0
                    ey = (gyi[ln] - pyi[ln]) / d0 if d0 > 0.0 else 0.0
                    ax[ln] = (vpi[ln] * ex - vxi[ln]) / tau
                    ay[ln] = (vpi[ln] * ey - vyi[ln]) / tau
                for j in range(n_h):
                    if j == i:
                        continue
                    pxj, pyj, rj, stj = px[j], py[j], rad[j], status[j]
                    n_ok = 0
                    for ln in range(n):
                        dx = pxi[ln] - pxj[ln]
                        dy = pyi[ln] - pyj[ln]
                        d = norm2d(dx, dy)
                        z = (ri[ln] + rj[ln] - d) / b_h
                        dxs[ln] = dx
                        dys[ln] = dy
                        ds[ln] = d
                        zs[ln] = z
                        ok[ln] = stj[ln] != GONE and d > 1e-9 and z > EXP_CUTOFF
                        n_ok += ok[ln]
                    if n_ok:  # (most pairs are out of range in every lane)
                        exp_where(zs, ok, es, e_scr, n, vector_exp)
                        _accumulate(ax, ay, a_h, es, dxs, dys, ds, ok, n)
                rei = reacts[i]
                for ln in range(n):
                    dx = pxi[ln] - x[ln]
                    dy = pyi[ln] - y[ln]
                    d = norm2d(dx, dy)
                    z = (ri[ln] + r_robot - d) / b_r
                    dxs[ln] = dx
                    dys[ln] = dy
                    ds[ln] = d
                    zs[ln] = z
                    ok[ln] = rei[ln] and a_r[ln] > 0.0 and d > 1e-9 and z > EXP_CUTOFF
                exp_where(zs, ok, es, e_scr, n, vector_exp)
                for ln in range(n):
                    mag = a_r[ln] * es[ln]
                    ax[ln] = ax[ln] + mag * dxs[ln] / ds[ln] if ok[ln] else ax[ln]
                    ay[ln] = ay[ln] + mag * dys[ln] / ds[ln] if ok[ln] else ay[ln]
                wdi = wall_d[i]
                for ln in range(n):
                    wdi[ln] = np.inf
                for q in range(m_pad):
                    wx1 = wall_tab[0, q]
                    wy1 = wall_tab[1, q]
                    wex = wall_tab[2, q]
                    wey = wall_tab[3, q]
                    wll = wall_tab[4, q]
                    n_ok = 0
                    for ln in range(n):
                        # wall_offsets' operations for one wall
                        qx = pxi[ln]
                        qy = pyi[ln]
                        sp = ((qx - wx1) * wex + (qy - wy1) * wey) / wll
                        sp = min(1.0, max(0.0, sp))
                        dx = qx - (wx1 + sp * wex)
                        dy = qy - (wy1 + sp * wey)
                        d = norm2d(dx, dy)
                        wdi[ln] = min(wdi[ln], d)
                        z = (ri[ln] - d) / b_w
                        dxs[ln] = dx
                        dys[ln] = dy
                        ds[ln] = d
                        zs[ln] = z
                        ok[ln] = d > 1e-9 and z > EXP_CUTOFF
                        n_ok += ok[ln]
                    if n_ok:  # (most walls are out of range in every lane)
                        exp_where(zs, ok, es, e_scr, n, vector_exp)
                        _accumulate(ax, ay, a_w, es, dxs, dys, ds, ok, n)
                fxi, fyi = fx[i], fy[i]
                for ln in range(n):
                    fxi[ln] = ax[ln]
                    fyi[ln] = ay[ln]
            # Integration with the speed cap; who needs pushing out of a wall.
            for i in range(n_h):
                pxi, pyi, vxi, vyi = px[i], py[i], vx[i], vy[i]
                fxi, fyi, wki, ri, vpi = fx[i], fy[i], walking[i], rad[i], vpref[i]
                wdi, pui = wall_d[i], push[i]
                for ln in range(n):
                    ux = vxi[ln] + fxi[ln] * h
                    uy = vyi[ln] + fyi[ln] * h
                    sp = norm2d(ux, uy)
                    vmax = cap * vpi[ln]
                    ux = ux * (vmax / sp) if sp > vmax else ux
                    uy = uy * (vmax / sp) if sp > vmax else uy
                    nx = pxi[ln] + ux * h
                    ny = pyi[ln] + uy * h
                    go = wki[ln]
                    pui[ln] = go and wdi[ln] - norm2d(ux * h, uy * h) <= ri[ln]
                    pxi[ln] = nx if go else pxi[ln]
                    pyi[ln] = ny if go else pyi[ln]
                    vxi[ln] = ux if go else vxi[ln]
                    vyi[ln] = uy if go else vyi[ln]
            # The rare branches, per lane as in the reference.
            for i in range(n_h):
                for ln in range(n):
                    if not walking[i, ln]:
                        continue
                    if push[i, ln]:
                        px[i, ln], py[i, ln], vx[i, ln], vy[i, ln] = push_out_of_walls(
                            px[i, ln], py[i, ln], vx[i, ln], vy[i, ln], rad[i, ln], walls
                        )
                    qx = px[i, ln]
                    qy = py[i, ln]
                    if ready[i, ln] and norm2d(vx[i, ln], vy[i, ln]) < settle_v:
                        b = copy_of[ln]
                        kk = wpi[i, ln]
                        dd = math.hypot(hwp[b, i, kk, 0] - qx, hwp[b, i, kk, 1] - qy)
                        if dd < settle_d:
                            if kk >= nwp[i, ln] - 1:
                                status[i, ln] = ARRIVED
                                vx[i, ln] = 0.0
                                vy[i, ln] = 0.0
                            else:
                                wpi[i, ln] = kk + 1
                    r = rad[i, ln]
                    outside = (
                        qx < bounds[0] - r
                        or qx > bounds[1] + r
                        or qy < bounds[2] - r
                        or qy > bounds[3] + r
                    )
                    if outside and ready[i, ln] and wpi[i, ln] >= nwp[i, ln] - 1:
                        status[i, ln] = GONE
                        vx[i, ln] = 0.0
                        vy[i, ln] = 0.0
            # The robot along its arc, then the swept gaps to the humans and the walls.
            for ln in range(n):
                x1[ln], y1[ln], th1[ln] = integrate_unicycle(x[ln], y[ln], th[ln], v[ln], w[ln], h)
            for i in range(n_h):
                oxi, oyi, pxi, pyi, pri, ri = ox[i], oy[i], px[i], py[i], present[i], rad[i]
                for ln in range(n):
                    # swept_point_distance's operations, its branch a select
                    d0x = oxi[ln] - x[ln]
                    d0y = oyi[ln] - y[ln]
                    ex = (pxi[ln] - x1[ln]) - d0x
                    ey = (pyi[ln] - y1[ln]) - d0y
                    ll = ex * ex + ey * ey
                    sp = -(d0x * ex + d0y * ey) / ll if ll > 0.0 else 0.0
                    sp = min(1.0, max(0.0, sp))
                    # where ll = 0, sp = 0 and d0 + 0·e = d0 exactly: the reference's branch
                    d = norm2d(d0x + sp * ex, d0y + sp * ey)
                    gap = d - r_robot - ri[ln] - sag[ln]
                    cmin[ln] = min(cmin[ln], gap) if pri[ln] else cmin[ln]
            # The walls as in the reference: the one nearest the chord's midpoint first, then
            # the others in order, each skipped when the cheap bound cannot lower the minimum.
            # The midpoint distances and the nearest wall's distance in lanes, the rest (a
            # wall near a corner) per lane.
            for ln in range(n):
                half[ln] = 0.5 * norm2d(x1[ln] - x[ln], y1[ln] - y[ln])
                mxs[ln] = 0.5 * (x[ln] + x1[ln])
                mys[ln] = 0.5 * (y[ln] + y1[ln])
                near[ln] = 0
            for q in range(m):
                wx1 = wall_tab[0, q]
                wy1 = wall_tab[1, q]
                wex = wall_tab[2, q]
                wey = wall_tab[3, q]
                wll = wall_tab[4, q]
                dq = dmid[q]
                for ln in range(n):  # wall_offsets' operations for one wall
                    sp = ((mxs[ln] - wx1) * wex + (mys[ln] - wy1) * wey) / wll
                    sp = min(1.0, max(0.0, sp))
                    dq[ln] = norm2d(mxs[ln] - (wx1 + sp * wex), mys[ln] - (wy1 + sp * wey))
                if q > 0:
                    for ln in range(n):
                        near[ln] = q if dq[ln] < best[ln] else near[ln]
                        best[ln] = dq[ln] if dq[ln] < best[ln] else best[ln]
                else:
                    for ln in range(n):
                        best[ln] = dq[ln]
            for ln in range(n if m > 0 else 0):
                q = near[ln]
                d = segment_segment_distance(
                    x[ln], y[ln], x1[ln], y1[ln], walls[q, 0], walls[q, 1], walls[q, 2],
                    walls[q, 3],
                )  # fmt: skip
                skip = best[ln] - half[ln] - r_robot - sag[ln] >= wmin[ln]
                wmin[ln] = wmin[ln] if skip else min(wmin[ln], d - r_robot - sag[ln])
            for ln in range(n):
                wm = wmin[ln]
                nr = near[ln]
                for q in range(m):
                    if q == nr or dmid[q, ln] - half[ln] - r_robot - sag[ln] >= wm:
                        continue
                    d = segment_segment_distance(
                        x[ln], y[ln], x1[ln], y1[ln], walls[q, 0], walls[q, 1], walls[q, 2],
                        walls[q, 3],
                    )  # fmt: skip
                    wm = min(wm, d - r_robot - sag[ln])
                wmin[ln] = wm
                x[ln] = x1[ln]
                y[ln] = y1[ln]
                th[ln] = th1[ln]
        # The step's end: bookkeeping and records, per copy.
        for ln in range(n):
            b = copy_of[ln]
            tt[ln] += dt
            pth[ln] += v[ln] * dt
            clear_out[b] = cmin[ln]
            wclear_out[b] = wmin[ln]
            if cmin[ln] < 0.0 or wmin[ln] < 0.0:
                collided[b] = True
            if not collided[b] and math.hypot(goal[b, 0] - x[ln], goal[b, 1] - y[ln]) < goal_tol:
                reached[b] = True
            clear_min[b] = min(clear_min[b], cmin[ln])
            wclear_min[b] = min(wclear_min[b], wmin[ln])
            for i in range(n_h):
                px_, py_ = px[i, ln], py[i, ln]
                circles[b, k, i, 0] = px_
                circles[b, k, i, 1] = py_
                circles[b, k, i, 2] = rad[i, ln] if status[i, ln] != GONE else 0.0
            poses[b, k, 0] = x[ln]
            poses[b, k, 1] = y[ln]
            poses[b, k, 2] = th[ln]
        if not stop:
            continue
        # Copies that collided in this step stop: write them back, hand their lane over.
        ln = 0
        while ln < n:
            b = copy_of[ln]
            if not collided[b]:
                ln += 1
                continue
            live_steps[b] = k + 1
            dead_at[b] = k
            _write_back(ln, b, x, y, th, v, w, tt, pth, px, py, vx, vy, status, wpi, robot,
                        cmd_out, t, path, hpos, hvel, hstatus, hwpi)  # fmt: skip
            n -= 1
            if ln != n:
                copy_of[ln] = copy_of[n]
                for a1 in (x, y, th, v, w, tt, pth, sag, a_r):
                    a1[ln] = a1[n]
                for a2 in (px, py, vx, vy, rad, vpref, delay, homex, homey):
                    _swap_lanes(a2, ln, n)
                _swap_lanes(status, ln, n)
                _swap_lanes(wpi, ln, n)
                _swap_lanes(nwp, ln, n)
                _swap_lanes(release, ln, n)
                _swap_lanes(reacts, ln, n)
                _swap_lanes(wait, ln, n)
    for ln in range(n):
        b = copy_of[ln]
        _write_back(ln, b, x, y, th, v, w, tt, pth, px, py, vx, vy, status, wpi, robot,
                    cmd_out, t, path, hpos, hvel, hstatus, hwpi)  # fmt: skip
    # A stopped copy's later records repeat its last step's.
    for b in range(n_b):
        k0 = dead_at[b]
        if k0 < 0:
            continue
        for k in range(k0 + 1, n_l):
            for c in range(3):
                poses[b, k, c] = poses[b, k0, c]
            for i in range(n_h):
                for c in range(3):
                    circles[b, k, i, c] = circles[b, k0, i, c]


@njit(cache=True, error_model="numpy", inline="always")
def _accumulate(
    ax: F64, ay: F64, a: float, es: F64, dxs: F64, dys: F64, ds: F64, ok: B8, n: int
) -> None:
    """``a_· += (A e^z) · d_·/d`` where ``ok`` (the reference's ``mag * dx / d``)."""
    for ln in range(n):
        mag = a * es[ln]
        ax[ln] = ax[ln] + mag * dxs[ln] / ds[ln] if ok[ln] else ax[ln]
        ay[ln] = ay[ln] + mag * dys[ln] / ds[ln] if ok[ln] else ay[ln]


@njit(cache=True, error_model="numpy", inline="always")
def _record(
    b: int, k: int, rx: float, ry: float, rth: float, hpos: F64, hrad: F64, hstatus: Any,
    poses: F64, circles: F64,
) -> None:  # fmt: skip
    """Record copy ``b``'s pose and humans (B-major state) as step ``k``'s."""
    poses[b, k, 0] = rx
    poses[b, k, 1] = ry
    poses[b, k, 2] = rth
    for i in range(hpos.shape[1]):
        circles[b, k, i, 0] = hpos[b, i, 0]
        circles[b, k, i, 1] = hpos[b, i, 1]
        circles[b, k, i, 2] = hrad[b, i] if hstatus[b, i] != GONE else 0.0


@njit(cache=True, error_model="numpy", inline="always")
def _write_back(
    ln: int, b: int, x: F64, y: F64, th: F64, v: F64, w: F64, tt: F64, pth: F64,
    px: F64, py: F64, vx: F64, vy: F64, status: Any, wpi: I64,
    robot: F64, cmd_out: F64, t: F64, path: F64, hpos: F64, hvel: F64, hstatus: Any, hwpi: I64,
) -> None:  # fmt: skip
    """Lane ``ln``'s state into copy ``b`` of the (B-major) state arrays."""
    robot[b, 0] = x[ln]
    robot[b, 1] = y[ln]
    robot[b, 2] = th[ln]
    cmd_out[b, 0] = v[ln]
    cmd_out[b, 1] = w[ln]
    t[b] = tt[ln]
    path[b] = pth[ln]
    for i in range(px.shape[0]):
        hpos[b, i, 0] = px[i, ln]
        hpos[b, i, 1] = py[i, ln]
        hvel[b, i, 0] = vx[i, ln]
        hvel[b, i, 1] = vy[i, ln]
        hstatus[b, i] = status[i, ln]
        hwpi[b, i] = wpi[i, ln]
