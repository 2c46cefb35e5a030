"""CVaR barrier-function safety filter with adaptive risk (Wang et al., IROS 2025; SPEC 5).

Baseline ``cvar-bf`` of the paper's Table I: Wang, Kim, Hoxha, Fainekos, Panagou, "Safe
Navigation in Uncertain Crowded Environments Using Risk Adaptive CVaR Barrier Functions",
arXiv 2504.06513. Every 0.1 s it minimally modifies a nominal go-to-goal command subject to
one discrete-time CVaR barrier condition per human and one barrier condition per wall.

Formulation as implemented
--------------------------
Robot pose x = (p_r, θ), command u = (v, ω), control period Δt = 0.1 s.

*Nominal command* (proportional go-to-goal, as :class:`~pioneer.baselines.classic.GoalPolicy`):
φ = wrap(atan2(g − p_r) − θ), ω_nom = clip(k_ω φ, ±ω_max),
v_nom = v_max · max(0, cos φ) · min(1, ‖g − p_r‖ / d_slow).

*Unicycle via a look-ahead point.* The barriers constrain the point p_l = p_r + ℓ (cos θ, sin θ)
(ℓ = 0.15 m) whose velocity is linear in u:

    ṗ_l = J(θ) u,   J(θ) = [[cos θ, −ℓ sin θ], [sin θ, ℓ cos θ]]
    p_l⁺ = p_l + J(θ) u Δt                                   (next look-ahead point, linear in u)

The robot's centre moves only along its heading within one step, so a barrier on the centre
could brake but never steer; on p_l the turn rate ω acts at first order. Radii are the SPEC's
R = r_r + r_h (+ ``margin``) measured from p_l: when a person is ahead (the usual approach) p_l
is nearer to them than the centre and the barrier is conservative; for a person beside or
behind, the body may come up to ℓ closer than the barrier says. ``cover_body=True`` inflates
every human radius by ℓ so the disc around p_l covers the body for any direction — a guarantee
that cost the whole success rate in the elevator (HR-RL seeds 0–7: 0 of 8 reached the goal,
all frozen at the door, against 6 of 8 without), so it is off by default. Walls are always
inflated (below).

*Dynamic-zone barrier* (CVaR-BF paper), for human o with position p_o and velocity v_o:

    h(p_l, v_r; p_o, v_o) = ‖p_l − p_o‖² − R² − R² (‖v_o‖ / v̂) (1/ρ) log(1 + exp(−ρ cos θ_rel))
    cos θ_rel = p_relᵀ v_rel / (‖p_rel‖ ‖v_rel‖),  p_rel = p_o − p_l,  v_rel = v_o − v_r

with ρ = 10, v̂ = 1 m/s and v_r = J(θ) u the look-ahead point's velocity. ‖v_rel‖ is
regularised as √(‖v_rel‖² + ε_v²), ε_v = 0.05 m/s, so cos θ_rel stays smooth when the relative
velocity vanishes. h(x_k) uses the current positions and the last applied command;
h(x_{k+1}) the next look-ahead point and sampled human positions, with the command u held.

*Uncertainty.* S = 15 next-step positions of every human are sampled from the policy's own
generator (seeded by ``reset``): p̂_s = p_o + (v_o + w_u,s) Δt + w_x,s, w_x ~ N(0, σ_x² I) with
σ_x = 0.025 m (the paper's value), w_u ~ N(0, σ_u² I) with σ_u = 0.1 m/s (our choice). Sample
s has probability p_s ∝ N(w_x,s; 0, σ_x²) N(w_u,s; 0, σ_u²), normalised to Σ_s p_s = 1. The
dynamic-zone term of every sample uses the predicted velocity v_o: the norm of a noisy velocity
is biased upward (E‖v_o + w_u‖ > ‖v_o‖), which made a resting person's zone grow from h(x_k) to
h(x_{k+1}) and the condition infeasible even for a robot standing still.

*CVaR barrier condition* (discrete time, Rockafellar–Uryasev with slack variables): for each
human, with h_s(u) the barrier at sample s,

    CVaR_β(h(x_{k+1})) ≥ (1 − γ) h(x_k)   ⟺   ∃ ζ, η:  η_s ≥ −h_s(u) − ζ,  η_s ≥ 0,
                                                       ζ + (1/β) Σ_s p_s η_s ≤ −(1 − γ) h(x_k)

γ = 0.1. β is the tail fraction: a small β looks only at the worst samples (conservative).

*Linearisation.* h_s(u) is quadratic (and, through cos θ_rel, not polynomial) in u; it is
replaced by its first-order expansion around the nominal command,
h_s(u) ≈ h_s(u_nom) + ∇_u h_s(u_nom)ᵀ (u − u_nom), so every constraint is linear. The distance
term ‖p_l⁺ − p̂‖² is convex in u, so its linearisation is a lower bound (conservative); the
dynamic-zone term is not (its softplus, ρ = 10, is sharp in the relative velocity), and the
robot moves along an arc rather than the Euler step of p_l. After the β search the barriers
are linearised once more around the solution, with the same samples, and the QP is solved
again at the chosen β (``refine`` = 1; kept only if feasible): in an HR-RL episode this cut
the worst violation of the true condition from 0.068 to 0.043 m². The tests check the
condition at the state the simulator actually reached within 0.05 m².

*Walls* are barriers on the same point: h_w = d(p_l, wall)² − (r_r + ℓ + wall_margin)², with
h_w(x_{k+1}) ≥ (1 − γ) h_w(x_k), linearised the same way (d² to a segment is convex, so this
linearisation is conservative too). For walls the radius is always inflated by ℓ: without it
the robot's centre, behind p_l, clipped a door jamb in 2 of 20 HR-RL episodes; the 1.8 m door
still leaves p_l a 0.9 m wide passage.

*QP.* In z = (v, ω, ζ_1…ζ_N, η_11…η_NS):

    minimise  w_v (v − v_nom)² + w_ω (ω − ω_nom)²
    s.t.      the linearised CVaR constraints of every present human (status ≠ GONE),
              the linearised wall constraints,  v ∈ [0, v_max],  |ω| ≤ ω_max,  η ≥ 0.

w_v = 1 s²/m², w_ω = 0.1 s²/rad²: a change of 1 rad/s costs as much as one of 0.32 m/s, so the
filter prefers to steer around a person rather than stop in front of them. Solved with OSQP
(one workspace per decision; across β only the values of the CVaR rows change, so it is
updated and warm-started); SciPy's SLSQP is available (``solver="slsqp"``) as a cross-check,
but took 100–2,000 ms per solve here. A solve counts as feasible if the solver returns an
iterate (solved, or stopped inaccurate / at the iteration limit) *and* that iterate satisfies
every constraint to ``feasibility_tol`` = 1e-5 m². If u_nom itself satisfies every constraint
at the current β it is the QP optimum and no solver is called (the fast path).

*Adaptive risk.* β runs through (0.05, 0.10, …, 0.70) from the most conservative level; the
first feasible solve is kept. If no level is feasible the robot stops and turns in place toward
the goal, |ω| ≤ ``fallback_omega`` = 0.5 rad/s; turning in place does not move the body.

Differences from the original, and why
--------------------------------------
- Ours is a unicycle: the barriers act on a look-ahead point and are linearised around u_nom
  (above), where the original's next state enters the barrier directly.
- Walls are extra barrier constraints (the elevator has walls; the original's scenes do not).
- Human prediction is constant velocity from the privileged state (``info["state"]``), as the
  original's deterministic g(x_o); σ_u and the nominal sample velocity are our choices (above).
- The fast path and the safe fallback are ours; the original counts an infeasible QP as a
  failure.

Counters: ``n_decisions``, ``n_solves`` (solver calls), ``n_infeasible`` (β levels that
failed), ``n_fallback`` (decisions with no feasible β) accumulate over the policy's lifetime;
``betas`` (chosen β per step, NaN at a fallback) and ``solve_times`` [s] (wall time per
decision) are kept per episode; ``last`` is the latest :class:`CvarDecision`.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
import scipy.optimize
from numpy.typing import NDArray

from pioneer.config import Config, check_nonnegative, check_positive
from pioneer.errors import ConfigError, expect
from pioneer.sim.humans import GONE
from pioneer.sim.world import State, World

__all__ = [
    "CvarBfConfig",
    "CvarBfPolicy",
    "CvarDecision",
    "QPResult",
    "cvar_lower",
    "dynamic_zone_barrier",
    "lookahead_jacobian",
    "lookahead_point",
    "select_beta",
    "wall_barrier",
]

F64 = NDArray[np.float64]
BETAS = tuple(round(0.05 * k, 2) for k in range(1, 15))  # 0.05, 0.10, …, 0.70


@dataclasses.dataclass(frozen=True)
class CvarBfConfig(Config):
    """Parameters of the CVaR-BF filter (defaults: the original's values where it has them)."""

    gamma: float = 0.1  # γ of the discrete-time barrier condition
    betas: tuple[float, ...] = BETAS  # risk levels, most conservative first
    n_samples: int = 15  # S, sampled next-step positions per human
    sigma_pos: float = 0.025  # [m] σ_x of the position noise w_x
    sigma_vel: float = 0.1  # [m/s] σ_u of the velocity noise w_u (our choice)
    rho: float = 10.0  # ρ of the dynamic zone's softplus
    v_hat: float = 1.0  # [m/s] v̂, speed normalisation of the dynamic zone
    eps_vel: float = 0.05  # [m/s] ε_v, regularises ‖v_rel‖ in cos θ_rel
    lookahead: float = 0.15  # [m] ℓ, distance of the controlled point ahead of the centre
    cover_body: bool = False  # inflate every radius by ℓ so the barriers on p_l cover the body
    margin: float = 0.0  # [m] added to R = r_r + r_h
    wall_margin: float = 0.0  # [m] added to the wall radius r_r + ℓ
    weight_v: float = 1.0  # [s²/m²] w_v
    weight_omega: float = 0.1  # [s²/rad²] w_ω
    k_omega: float = 1.5  # [1/s] nominal heading gain
    v_nominal: float = 0.8  # [m/s] nominal cruise speed (capped by the robot's v_max)
    slow_distance: float = 0.5  # [m] nominal slows down linearly inside this goal distance
    fallback_omega: float = 0.5  # [rad/s] |ω| bound of the turn-in-place fallback
    feasibility_tol: float = 1e-5  # accepted constraint violation of a solve [m²]
    solver: str = "osqp"  # "osqp" (default) or "slsqp" (SciPy; ~100× slower, a cross-check)
    max_iter: int = 2000  # iteration limit per solve (OSQP ADMM iterations / SLSQP steps)
    refine: int = 1  # re-linearisations around the solution at the chosen β (0: none)

    def __post_init__(self) -> None:
        for name in (
            "gamma",
            "sigma_pos",
            "sigma_vel",
            "rho",
            "v_hat",
            "eps_vel",
            "lookahead",
            "weight_v",
            "weight_omega",
            "v_nominal",
            "slow_distance",
            "feasibility_tol",
        ):
            check_positive("CvarBfConfig", name, getattr(self, name))
        for name in ("margin", "wall_margin", "fallback_omega", "k_omega"):
            check_nonnegative("CvarBfConfig", name, getattr(self, name))
        if not 0.0 < self.gamma <= 1.0:
            raise ConfigError(expect("CvarBfConfig.gamma", "in (0, 1]", self.gamma, "use 0.1"))
        b = self.betas
        if not b or any(not 0.0 < x <= 1.0 for x in b) or list(b) != sorted(b):
            raise ConfigError(
                expect(
                    "CvarBfConfig.betas",
                    "a non-empty increasing sequence in (0, 1]",
                    b,
                    "use 0.05, 0.10, …, 0.70",
                )
            )
        if not isinstance(self.n_samples, int) or self.n_samples < 1:
            raise ConfigError(
                expect("CvarBfConfig.n_samples", "an integer >= 1", self.n_samples, "use 15")
            )
        if self.solver not in ("osqp", "slsqp"):
            raise ConfigError(
                expect("CvarBfConfig.solver", "'osqp' or 'slsqp'", self.solver, "use 'osqp'")
            )
        if not isinstance(self.refine, int) or self.refine < 0:
            raise ConfigError(
                expect("CvarBfConfig.refine", "an integer >= 0", self.refine, "use 1")
            )
        if not isinstance(self.max_iter, int) or self.max_iter < 1:
            raise ConfigError(
                expect("CvarBfConfig.max_iter", "an integer >= 1", self.max_iter, "use 100")
            )


# ------------------------------------------------------------------------------ barrier maths
def lookahead_point(pose: F64, ell: float) -> F64:
    """p_l = p_r + ℓ (cos θ, sin θ) of poses ``(..., 3)`` → ``(..., 2)`` [m]."""
    pose = np.asarray(pose, dtype=np.float64)
    th = pose[..., 2]
    return pose[..., :2] + ell * np.stack([np.cos(th), np.sin(th)], axis=-1)


def lookahead_jacobian(theta: float, ell: float) -> F64:
    """J(θ) with ṗ_l = J(θ) (v, ω): ``[[cos θ, −ℓ sin θ], [sin θ, ℓ cos θ]]``, shape (2, 2)."""
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -ell * s], [s, ell * c]])


