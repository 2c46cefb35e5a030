"""CVaR barrier-function safety filter with adaptive risk (Wang et al., IROS 2025).

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
(ℓ = 0.25 m, chosen on validation episodes: docs/baselines.md) whose velocity is linear in u:

    ṗ_l = J(θ) u,   J(θ) = [[cos θ, −ℓ sin θ], [sin θ, ℓ cos θ]]
    p_l⁺ = p_l + J(θ) u Δt                                   (next look-ahead point, linear in u)

The robot's centre moves only along its heading within one step, so a barrier on the centre
could brake but never steer; on p_l the turn rate ω acts at first order. Radii are CVaR-BF's
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

*QP.* In z = (v, ω, ζ_1…ζ_N, η_11…η_NS)::

    minimise  w_v (v − v_nom)² + w_ω (ω − ω_nom)²
    s.t.      the linearised CVaR constraints of every present human (status ≠ GONE),
              the linearised wall constraints,  v ∈ [0, v_max],  |ω| ≤ ω_max,  η ≥ 0.

w_v = 1 s²/m², w_ω = 0.1 s²/rad²: a change of 1 rad/s costs as much as one of 0.32 m/s, so the
filter prefers to steer around a person rather than stop in front of them.

*Solving it.* ζ and η only express CVaR_β(h_j(u)) ≥ (1 − γ) h(x_k), a concave piecewise-linear
constraint on the two-dimensional u: CVaR_β(h(u)) = min_q Σ_s q_s h_s(u) over the tail weights
0 ≤ q_s ≤ p_s/β, Σ_s q_s = 1. The default solver (``solver="exact"``) works in u alone by
cutting planes (Kelley): minimise the cost over the box, the walls and the cuts found so far,
exactly (a strictly convex QP in two variables: the cheapest of the unconstrained minimum, the
projections onto each row and the crossings of two rows that satisfies every row); at the
solution, for every human whose exact CVaR constraint fails, add the cut Σ_s q*_s h_s(u) ≥
(1 − γ) h(x_k) with the tail weights q* there (valid everywhere, tight at that point); stop when
no constraint fails — the solution of a relaxation that is feasible is the QP's optimum — or
when the relaxation is empty, which proves the level infeasible. Cuts are finitely many (q* is
a vertex of the weights' polytope), in practice 1–4 rounds. ``solver="osqp"`` solves the same
two-variable QPs with OSQP (one workspace per episode, updated and warm-started from the last
solve); ``solver="slsqp"`` solves the lifted QP above with SciPy's SLSQP (100–2,000 ms per
solve), both cross-checks. A solve counts as feasible if its solution satisfies every
constraint to ``feasibility_tol`` = 1e-5 m². If u_nom itself satisfies every constraint at the
current β it is the QP optimum and nothing is solved (the fast path).

Earlier versions solved the lifted QP with OSQP. Its ADMM iterations stopped at the limit
(2,000, ≈ 2.7 ms) on levels that were feasible with margins up to 0.18 m², so the "first
feasible" level was often a larger β than the first feasible one (422 of 1,001 decisions of the
regression episodes): less conservative than the method, and dependent on the warm start.

*Adaptive risk.* The first feasible level of β ∈ (0.05, 0.10, …, 0.70), from the most
conservative, is kept. Feasibility grows with β (a point feasible at β is feasible at every
β' > β: the η terms, η ≥ 0, shrink by β/β'), so it is found by bisection (``select_beta``):
level 0.05 first (the usual answer), then 0.70 (if infeasible, none is), then halving the gap —
at most 6 solves instead of 14, the same level as trying them in order (the regression
reference and a property test check it). If no level is feasible the robot stops and turns in
place toward the goal, |ω| ≤ ``fallback_omega`` = 0.5 rad/s; turning in place does not move
the body.

Differences from the original, and why
--------------------------------------
- Ours is a unicycle: the barriers act on a look-ahead point and are linearised around u_nom
  (above), where the original's next state enters the barrier directly.
- Walls are extra barrier constraints (the elevator has walls; the original's scenes do not).
- Human prediction is constant velocity from the privileged state (``info["state"]``), as the
  original's deterministic g(x_o); σ_u and the nominal sample velocity are our choices (above).
- The fast path and the safe fallback are ours; the original counts an infeasible QP as a
  failure.

Counters: ``n_decisions``, ``n_solves`` (solver calls: 2-D QPs, or SLSQP runs),
``n_infeasible`` (β levels below the chosen one, all infeasible), ``n_fallback`` (decisions
with no feasible β) accumulate over the policy's lifetime;
``betas`` (chosen β per step, NaN at a fallback) and ``solve_times`` [s] (wall time per
decision) are kept per episode; ``last`` is the latest :class:`CvarDecision`.
"""

from pioneer.baselines.cvar_bf.barriers import (
    cvar_lower,
    cvar_weights,
    dynamic_zone_barrier,
    lookahead_jacobian,
    lookahead_point,
    wall_barrier,
)
from pioneer.baselines.cvar_bf.config import BETAS, CvarBfConfig
from pioneer.baselines.cvar_bf.policy import CvarBfPolicy, make_cvar_bf
from pioneer.baselines.cvar_bf.qp import CvarDecision, QPResult, select_beta

__all__ = [
    "BETAS",
    "CvarBfConfig",
    "CvarBfPolicy",
    "CvarDecision",
    "QPResult",
    "cvar_lower",
    "cvar_weights",
    "dynamic_zone_barrier",
    "lookahead_jacobian",
    "lookahead_point",
    "make_cvar_bf",
    "select_beta",
    "wall_barrier",
]
