"""The CVaR-BF quadratic programme: risk-level selection, the decision record and the OSQP
workspace (formulation in :mod:`pioneer.baselines.cvar_bf`)."""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pioneer.baselines.cvar_bf.config import CvarBfConfig
from pioneer.errors import ConfigError, expect
from pioneer.sim.world import World

__all__ = ["CvarDecision", "QPResult", "select_beta"]

F64 = NDArray[np.float64]


@dataclasses.dataclass(frozen=True)
class QPResult:
    """One solve of the CVaR-BF QP at one risk level β."""

    ok: bool  # feasible: solver success and every constraint within the tolerance
    u: F64  # (2,) command (v [m/s], ω [rad/s]); meaningless unless ok
    z: F64  # (2 + N + N·S,) full solution (u, ζ, η)
    violation: float  # largest constraint violation at z [m²]
    solver_call: bool  # False: u_nom was already feasible (fast path)
    message: str


def select_beta(
    solve: Callable[[float], QPResult], betas: Sequence[float]
) -> tuple[int, QPResult | None, int]:
    """Adaptive risk: try ``betas`` in order, keep the first feasible solve.

    Returns ``(index, result, n_failed)``; ``(-1, None, len(betas))`` when no level is feasible.
    """
    for i, beta in enumerate(betas):
        res = solve(beta)
        if res.ok:
            return i, res, i
    return -1, None, len(betas)


@dataclasses.dataclass(frozen=True)
class _Linearised:
    """The constraint data of one decision, linear in u (β enters only the CVaR rows)."""

    u_nom: F64  # (2,) the nominal command (the cost's target)
    u_lin: F64  # (2,) the linearisation point (u_nom, or a refined solution)
    h_k: F64  # (N,) h(x_k)
    h0: F64  # (N, S) h_s(u_lin)
    g: F64  # (N, S, 2) ∇_u h_s(u_lin)
    p: F64  # (N, S) sample probabilities
    hw_k: F64  # (M,) wall barriers at x_k
    hw0: F64  # (M,) wall barriers at the next state under u_lin
    gw: F64  # (M, 2) their gradients in u


@dataclasses.dataclass(frozen=True)
class CvarDecision:
    """One CVaR-BF decision: command, chosen risk level and the barrier data behind it."""

    command: F64  # (2,) the command sent (v [m/s], ω [rad/s])
    nominal: F64  # (2,) u_nom
    pose: F64  # (3,) robot pose x_k the decision was made from
    beta: float  # chosen β (NaN at a fallback)
    beta_index: int  # index into ``CvarBfConfig.betas`` (−1 at a fallback)
    n_infeasible: int  # β levels found infeasible in this decision
    n_solver_calls: int  # SLSQP calls in this decision
    fast_path: bool  # u_nom was feasible at the chosen β (no solver call)
    fallback: bool  # no β feasible: stop and turn toward the goal
    solve_time: float  # [s] wall time of the decision
    humans: NDArray[np.int64]  # (N,) indices of the constrained humans
    radius: F64  # (N,) R [m]
    h_k: F64  # (N,) h(x_k) [m²]
    h_lin: F64  # (N, S) linearised h_s(u) at the sent command [m²]
    samples_pos: F64  # (N, S, 2) sampled next human positions p̂ [m]
    samples_vel: F64  # (N, S, 2) sampled human velocities v̂ [m/s]
    weights: F64  # (N, S) sample probabilities p_s
    wall_h_k: F64  # (M,) wall barriers at x_k [m²]
    wall_h_lin: F64  # (M,) linearised wall barriers at the sent command [m²]