def dynamic_zone_barrier(
    p_r: F64,
    v_r: F64,
    p_o: F64,
    v_o: F64,
    radius: F64 | float,
    rho: float = 10.0,
    v_hat: float = 1.0,
    eps_vel: float = 0.05,
    grad: bool = False,
) -> tuple[F64, F64, F64]:
    """Dynamic-zone barrier h [m²] and its gradients w.r.t. the robot point and velocity.

    All arguments broadcast: ``p_r, v_r, p_o, v_o`` are ``(..., 2)`` [m, m/s], ``radius`` R
    [m] is ``(...)``. Returns ``(h, ∂h/∂p_r, ∂h/∂v_r)`` with shapes ``(...)``, ``(..., 2)``,
    ``(..., 2)`` (the gradients are zeros unless ``grad``).
    """
    a = np.asarray(p_o, dtype=np.float64) - p_r  # p_rel
    b = np.asarray(v_o, dtype=np.float64) - v_r  # v_rel
    na = np.sqrt(np.maximum((a * a).sum(-1), 1e-18))
    nb = np.sqrt((b * b).sum(-1) + eps_vel * eps_vel)
    c = (a * b).sum(-1) / (na * nb)
    r2 = np.asarray(radius, dtype=np.float64) ** 2
    k = r2 * np.linalg.norm(v_o, axis=-1) / v_hat
    h = na * na - r2 - k * np.logaddexp(0.0, -rho * c) / rho
    if not grad:
        z = np.zeros((*np.shape(h), 2))
        return h, z, z
    sig = 0.5 * (1.0 + np.tanh(-0.5 * rho * c))  # logistic σ(−ρc), dh/dc = K σ(−ρc)
    dh_dc = (k * sig)[..., None]
    ah = a / na[..., None]
    dc_da = (b / nb[..., None] - c[..., None] * ah) / na[..., None]
    dc_db = (ah - c[..., None] * b / nb[..., None]) / nb[..., None]
    dh_da = 2.0 * a + dh_dc * dc_da
    dh_db = dh_dc * dc_db
    return h, -dh_da, -dh_db  # p_rel = p_o − p_r and v_rel = v_o − v_r: chain rule signs


