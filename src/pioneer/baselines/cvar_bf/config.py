"""CVaR-BF parameters (formulation in :mod:`pioneer.baselines.cvar_bf`)."""

from __future__ import annotations

import dataclasses
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from pioneer.config import Config, check_nonnegative, check_positive
from pioneer.errors import ConfigError, expect

__all__ = ["BETAS", "CvarBfConfig"]

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
    solver: Literal["exact", "osqp", "slsqp"] = (
        "exact"  # QP solver: "exact" (cutting planes, exact 2-D QPs), "osqp" (the
    )
    # same cutting planes, OSQP on each 2-D QP) or "slsqp" (SciPy on the lifted QP; ~100× slower)
    max_iter: int = 2000  # iteration limit per solve (OSQP ADMM iterations / SLSQP steps)
    max_rounds: int = 20  # cutting-plane rounds (OSQP calls) per β level at most
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
        if not isinstance(self.refine, int) or self.refine < 0:
            raise ConfigError(
                expect("CvarBfConfig.refine", "an integer >= 0", self.refine, "use 1")
            )
        if not isinstance(self.max_rounds, int) or self.max_rounds < 1:
            raise ConfigError(
                expect("CvarBfConfig.max_rounds", "an integer >= 1", self.max_rounds, "use 20")
            )
        if not isinstance(self.max_iter, int) or self.max_iter < 1:
            raise ConfigError(
                expect("CvarBfConfig.max_iter", "an integer >= 1", self.max_iter, "use 100")
            )
