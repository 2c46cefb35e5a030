"""CVaR barrier-function safety filter with adaptive risk (Wang et al., IROS 2025; SPEC 5).

Baseline ``cvar-bf`` of the paper's Table I: Wang, Kim, Hoxha, Fainekos, Panagou, "Safe
Navigation in Uncertain Crowded Environments Using Risk Adaptive CVaR Barrier Functions",
arXiv 2504.06513. Every 0.1 s it minimally modifies a nominal go-to-goal command subject to
one discrete-time CVaR barrier condition per human and one barrier condition per wall.

Formulation as implemented
--------------------------
Robot pose x = (p_r, θ), command u = (v, ω), control period Δt = 0.1 s.

*Nominal command* (proportional go-to-goal, as :class:`~pioneer.control.classic.GoalPolicy`):
φ = wrap(atan2(g − p_r) − θ), ω_nom = clip(k_ω φ, ±ω_max),
v_nom = v_max · max(0, cos φ) · min(1, ‖g − p_r‖ / d_slow).

*Unicycle via a look-ahead point.* The barriers constrain the point p_l = p_r + ℓ (cos θ, sin θ)
whose velocity is linear in u:

    ṗ_l = J(θ) u,   J(θ) = [[cos θ, −ℓ sin θ], [sin θ, ℓ cos θ]]
    p_l⁺ = p_l + J(θ) u Δt                                   (next look-ahead point, linear in u)

The disc of radius r_r + ℓ around p_l contains the robot's body, so every radius below is
inflated by ℓ: keeping p_l clear keeps the body clear.

*Dynamic-zone barrier* (paper eq. for h_dz), for human o with position p_o, velocity v_o:

    h(p_l, v_r; p_o, v_o) = ‖p_l − p_o‖² − R² − R² (‖v_o‖ / v̂) (1/ρ) log(1 + exp(−ρ cos θ_rel))
    cos θ_rel = p_relᵀ v_rel / (‖p_rel‖ ‖v_rel‖),  p_rel = p_o − p_l,  v_rel = v_o − v_r

with R = r_r + ℓ + r_h + margin, ρ = 10, v̂ = 1 m/s and v_r = J(θ) u the look-ahead point's
velocity. (‖v_rel‖ is regularised as √(‖v_rel‖² + ε_v²), ε_v = 0.05 m/s, so cos θ_rel stays
smooth when the relative velocity vanishes.) h(x_k) is evaluated at the current state with the
last applied command; h(x_{k+1}) at the next look-ahead point, with the command u held.

*Uncertainty.* S = 15 next-step positions of every human are sampled from the policy's own
generator (seeded by ``reset``): p̂_s = p_o + (v_o + w_u,s) Δt + w_x,s, w_x ~ N(0, σ_x² I),
w_u ~ N(0, σ_u² I), with sample velocity v̂_s = v_o + w_u,s. Sample s has probability
p_s ∝ N(w_x,s; 0, σ_x²) N(w_u,s; 0, σ_u²), normalised to Σ_s p_s = 1.

*CVaR barrier condition* (discrete time, Rockafellar–Uryasev with slack variables): for each
human, with h_s(u) the barrier at sample s,

    CVaR_β(h(x_{k+1})) ≥ (1 − γ) h(x_k)   ⟺   ∃ ζ, η:  η_s ≥ −h_s(u) − ζ,  η_s ≥ 0,
                                                       ζ + (1/β) Σ_s p_s η_s ≤ −(1 − γ) h(x_k)

β is the tail fraction: small β looks only at the worst samples (conservative).

*Linearisation.* h_s(u) is quadratic (and, through cos θ_rel, non-polynomial) in u; it is
replaced by its first-order expansion around the nominal command,
h_s(u) ≈ h_s(u_nom) + ∇_u h_s(u_nom)ᵀ (u − u_nom), so every constraint is linear. The distance
term ‖p_l⁺ − p̂‖² is convex in u, hence its linearisation is a lower bound (conservative); the
dynamic-zone term is not, and the unicycle moves along an arc rather than the Euler step of
p_l — the tests check the condition at the true next state within this tolerance.

*Walls* are barriers on the same point: h_w = d(p_l, wall)² − (r_r + ℓ + wall_margin)², with
h_w(x_{k+1}) ≥ (1 − γ) h_w(x_k), linearised the same way (d² to a segment is convex, so this
linearisation is conservative too).

*QP.* In z = (v, ω, ζ_1…ζ_N, η_11…η_NS):

    minimise  w_v (v − v_nom)² + w_ω (ω − ω_nom)²
    s.t.      the linearised CVaR constraints of every present human (status ≠ GONE),
              the linearised wall constraints,  v ∈ [0, v_max],  |ω| ≤ ω_max,  η ≥ 0,

solved with SciPy's SLSQP (a dense SQP method; on a QP with linear constraints its
subproblem is the problem itself). A solution counts as feasible only if SLSQP reports
success *and* every constraint holds to ``feasibility_tol``. If u_nom itself satisfies every
constraint at the current β it is the QP optimum and no solver call is made (``fast path``).
Weights: w_v = 1 s²/m², w_ω = 0.1 s²/rad² — turning is cheaper than braking, which lets the
filter steer around people instead of only stopping in front of them (the isotropic choice in
look-ahead-point velocity, w_ω = ℓ², makes the robot spin at the first contact).

*Adaptive risk.* β runs through (0.05, 0.10, …, 0.70) from the most conservative level; the
first feasible solve is kept. If no level is feasible the robot stops and turns in place toward
the goal, |ω| ≤ ``fallback_omega`` (turning in place does not move the body's disc).

Differences from the original, and why
--------------------------------------
- The original robot in the CVaR-BF experiments is controlled through a model whose next
  state is affine in the input; ours is a unicycle, so the barriers act on a look-ahead point
  (radius inflated by ℓ) and the barrier is linearised around u_nom (above).
- Walls are extra barrier constraints (the original scenes have no walls).
- The human-motion prediction is constant velocity (privileged: ``info["state"]``), as the
  original's g(x_o); σ_u is our choice (the paper gives σ = 0.025 m for the position noise).
- The fast path and the safe fallback are ours; the original reports infeasibility.

Counters: ``n_decisions``, ``n_solves`` (SLSQP calls), ``n_infeasible`` (β levels that
failed), ``n_fallback`` (decisions with no feasible β) accumulate over the policy's lifetime;
``betas`` (chosen β per step, NaN at a fallback) and ``solve_times`` [s] per step are kept per
episode; ``last`` is the latest :class:`CvarDecision`.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
import scipy.optimize
from numpy.typing import NDArray

from pioneer.config import Config, check_nonnegative, check_positive
from pioneer.control.policy import register_policy
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
    margin: float = 0.0  # [m] added to R = r_r + ℓ + r_h
    wall_margin: float = 0.0  # [m] added to the wall radius r_r + ℓ
    weight_v: float = 1.0  # [s²/m²] w_v
    weight_omega: float = 0.1  # [s²/rad²] w_ω
    k_omega: float = 1.5  # [1/s] nominal heading gain
    v_nominal: float = 0.8  # [m/s] nominal cruise speed (capped by the robot's v_max)
    slow_distance: float = 0.5  # [m] nominal slows down linearly inside this goal distance
    fallback_omega: float = 0.5  # [rad/s] |ω| bound of the turn-in-place fallback
    feasibility_tol: float = 1e-5  # accepted constraint violation of a solve [m²]
    solver: str = "osqp"  # "osqp" (default) or "slsqp" (SciPy; ~100× slower, a cross-check)
    max_iter: int = 4000  # iteration limit per solve (OSQP ADMM iterations / SLSQP steps)

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

    u_nom: F64  # (2,)
    h_k: F64  # (N,) h(x_k)
    h0: F64  # (N, S) h_s(u_nom)
    g: F64  # (N, S, 2) ∇_u h_s(u_nom)
    p: F64  # (N, S) sample probabilities
    hw_k: F64  # (M,) wall barriers at x_k
    hw0: F64  # (M,) wall barriers at the nominal next state
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
        """S sampled next positions ``(N, S, 2)``, velocities ``(N, S, 2)`` and probabilities
        ``(N, S)`` of the humans ``idx`` (constant velocity plus Gaussian noise)."""
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
        r_w = world.sim.robot.radius + ell + cfg.wall_margin
        hw, _ = wall_barrier(p_l, world.walls, r_w)
        return h, hw

    def linearise(self, world: World, state: State) -> tuple[_Linearised, dict[str, Any]]:
        """Sample the humans and linearise every barrier around u_nom (one decision's data)."""
        cfg = self.config
        dt = world.sim.dt
        ell = cfg.lookahead
        u_nom = self.nominal(world, state)
        pose = state.robot[0]
        jac = lookahead_jacobian(float(pose[2]), ell)
        p_l = lookahead_point(pose, ell)
        v_k = jac @ state.command[0]  # look-ahead point velocity under the last command
        v_n = jac @ u_nom
        p_n = p_l + v_n * dt  # nominal next look-ahead point
        idx = np.flatnonzero(state.h_status[0] != GONE).astype(np.int64)
        radius = world.sim.robot.radius + ell + state.h_radius[0, idx] + cfg.margin
        p_hat, v_hat, prob = self.sample_humans(state, idx, dt)
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
            p_n, v_n, p_hat, v_hat, radius[:, None], cfg.rho, cfg.v_hat, cfg.eps_vel, grad=True
        )
        g = (dh_dp * dt + dh_dv) @ jac  # ∇_u h_s: p_l⁺ = p_l + J u Δt, v_r = J u
        r_w = world.sim.robot.radius + ell + cfg.wall_margin
        hw_k, _ = wall_barrier(p_l, world.walls, r_w)
        hw0, dhw = wall_barrier(p_n, world.walls, r_w)
        lin = _Linearised(u_nom, h_k, h0, g, prob, hw_k, hw0, dhw @ jac * dt)
        extra = {"humans": idx, "radius": radius, "samples_pos": p_hat, "samples_vel": v_hat}
        return lin, extra

    def solve(self, world: World, lin: _Linearised, beta: float) -> QPResult:
        """The CVaR-BF QP at risk level ``beta`` (fast path if u_nom is feasible)."""
        cfg = self.config
        gam = cfg.gamma
        tol = cfg.feasibility_tol
        n, s = lin.h0.shape
        if bool(
            np.all(cvar_lower(lin.h0, lin.p, beta) >= (1.0 - gam) * lin.h_k - tol)
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
        try:
            import osqp
        except ImportError as exc:  # pragma: no cover - osqp is a dependency
            raise ConfigError(
                expect("CvarBfConfig.solver", "an installed osqp", "osqp", "pip install osqp")
            ) from exc
        import scipy.sparse as sp

        cfg = self.config
        n, s = lin.h0.shape
        nv = mat.shape[1]
        lo, hi = self._bounds(world, n, s)
        box = np.flatnonzero(np.isfinite(lo) | np.isfinite(hi))
        a_full = sp.vstack([sp.csc_matrix(mat), sp.eye(nv, format="csc")[box]], format="csc")
        low = np.concatenate([-off, lo[box]])
        high = np.concatenate([np.full(off.shape, np.inf), hi[box]])
        w2 = 2.0 * np.array([cfg.weight_v, cfg.weight_omega])
        p_mat = sp.diags(np.concatenate([w2, np.zeros(nv - 2)]), format="csc")
        q = np.zeros(nv)
        q[:2] = -w2 * lin.u_nom
        prob = osqp.OSQP()
        prob.setup(
            p_mat,
            q,
            a_full,
            low,
            high,
            verbose=False,
            eps_abs=1e-7,
            eps_rel=1e-7,
            max_iter=cfg.max_iter,
            polishing=True,
        )
        z0 = np.concatenate([lin.u_nom, -lin.h0.min(axis=1) if n else np.zeros(0), np.zeros(n * s)])
        prob.warm_start(x=z0)
        res = prob.solve()
        status = str(res.info.status)
        if res.x is None or not np.all(np.isfinite(res.x)):
            return z0, False, status
        return np.asarray(res.x, dtype=np.float64), status == "solved", status

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
        z0 = np.concatenate([u0, -lin.h0.min(axis=1) if n else np.zeros(0), np.zeros(n * s)])
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
        off[: n * s] = lin.h0.ravel() - lin.g.reshape(-1, 2) @ lin.u_nom
        # −(1 − γ) h_k,j − ζ_j − (1/β) Σ_s p_js η_js ≥ 0
        r = n * s + np.arange(n)
        mat[r, 2 + np.arange(n)] = -1.0
        mat[r[hum], 2 + n + rows] = -lin.p.ravel() / beta
        off[n * s : n * s + n] = -(1.0 - self.config.gamma) * lin.h_k
        # walls: hw0 + gwᵀ (u − u_nom) − (1 − γ) hw_k ≥ 0
        mat[n * s + n :, :2] = lin.gw
        off[n * s + n :] = lin.hw0 - lin.gw @ lin.u_nom - (1.0 - self.config.gamma) * lin.hw_k
        return mat, off

    def decide(self, world: World, state: State) -> CvarDecision:
        """One decision from ``state`` (B = 1): adaptive-β QP, or the fallback."""
        cfg = self.config
        t0 = time.perf_counter()
        lin, extra = self.linearise(world, state)
        solves_before = self.n_solves
        i, res, n_failed = select_beta(lambda b: self.solve(world, lin, b), cfg.betas)
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
        du = command - lin.u_nom
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


register_policy("cvar-bf", make_cvar_bf)