def _pattern(n: int, s: int, m: int) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Structural non-zeros (rows, cols) of the constraint matrix of ``_constraints``."""
    ns = n * s
    k = np.arange(ns)
    hum = np.repeat(np.arange(n), s)
    r_a = np.repeat(k, 4)  # CVaR sample rows: v, ω, ζ_j, η_js
    c_a = np.stack([np.zeros(ns, np.int64), np.ones(ns, np.int64), 2 + hum, 2 + n + k], 1)
    r_b = np.concatenate([ns + np.arange(n), ns + hum])  # CVaR rows: ζ_j and every η_j·
    c_b = np.concatenate([2 + np.arange(n), 2 + n + k])
    r_w = np.repeat(ns + n + np.arange(m), 2)  # wall rows: v, ω
    c_w = np.tile(np.array([0, 1]), m)
    return (
        np.concatenate([r_a, r_b, r_w]).astype(np.int64),
        np.concatenate([c_a.ravel(), c_b, c_w]).astype(np.int64),
    )


@functools.lru_cache(maxsize=64)
def _csc_layout(n: int, s: int, m: int, n_con: int) -> tuple[Any, Any, Any, Any]:
    """The constraint matrix's layout for n humans, s samples, m walls (cached per shape: a
    CSC conversion per decision cost ≈ 1 ms): pattern rows and cols, the CSC structure with the
    v, ω, η box rows appended, and the permutation from triplet order to CSC slots."""
    import scipy.sparse as sp

    rows, cols = _pattern(n, s, m)
    box = np.concatenate([[0, 1], 2 + n + np.arange(n * s)]).astype(np.int64)  # v, ω, η
    all_rows = np.concatenate([rows, n_con + np.arange(box.size)])
    all_cols = np.concatenate([cols, box])
    tag = np.arange(1, all_rows.size + 1, dtype=np.float64)
    order = sp.csc_matrix((tag, (all_rows, all_cols)), shape=(n_con + box.size, 2 + n + n * s))
    perm = order.data.astype(np.int64) - 1  # CSC slot → triplet index
    for a in (rows, cols, order.indices, order.indptr, order.data, perm):
        a.setflags(write=False)  # shared by every workspace of this shape
    return rows, cols, order, perm


@functools.cache
def _osqp_algebra() -> str:
    """OSQP's default linear-algebra backend, looked up once: ``osqp.OSQP()`` looks it up on
    every construction by trying to import the CUDA and MKL backends first, and the two failing
    imports cost ≈ 0.7 ms per decision (the same backend either way)."""
    import osqp

    return str(osqp.default_algebra())


class _OsqpWorkspace:
    """The OSQP problem of one decision. Across β only the values of the CVaR rows change, so
    the sparsity pattern is fixed: the later solves update the matrix and warm-start."""

    def __init__(self, world: World, lin: _Linearised, off: F64, cfg: CvarBfConfig) -> None:
        try:
            import osqp
        except ImportError as exc:  # pragma: no cover - osqp is a dependency
            raise ConfigError(
                expect("CvarBfConfig.solver", "an installed osqp", "osqp", "pip install osqp")
            ) from exc
        import scipy.sparse as sp

        self.lin = lin
        n, s = lin.h0.shape
        n_con = off.shape[0]
        nv = 2 + n + n * s
        rob = world.sim.robot
        self.rows, self.cols, self.order, self.perm = _csc_layout(n, s, lin.hw0.shape[0], n_con)
        self.n_box = self.order.shape[0] - n_con  # v, ω, η box rows
        self.lo = np.concatenate([-off, rob.command_low, np.zeros(n * s)])
        self.hi = np.concatenate([np.full(n_con, np.inf), rob.command_high, np.full(n * s, np.inf)])
        w2 = 2.0 * np.array([cfg.weight_v, cfg.weight_omega])
        self.p_mat = sp.csc_matrix((w2, ([0, 1], [0, 1])), shape=(nv, nv))
        self.q = np.zeros(nv)
        self.q[:2] = -w2 * lin.u_nom
        self.cfg = cfg
        self.prob = osqp.OSQP(algebra=_osqp_algebra())
        self.ready = False
        zeta = -lin.h0.min(axis=1) if n else np.zeros(0)
        self.z = np.concatenate([lin.u_lin, zeta, np.zeros(n * s)])

    def solve(self, mat: F64) -> tuple[F64, bool, str]:
        """Solve with the constraint values of ``mat`` (dense, the pattern of ``_pattern``)."""
        import scipy.sparse as sp

        vals = np.concatenate([mat[self.rows, self.cols], np.ones(self.n_box)])[self.perm]
        if not self.ready:
            o = self.order
            a = sp.csc_matrix((vals, o.indices, o.indptr), shape=o.shape)
            self.prob.setup(
                self.p_mat,
                self.q,
                a,
                self.lo,
                self.hi,
                verbose=False,
                eps_abs=1e-6,
                eps_rel=1e-6,
                max_iter=self.cfg.max_iter,
                polishing=True,
            )
            self.ready = True
        else:
            self.prob.update(Ax=vals)
        self.prob.warm_start(x=self.z)
        res = self.prob.solve(raise_error=False)
        status = str(res.info.status)
        if res.x is None or not np.all(np.isfinite(res.x)):
            return self.z, False, status
        x = np.asarray(res.x, dtype=np.float64)
        # An unconverged or inaccurate iterate still counts if it satisfies every constraint
        # (checked by the caller): it is a feasible, slightly suboptimal command.
        usable = status in ("solved", "solved inaccurate", "maximum iterations reached")
        if usable:
            self.z = x
        return x, usable, status
