"""The CVaR-BF quadratic programme: risk-level selection, the decision record and the OSQP
workspace (formulation in :mod:`pioneer.baselines.cvar_bf`)."""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

from pioneer.baselines.cvar_bf.barriers import cvar_weights
from pioneer.baselines.cvar_bf.config import CvarBfConfig
from pioneer.envs.policy import Decision
from pioneer.errors import ConfigError, expect

__all__ = ["CvarDecision", "QPResult", "cut_rows", "lifted_solution", "select_beta", "wall_rows"]

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
    """Adaptive risk: the first feasible level of ``betas`` (increasing), found by bisection.

    Feasibility grows with β (a point feasible at β is feasible at every β' > β: the CVaR
    row's η terms, η ≥ 0, shrink by β/β'), so the levels split into infeasible ones followed
    by feasible ones. The most conservative level is tried first (the usual answer), then the
    least (if it fails, none is feasible), then the gap between the last infeasible and the
    first feasible level found is halved: at most 2 + ⌈log₂(len − 1)⌉ solves, against up to
    ``len`` in order; the same level as in order as long as the solves' verdicts are monotone
    (near-ties within the feasibility tolerance may break either way).

    Returns ``(index, result, n_failed)``, n_failed = index (the levels below it are
    infeasible); ``(-1, None, len(betas))`` when no level is feasible.
    """
    k = len(betas)
    res = solve(betas[0])
    if res.ok:
        return 0, res, 0
    if k == 1 or not (res := solve(betas[-1])).ok:
        return -1, None, k
    lo, hi = 0, k - 1  # lo infeasible, hi feasible with result ``res``
    while hi - lo > 1:
        mid = (lo + hi) // 2
        r = solve(betas[mid])
        if r.ok:
            hi, res = mid, r
        else:
            lo = mid
    return hi, res, hi


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
class CvarDecision(Decision):
    """One CVaR-BF decision: the command sent, the chosen risk level and the barrier data
    behind it."""

    nominal: F64  # (2,) u_nom
    pose: F64  # (3,) robot pose x_k the decision was made from
    beta: float  # chosen β (NaN at a fallback)
    beta_index: int  # index into ``CvarBfConfig.betas`` (−1 at a fallback)
    n_infeasible: int  # β levels below the chosen one (infeasible; all of them at a fallback)
    n_solver_calls: int  # solver calls (2-D QPs, or SLSQP runs) in this decision
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


def cut_rows(lin: _Linearised, beta: float, gamma: float, u: F64) -> tuple[F64, F64, F64, F64]:
    """The CVaR constraints of every human at the point ``u`` (2,): their values
    CVaR_β(h_j(u)) ``(N,)``, bounds (1 − γ) h_k,j ``(N,)`` and the supporting cuts
    ``coef (N, 2)``, ``lo (N,)`` with ``coef_j · u' ≥ lo_j`` for every feasible u'.

    CVaR_β(h(u)) = min over q of Σ_s q_s h_s(u) with 0 ≤ q_s ≤ p_s/β, Σ q_s = 1; the minimising
    tail weights q* at ``u`` (:func:`cvar_weights`) give a linear upper bound
    Σ q*_s h_s(u') ≥ CVaR_β(h(u')) that equals it at ``u``, so Σ q*_s h_s(u') ≥ (1 − γ) h_k is
    implied by the constraint (a valid cut) and is violated at ``u`` when the constraint is.
    """
    a = lin.h0 - lin.g @ lin.u_lin  # h_s(u) = a_s + g_s · u
    h = a + lin.g @ u
    q = cvar_weights(h, lin.p, beta)
    need = (1.0 - gamma) * lin.h_k
    coef = np.einsum("ns,nsk->nk", q, lin.g)
    return (q * h).sum(-1), need, coef, need - (q * a).sum(-1)


def wall_rows(lin: _Linearised, gamma: float) -> tuple[F64, F64]:
    """The linearised wall constraints as rows ``coef (M, 2) · u ≥ lo (M,)``."""
    return lin.gw, (1.0 - gamma) * lin.hw_k - lin.hw0 + lin.gw @ lin.u_lin


def lifted_solution(lin: _Linearised, beta: float, u: F64) -> F64:
    """z = (u, ζ, η) of the Rockafellar–Uryasev form at the command ``u``: ζ_j = −VaR (the
    sample where the tail weights end), η_js = max(0, −h_js(u) − ζ_j)."""
    h = lin.h0 + lin.g @ (u - lin.u_lin)
    q = cvar_weights(h, lin.p, beta)
    zeta = -np.where(q > 0.0, h, -np.inf).max(axis=1, initial=-np.inf)
    eta = np.maximum(0.0, -h - zeta[:, None])
    return np.concatenate([u, zeta, eta.ravel()])


