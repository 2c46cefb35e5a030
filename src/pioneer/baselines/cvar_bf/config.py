"""CVaR-BF parameters (formulation in :mod:`pioneer.baselines.cvar_bf`)."""

from __future__ import annotations

import dataclasses
from typing import Annotated, Literal

import numpy as np
from annotated_types import Interval, MinLen
from numpy.typing import NDArray

from pioneer.bounds import Count, NonNegative, NonNegativeInt, Positive
from pioneer.config import Config, Ordered

__all__ = ["BETAS", "CvarBfConfig"]

F64 = NDArray[np.float64]


BETAS = tuple(round(0.05 * k, 2) for k in range(1, 15))  # 0.05, 0.10, …, 0.70
Level = Annotated[float, Interval(gt=0, le=1)]  # a number in (0, 1]
Solver = Literal["exact", "osqp", "slsqp"]


@dataclasses.dataclass(frozen=True)
class CvarBfConfig(Config):
    """Parameters of the CVaR-BF filter (defaults: the original's values where it has them)."""

    gamma: Level = 0.1  # γ of the discrete-time barrier condition
    # risk levels, most conservative first
    betas: Annotated[tuple[Level, ...], MinLen(1), Ordered()] = BETAS
    n_samples: Count = 15  # S, sampled next-step positions per human
    sigma_pos: Positive = 0.025  # [m] σ_x of the position noise w_x
    sigma_vel: Positive = 0.1  # [m/s] σ_u of the velocity noise w_u (our choice)
    rho: Positive = 10.0  # ρ of the dynamic zone's softplus
    v_hat: Positive = 1.0  # [m/s] v̂, speed normalisation of the dynamic zone
    eps_vel: Positive = 0.05  # [m/s] ε_v, regularises ‖v_rel‖ in cos θ_rel
    lookahead: Positive = 0.25  # [m] ℓ, the controlled point ahead of the centre (validation)
    cover_body: bool = False  # inflate every radius by ℓ so the barriers on p_l cover the body
    margin: NonNegative = 0.0  # [m] added to R = r_r + r_h
    wall_margin: NonNegative = 0.0  # [m] added to the wall radius r_r + ℓ
    weight_v: Positive = 1.0  # [s²/m²] w_v
    weight_omega: Positive = 0.1  # [s²/rad²] w_ω
    k_omega: NonNegative = 1.5  # [1/s] nominal heading gain
    v_nominal: Positive = 0.8  # [m/s] nominal cruise speed (capped by the robot's v_max)
    slow_distance: Positive = 0.5  # [m] nominal slows down linearly inside this goal distance
    fallback_omega: NonNegative = 0.5  # [rad/s] |ω| bound of the turn-in-place fallback
    feasibility_tol: Positive = 1e-5  # accepted constraint violation of a solve [m²]
    # QP solver: "exact" (cutting planes, exact 2-D QPs), "osqp" (the same cutting planes, OSQP
    # on each 2-D QP) or "slsqp" (SciPy on the lifted QP; ~100× slower)
    solver: Solver = "exact"
    max_iter: Count = 2000  # iteration limit per solve (OSQP ADMM iterations / SLSQP steps)
    max_rounds: Count = 20  # cutting-plane rounds (OSQP calls) per β level at most
    refine: NonNegativeInt = 1  # re-linearisations around the solution at the chosen β (0: none)