def wall_barrier(p: F64, walls: F64, radius: float) -> tuple[F64, F64]:
    """h_w = d(p, wall)² − radius² for every wall ``(M, 4)`` and its gradient ``(M, 2)``."""
    a = walls[:, :2]
    e = walls[:, 2:] - a
    ll = np.maximum((e * e).sum(-1), 1e-300)
    s = np.clip(((p - a) * e).sum(-1) / ll, 0.0, 1.0)
    d = p - (a + s[:, None] * e)
    return (d * d).sum(-1) - radius * radius, 2.0 * d


def cvar_lower(h: F64, p: F64, beta: float) -> F64:
    """CVaR_β of the lower tail of h (samples on the last axis, probabilities ``p``).

    −min_ζ [ζ + (1/β) Σ_s p_s max(0, −h_s − ζ)] (Rockafellar–Uryasev); the minimum of this
    convex piecewise-linear function of ζ lies at one of the −h_s, so it is found exactly.
    """
    h = np.asarray(h, dtype=np.float64)
    zeta = -h[..., :, None]  # candidates (..., S, 1)
    loss = -h[..., None, :]  # (..., 1, S)
    val = zeta[..., 0] + (np.maximum(0.0, loss - zeta) * p[..., None, :]).sum(-1) / beta
    return -val.min(-1)