def qp_2d(w: F64, u0: F64, a: F64, lo: F64, tol: float = 1e-9) -> F64 | None:
    """min Σ_i w_i (u_i − u0_i)² over u ∈ R² with ``a u ≥ lo`` (``a (R, 2)``, ``lo (R,)``),
    exactly; None if no point satisfies every row to ``tol``.

    The objective is strictly convex, so the optimum is the point of least cost among those
    where 0, 1 or 2 (independent) rows hold with equality that satisfy every row: u0, its
    projection (in the cost's metric) onto every row's line, and every two lines' crossing.
    All R + R (R − 1)/2 + 1 candidates are checked at once.
    """
    k = a.shape[0]
    aw = a / w
    den = (a * aw).sum(1)
    ok = den > 0.0
    t = np.where(ok, lo - a @ u0, 0.0) / np.where(ok, den, 1.0)
    single = u0 + t[:, None] * aw
    i, j = _pairs(k)
    det = a[i, 0] * a[j, 1] - a[i, 1] * a[j, 0]
    nz = np.abs(det) > 1e-12
    d = np.where(nz, det, 1.0)
    pair = np.stack(
        [(lo[i] * a[j, 1] - lo[j] * a[i, 1]) / d, (a[i, 0] * lo[j] - a[j, 0] * lo[i]) / d], 1
    )[nz]
    cand = np.concatenate([u0[None], single[ok], pair])
    cost = (((cand - u0) ** 2) * w).sum(1)
    cost[np.any(cand @ a.T < lo - tol, axis=1)] = np.inf
    best = int(np.argmin(cost))
    return cand[best].copy() if np.isfinite(cost[best]) else None


@functools.lru_cache(maxsize=256)
def _pairs(k: int) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    return np.triu_indices(k, 1)


class _OsqpWorkspace:
    """OSQP on the QP in u = (v, ω) alone, min w_v (v − v_nom)² + w_ω (ω − ω_nom)² over the
    rows ``coef · u ≥ lo`` (the command box, the walls and the cuts of the cutting-plane solve).

    One workspace serves a policy's whole episode: the matrix keeps ``capacity`` rows with a
    fixed (dense, two-column) pattern, unused rows are free (−∞ ≤ 0 · u ≤ ∞), and every solve
    only updates q, l, u and the matrix values, then warm-starts from the previous solution
    (of the last round, β level or decision).
    """

    def __init__(self, cfg: CvarBfConfig, capacity: int) -> None:
        try:
            import osqp
        except ImportError as exc:  # pragma: no cover - osqp is a dependency
            raise ConfigError(
                expect("CvarBfConfig.solver", "an installed osqp", "osqp", "pip install osqp")
            ) from exc
        self.cfg = cfg
        self.capacity = capacity
        self.w2 = 2.0 * np.array([cfg.weight_v, cfg.weight_omega])
        self.prob = osqp.OSQP(algebra=_osqp_algebra())
        self.ready = False

    def solve(self, u_nom: F64, coef: F64, lo: F64, hi: F64) -> tuple[F64 | None, str]:
        """The QP's solution (None unless OSQP returned a finite iterate) and OSQP's status;
        ``coef (R, 2)``, ``lo``, ``hi (R,)`` with R ≤ ``capacity``."""
        import scipy.sparse as sp

        r, cap = coef.shape[0], self.capacity
        a = np.zeros((cap, 2))
        a[:r] = coef
        l_full = np.full(cap, -np.inf)
        u_full = np.full(cap, np.inf)
        l_full[:r], u_full[:r] = lo, hi
        q = -self.w2 * u_nom
        ax = a.ravel(order="F")
        if not self.ready:
            pattern = np.tile(np.arange(cap), 2), np.array([0, cap, 2 * cap])
            self.prob.setup(
                sp.csc_matrix((self.w2, ([0, 1], [0, 1])), shape=(2, 2)),
                q,
                sp.csc_matrix((ax, *pattern), shape=(cap, 2)),
                l_full,
                u_full,
                verbose=False,
                eps_abs=1e-8,
                eps_rel=1e-8,
                max_iter=self.cfg.max_iter,
                polishing=True,
                warm_starting=True,
            )
            self.ready = True
        else:
            self.prob.update(q=q, l=l_full, u=u_full, Ax=ax)
        res = self.prob.solve(raise_error=False)
        status = str(res.info.status)
        if res.x is None or not np.all(np.isfinite(res.x)):
            return None, status
        return np.asarray(res.x, dtype=np.float64), status


@functools.cache
def _osqp_algebra() -> str:
    """OSQP's default linear-algebra backend, looked up once: ``osqp.OSQP()`` looks it up on
    every construction by trying to import the CUDA and MKL backends first, and the two failing
    imports cost ≈ 0.7 ms per decision (the same backend either way)."""
    import osqp

    return str(osqp.default_algebra())
