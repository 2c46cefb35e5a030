"""The ``cvar-bf`` policy: nominal go-to-goal command filtered by the adaptive CVaR barriers
(formulation in :mod:`pioneer.baselines.cvar_bf`)."""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from typing import Any

import numpy as np
import scipy.optimize
from numpy.typing import NDArray

from pioneer.baselines.cvar_bf.barriers import (
    dynamic_zone_barrier,
    lookahead_jacobian,
    lookahead_point,
    wall_barrier,
)
from pioneer.baselines.cvar_bf.config import CvarBfConfig
from pioneer.baselines.cvar_bf.qp import (
    CvarDecision,
    QPResult,
    _Linearised,
    _OsqpWorkspace,
    cut_rows,
    lifted_solution,
    qp_2d,
    select_beta,
    wall_rows,
)
from pioneer.errors import ConfigError, expect
from pioneer.sim.humans import GONE
from pioneer.sim.world import State, World

__all__ = ["CvarBfPolicy", "make_cvar_bf"]

F64 = NDArray[np.float64]
# OSQP statuses whose iterate is used; an inaccurate or unconverged one still counts if it
# satisfies every constraint (checked exactly after the solve): a feasible command.
_USABLE = ("solved", "solved inaccurate", "maximum iterations reached")


class CvarBfPolicy:
    """CVaR-BF as a :class:`~pioneer.envs.policy.Policy` (privileged: reads ``info["state"]``).

    See the module docstring for the formulation. ``rng`` given to ``reset`` seeds the
    sampling of human positions; the global numpy RNG is never used.
    """

    def __init__(self, config: CvarBfConfig | None = None, name: str = "cvar-bf") -> None:
        self.config = config or CvarBfConfig()
        self.name = name
        self._rng = np.random.default_rng(0)
        self.last: CvarDecision | None = None
        self.n_decisions = 0
        self.n_solves = 0
        self.n_infeasible = 0
        self.n_fallback = 0
        self.betas: list[float] = []
        self.solve_times: list[float] = []
        self._ws: _OsqpWorkspace | None = None

    def reset(self, info: Mapping[str, Any], rng: np.random.Generator) -> None:
        """Seed the sampling generator from ``rng``; clear the per-episode lists."""
        self._rng = np.random.default_rng(rng.integers(0, 2**63 - 1))
        self._ws = None  # a fresh solver workspace: an episode does not depend on the last one
        self.last = None
        self.betas = []
        self.solve_times = []

    def act(self, obs: NDArray[np.float32], info: Mapping[str, Any]) -> F64:
        """Decide from the privileged ``info["state"]`` and ``info["world"]``."""
        self.last = self.decide(info["world"], info["state"])
        return self.last.command

    # -------------------------------------------------------------------------- pieces
    def nominal(self, world: World, state: State) -> F64:
        """Proportional go-to-goal command u_nom = (v [m/s], ω [rad/s])."""
        cfg, rob = self.config, world.sim.robot
        x, y, th = state.robot[0]
        dx, dy = state.goal[0, 0] - x, state.goal[0, 1] - y
        phi = math.remainder(math.atan2(dy, dx) - th, 2.0 * math.pi)
        w = float(np.clip(cfg.k_omega * phi, -rob.omega_max, rob.omega_max))
        v_cap = min(cfg.v_nominal, rob.v_max)
        v = v_cap * max(0.0, math.cos(phi)) * min(1.0, math.hypot(dx, dy) / cfg.slow_distance)
        return np.array([max(v, rob.v_min), w])

    def sample_humans(
        self, state: State, idx: NDArray[np.int64], dt: float
    ) -> tuple[F64, F64, F64]:
        """S sampled next positions ``(N, S, 2)`` [m], the velocities their dynamic zones use
        ``(N, S, 2)`` [m/s] (the predicted v_o) and probabilities ``(N, S)`` of the humans
        ``idx``: constant velocity plus Gaussian noise, from the policy's own generator."""
        cfg = self.config
        n, s = len(idx), cfg.n_samples
        w_x = self._rng.normal(0.0, cfg.sigma_pos, (n, s, 2))
        w_u = self._rng.normal(0.0, cfg.sigma_vel, (n, s, 2))
        v_o = np.broadcast_to(state.h_vel[0, idx][:, None, :], (n, s, 2))
        p_hat = state.h_pos[0, idx][:, None, :] + (v_o + w_u) * dt + w_x
        log_p = -0.5 * ((w_x**2).sum(-1) / cfg.sigma_pos**2 + (w_u**2).sum(-1) / cfg.sigma_vel**2)
        p = np.exp(log_p - log_p.max(axis=1, keepdims=True))
        return p_hat, v_o, p / p.sum(axis=1, keepdims=True)

    def barrier_at(
        self, world: World, pose: F64, command: F64, decision: CvarDecision | None = None
    ) -> tuple[F64, F64]:
        """Nonlinear barriers of a decision's samples at robot ``pose`` (3,) with the command
        ``command`` held: human barriers ``(N, S)`` and wall barriers ``(M,)`` [m²].

        Evaluated at the true next pose this checks the linearisation (see the tests).
        """
        d = decision or self.last
        if d is None:
            raise ConfigError(expect("barrier_at", "a decision", None, "call act() first"))
        ell = self.config.lookahead
        p_l = lookahead_point(pose, ell)
        v_r = lookahead_jacobian(float(pose[2]), ell) @ np.asarray(command, dtype=np.float64)
        cfg = self.config
        h, _, _ = dynamic_zone_barrier(
            p_l,
            v_r,
            d.samples_pos,
            d.samples_vel,
            d.radius[:, None],
            cfg.rho,
            cfg.v_hat,
            cfg.eps_vel,
        )
        r_w = world.sim.robot.radius + ell + cfg.wall_margin  # walls: always cover the body
        hw, _ = wall_barrier(p_l, world.walls, r_w)
        return h, hw

    def linearise(self, world: World, state: State) -> tuple[_Linearised, dict[str, Any]]:
        """Sample the humans and linearise every barrier around u_nom (one decision's data)."""
        cfg = self.config
        idx = np.flatnonzero(state.h_status[0] != GONE).astype(np.int64)
        infl = cfg.lookahead if cfg.cover_body else 0.0
        radius = world.sim.robot.radius + infl + state.h_radius[0, idx] + cfg.margin
        p_hat, v_hat, prob = self.sample_humans(state, idx, world.sim.dt)
        extra = {
            "humans": idx,
            "radius": radius,
            "samples_pos": p_hat,
            "samples_vel": v_hat,
            "weights": prob,
        }
        u_nom = self.nominal(world, state)
        return self.linearise_at(world, state, extra, u_nom, u_nom), extra

    def linearise_at(
        self, world: World, state: State, extra: dict[str, Any], u_nom: F64, u_lin: F64
    ) -> _Linearised:
        """The barriers of the samples in ``extra`` linearised around the command ``u_lin``."""
        cfg = self.config
        dt = world.sim.dt
        ell = cfg.lookahead
        idx, radius = extra["humans"], extra["radius"]
        pose = state.robot[0]
        jac = lookahead_jacobian(float(pose[2]), ell)
        p_l = lookahead_point(pose, ell)
        v_k = jac @ state.command[0]  # look-ahead point velocity under the last command
        v_n = jac @ u_lin
        p_n = p_l + v_n * dt  # next look-ahead point under u_lin
        h_k, _, _ = dynamic_zone_barrier(
            p_l,
            v_k,
            state.h_pos[0, idx],
            state.h_vel[0, idx],
            radius,
            cfg.rho,
            cfg.v_hat,
            cfg.eps_vel,
        )
        h0, dh_dp, dh_dv = dynamic_zone_barrier(
            p_n,
            v_n,
            extra["samples_pos"],
            extra["samples_vel"],
            radius[:, None],
            cfg.rho,
            cfg.v_hat,
            cfg.eps_vel,
            grad=True,
        )
        g = (dh_dp * dt + dh_dv) @ jac  # ∇_u h_s: p_l⁺ = p_l + J u Δt, v_r = J u
        r_w = world.sim.robot.radius + ell + cfg.wall_margin  # walls: always cover the body
        hw_k, _ = wall_barrier(p_l, world.walls, r_w)
        hw0, dhw = wall_barrier(p_n, world.walls, r_w)
        return _Linearised(
            u_nom.copy(), u_lin.copy(), h_k, h0, g, extra["weights"], hw_k, hw0, dhw @ jac * dt
        )

    def solve(self, world: World, lin: _Linearised, beta: float) -> QPResult:
        """The CVaR-BF QP at risk level ``beta`` (fast path if u_nom is feasible)."""
        cfg = self.config
        if np.array_equal(lin.u_lin, lin.u_nom) and self._violation(
            world, lin, beta, lin.u_nom
        ) <= (cfg.feasibility_tol):
            z = lifted_solution(lin, beta, lin.u_nom)
            return QPResult(True, lin.u_nom.copy(), z, 0.0, False, "nominal feasible")
        if cfg.solver in ("exact", "osqp"):
            return self._solve_cuts(world, lin, beta)
        n, _ = lin.h0.shape
        mat, off = self._constraints(lin, beta)
        self.n_solves += 1
        z, success, message = self._solve_slsqp(world, lin, mat, off)
        rob = world.sim.robot
        u = np.clip(z[:2], rob.command_low, rob.command_high)
        viol = max(
            float(max(0.0, -(mat @ z + off).min(initial=np.inf))),
            float(np.abs(u - z[:2]).max()),
            float(max(0.0, -z[2 + n :].min(initial=0.0))),
        )
        return QPResult(success and viol <= cfg.feasibility_tol, u, z, viol, True, message)

    def _violation(self, world: World, lin: _Linearised, beta: float, u: F64) -> float:
        """Largest violation [m²] of the linearised CVaR and wall constraints at ``u`` (exact:
        the CVaR of the samples, not a cut), and of the command box."""
        gam = self.config.gamma
        val, need, _, _ = cut_rows(lin, beta, gam, u)
        wc, wl = wall_rows(lin, gam)
        rob = world.sim.robot
        return max(
            float(np.max(need - val, initial=0.0)),
            float(np.max(wl - wc @ u, initial=0.0)),
            float(np.max(rob.command_low - u, initial=0.0)),
            float(np.max(u - rob.command_high, initial=0.0)),
        )

    def _solve_cuts(self, world: World, lin: _Linearised, beta: float) -> QPResult:
        """The QP in u alone by cutting planes (Kelley): minimise the cost over the box, the
        walls and the cuts found so far (a relaxation of the CVaR constraints) with
        :func:`qp_2d` (``solver="exact"``) or OSQP (``"osqp"``); add a cut for every human whose
        exact CVaR constraint the solution violates, until none is. The last solution is then
        the QP's optimum (optimal for a relaxation and feasible); an empty relaxation proves
        the level infeasible."""
        cfg = self.config
        gam, tol = cfg.gamma, cfg.feasibility_tol
        rob = world.sim.robot
        n = lin.h0.shape[0]
        w = np.array([cfg.weight_v, cfg.weight_omega])
        wc, wl = wall_rows(lin, gam)
        coef: list[F64] = [np.eye(2), wc]
        lo: list[F64] = [rob.command_low, wl]
        hi: list[F64] = [rob.command_high, np.full(wl.shape, np.inf)]

        def add_cuts(u: F64) -> bool:
            val, need, c, b = cut_rows(lin, beta, gam, u)
            bad = val < need - tol
            coef.append(c[bad])
            lo.append(b[bad])
            hi.append(np.full(int(bad.sum()), np.inf))
            return bool(bad.any())

        add_cuts(lin.u_nom)
        if not np.array_equal(lin.u_lin, lin.u_nom):
            add_cuts(lin.u_lin)  # a refined solve: the previous solution's cuts too
        u, status = lin.u_nom, ""
        x: F64 | None
        for _ in range(cfg.max_rounds):
            a, b = np.concatenate(coef), np.concatenate(lo)
            if np.all(a @ lin.u_nom >= b):
                x, status = lin.u_nom.copy(), "solved"  # the cost's minimum is feasible
            elif cfg.solver == "exact":
                fin = np.concatenate(hi) < np.inf  # the box's upper bounds as rows −u ≥ −hi
                x = qp_2d(
                    w,
                    lin.u_nom,
                    np.concatenate([a, -a[fin]]),
                    np.concatenate([b, -np.concatenate(hi)[fin]]),
                )
                status = "solved" if x is not None else "primal infeasible"
                self.n_solves += 1
            else:
                x, status = self._workspace(world, n, a.shape[0]).solve(
                    lin.u_nom, a, b, np.concatenate(hi)
                )
                self.n_solves += 1
            if x is None or status not in _USABLE:
                break
            u = np.clip(x, rob.command_low, rob.command_high)
            if not add_cuts(u):
                break
        else:
            status = "cut limit reached"
        viol = self._violation(world, lin, beta, u)
        ok = status in _USABLE and viol <= tol
        return QPResult(ok, u, lifted_solution(lin, beta, u), viol, True, status)

    def _workspace(self, world: World, n: int, rows: int) -> _OsqpWorkspace:
        """The policy's OSQP workspace, re-made larger when ``rows`` exceed its capacity."""
        ws = self._ws
        if ws is None or ws.capacity < rows:
            cap = max(
                rows, 2 + world.walls.shape[0] + 4 * max(n, 1), 2 * (ws.capacity if ws else 0)
            )
            ws = self._ws = _OsqpWorkspace(self.config, cap)
        return ws

    def _bounds(self, world: World, n: int, s: int) -> tuple[F64, F64]:
        """Variable bounds of z: the command box, ζ free, η ≥ 0."""
        rob = world.sim.robot
        lo = np.concatenate([rob.command_low, np.full(n, -np.inf), np.zeros(n * s)])
        hi = np.concatenate([rob.command_high, np.full(n + n * s, np.inf)])
        return lo, hi

    def _solve_slsqp(
        self, world: World, lin: _Linearised, mat: F64, off: F64
    ) -> tuple[F64, bool, str]:
        cfg = self.config
        n, s = lin.h0.shape
        u0 = lin.u_nom
        w = np.array([cfg.weight_v, cfg.weight_omega])

        def cost(z: F64) -> tuple[float, F64]:
            du = z[:2] - u0
            grad = np.zeros_like(z)
            grad[:2] = 2.0 * w * du
            return float((w * du * du).sum()), grad

        lo, hi = self._bounds(world, n, s)
        z0 = np.concatenate([lin.u_lin, -lin.h0.min(axis=1) if n else np.zeros(0), np.zeros(n * s)])
        res = scipy.optimize.minimize(
            cost,
            z0,
            jac=True,
            method="SLSQP",
            bounds=scipy.optimize.Bounds(lo, hi),
            constraints=[{"type": "ineq", "fun": lambda z: mat @ z + off, "jac": lambda z: mat}],
            options={"maxiter": cfg.max_iter, "ftol": 1e-10},
        )
        return np.asarray(res.x, dtype=np.float64), bool(res.success), str(res.message)

    def _constraints(self, lin: _Linearised, beta: float) -> tuple[F64, F64]:
        """``mat z + off ≥ 0`` for z = (v, ω, ζ_1…ζ_N, η_11…η_NS)."""
        n, s = lin.h0.shape
        m = lin.hw0.shape[0]
        nv = 2 + n + n * s
        mat = np.zeros((n * s + n + m, nv))
        off = np.empty(n * s + n + m)
        rows = np.arange(n * s)
        hum = np.repeat(np.arange(n), s)
        # η_js + ζ_j + h_js(u) ≥ 0, h_js(u) = h0_js + g_jsᵀ (u − u_nom)
        mat[rows, :2] = lin.g.reshape(-1, 2)
        mat[rows, 2 + hum] = 1.0
        mat[rows, 2 + n + rows] = 1.0
        off[: n * s] = lin.h0.ravel() - lin.g.reshape(-1, 2) @ lin.u_lin
        # −(1 − γ) h_k,j − ζ_j − (1/β) Σ_s p_js η_js ≥ 0
        r = n * s + np.arange(n)
        mat[r, 2 + np.arange(n)] = -1.0
        mat[r[hum], 2 + n + rows] = -lin.p.ravel() / beta
        off[n * s : n * s + n] = -(1.0 - self.config.gamma) * lin.h_k
        # walls: hw0 + gwᵀ (u − u_nom) − (1 − γ) hw_k ≥ 0
        mat[n * s + n :, :2] = lin.gw
        off[n * s + n :] = lin.hw0 - lin.gw @ lin.u_lin - (1.0 - self.config.gamma) * lin.hw_k
        return mat, off

    def decide(self, world: World, state: State, prev: F64 | None = None) -> CvarDecision:
        """One decision from ``state`` (B = 1): adaptive-β QP, or the fallback (the last
        command is the state's; ``prev`` is not used)."""
        cfg = self.config
        t0 = time.perf_counter()
        lin, extra = self.linearise(world, state)
        solves_before = self.n_solves
        i, res, n_failed = select_beta(lambda b: self.solve(world, lin, b), cfg.betas)
        for _ in range(cfg.refine if res is not None and res.solver_call else 0):
            # Sequential linearisation: the same samples, linearised at the last solution.
            lin_r = self.linearise_at(world, state, extra, lin.u_nom, res.u)  # type: ignore[union-attr]
            res_r = self.solve(world, lin_r, cfg.betas[i])
            if not res_r.ok:
                break
            lin, res = lin_r, res_r
        self.n_decisions += 1
        self.n_infeasible += n_failed
        if res is None:
            self.n_fallback += 1
            rob = world.sim.robot
            w = float(np.clip(lin.u_nom[1], -cfg.fallback_omega, cfg.fallback_omega))
            command = np.array([rob.v_min, np.clip(w, -rob.omega_max, rob.omega_max)])
            beta = math.nan
        else:
            command = res.u
            beta = cfg.betas[i]
        du = command - lin.u_lin
        dt_solve = time.perf_counter() - t0
        self.betas.append(beta)
        self.solve_times.append(dt_solve)
        return CvarDecision(
            command=command.copy(),
            nominal=lin.u_nom.copy(),
            pose=state.robot[0].copy(),
            beta=beta,
            beta_index=i,
            n_infeasible=n_failed,
            n_solver_calls=self.n_solves - solves_before,
            fast_path=res is not None and not res.solver_call,
            fallback=res is None,
            solve_time=dt_solve,
            humans=extra["humans"],
            radius=extra["radius"],
            h_k=lin.h_k,
            h_lin=lin.h0 + lin.g @ du,
            samples_pos=extra["samples_pos"],
            samples_vel=extra["samples_vel"],
            weights=lin.p,
            wall_h_k=lin.hw_k,
            wall_h_lin=lin.hw0 + lin.gw @ du,
        )


def make_cvar_bf(**overrides: Any) -> CvarBfPolicy:
    """``cvar-bf`` with optional :class:`CvarBfConfig` overrides (e.g. ``lookahead=0.2``)."""
    return CvarBfPolicy(CvarBfConfig.from_dict(overrides) if overrides else None)