# ------------------------------------------------------------------------------ the QP
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


class CvarBfPolicy:
    """CVaR-BF as a :class:`~pioneer.control.policy.Policy` (privileged: reads ``info["state"]``).

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
        gam = cfg.gamma
        tol = cfg.feasibility_tol
        n, s = lin.h0.shape
        if bool(
            np.array_equal(lin.u_lin, lin.u_nom)
            and np.all(cvar_lower(lin.h0, lin.p, beta) >= (1.0 - gam) * lin.h_k - tol)
            and np.all(lin.hw0 >= (1.0 - gam) * lin.hw_k - tol)
        ):
            zeta = -lin.h0.min(axis=1) if n else np.zeros(0)
            z = np.concatenate([lin.u_nom, zeta, np.zeros(n * s)])
            return QPResult(True, lin.u_nom.copy(), z, 0.0, False, "nominal feasible")
        mat, off = self._constraints(lin, beta)
        self.n_solves += 1
        if cfg.solver == "osqp":
            z, success, message = self._solve_osqp(world, lin, mat, off)
        else:
            z, success, message = self._solve_slsqp(world, lin, mat, off)
        rob = world.sim.robot
        u = np.clip(z[:2], rob.command_low, rob.command_high)
        viol = max(
            float(max(0.0, -(mat @ z + off).min(initial=np.inf))),
            float(np.abs(u - z[:2]).max()),
            float(max(0.0, -z[2 + n :].min(initial=0.0))),
        )
        return QPResult(success and viol <= tol, u, z, viol, True, message)

    def _bounds(self, world: World, n: int, s: int) -> tuple[F64, F64]:
        """Variable bounds of z: the command box, ζ free, η ≥ 0."""
        rob = world.sim.robot
        lo = np.concatenate([rob.command_low, np.full(n, -np.inf), np.zeros(n * s)])
        hi = np.concatenate([rob.command_high, np.full(n + n * s, np.inf)])
        return lo, hi

    def _solve_osqp(
        self, world: World, lin: _Linearised, mat: F64, off: F64
    ) -> tuple[F64, bool, str]:
        """OSQP on the QP; one workspace per decision, re-used across β (only the CVaR rows'
        η coefficients change, so the sparsity pattern is fixed and the solve warm-starts)."""
        ws = self._ws
        if ws is None or ws.lin is not lin:
            ws = self._ws = _OsqpWorkspace(world, lin, off, self.config)
        return ws.solve(mat)

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

    def decide(self, world: World, state: State) -> CvarDecision:
        """One decision from ``state`` (B = 1): adaptive-β QP, or the fallback."""
        cfg = self.config
        t0 = time.perf_counter()
        lin, extra = self.linearise(world, state)
        solves_before = self.n_solves
        i, res, n_failed = select_beta(lambda b: self.solve(world, lin, b), cfg.betas)
        self._ws = None
        for _ in range(cfg.refine if res is not None and res.solver_call else 0):
            # Sequential linearisation: the same samples, linearised at the last solution.
            lin_r = self.linearise_at(world, state, extra, lin.u_nom, res.u)  # type: ignore[union-attr]
            res_r = self.solve(world, lin_r, cfg.betas[i])
            self._ws = None
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
