"""The CrowdNav++ reward (Liu et al., ICRA 2023; its public code's unicycle terms): the reward
the CrowdNav++ baseline is trained on, and the Gymnasium environments' own reward::

    r = +10                                  on success
        −20                                  on collision (a human or a wall)
        (d − 0.25) · 10 · Δt                 else if the gap d < 0.25 m
        3 (‖g − p_{t−1}‖ − ‖g − p_t‖)        otherwise (potential: decrease of goal distance)
      + min_{i,k} −20 / 2^(k+1) · [‖p_t − p̂_i(k)‖ < r_r + r_i]   intrusion into the CV-predicted
                                             positions k = 1..5 (Δt_pred = 0.25 s) of human i
      − 4.5 Δθ²                              spin: Δθ = ω Δt, the heading change of the step
      − 2 |v| if v < 0                       reversing (inert here: our v_min = 0)

d is the swept surface-to-surface gap over the step (``State.gap``) and Δt our 0.1 s; the intrusion
term is charged on non-terminal steps. The original steps every T = 0.25 s; the per-step terms
(intrusion, spin, reversing) are rescaled to our Δt so that a second of them costs what it costs
there: intrusion and reversing × Δt/T, spin × T/Δt (Δθ² shrinks with Δt²). Without it a second near
a person costs 2.5× the original's (−50 instead of −20 at k = 1), more than a collision, and pure
PPO learned to end its episodes by colliding (docs/baselines.md). The spin term charges the heading
change of the step, as the original's unicycle action is a rotation per step (Δθ = ω Δt); an earlier
copy in the environment charged ω² Δt (docs/architecture.md).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Mapping
from types import MappingProxyType
from typing import Literal

import numpy as np
from numba import njit
from numpy.typing import NDArray

from pioneer.bounds import Positive
from pioneer.config import Config
from pioneer.sim.events import Event
from pioneer.sim.world import State, World

__all__ = [
    "NO_INTRUSION",
    "REWARDS",
    "TERMS",
    "CrowdNavReward",
    "CrowdNavRewardConfig",
    "RewardName",
    "crowdnav_reward",
    "crowdnav_reward_terms",
]

F64 = NDArray[np.float64]


@dataclasses.dataclass(frozen=True)
class CrowdNavRewardConfig(Config):
    """CrowdNav++ reward terms (unicycle values of the original)."""

    success: float = 10.0  # on reaching the goal
    collision: float = -20.0  # on a collision (humans or walls)
    discomfort_distance: float = 0.25  # [m] gap below which discomfort is charged
    discomfort_scale: float = 10.0  # (d − d_disc) · scale · Δt  [1/(m·s)]
    potential: float = 3.0  # × decrease of goal distance [1/m]
    intrusion: float = -20.0  # / 2^(k+1) for predicted step k = 1..n_pred
    spin: float = -4.5  # × Δθ² [1/rad²], Δθ the heading change of the step
    reverse: float = -2.0  # × |v| when v < 0 [s/m]
    n_pred: int = 5  # K, predicted positions per human
    pred_dt: float = 0.25  # [s] Δt_pred between predicted positions
    # [s] the original's step T: per-step terms are rescaled to Δt (None: charged per step)
    reference_dt: Positive | None = 0.25


# Beyond CrowdNav++: the reward without its intrusion term, in which arriving pays more than
# waiting beside the door (with it, waiting costs ≈ −4 an episode and the teacher's own
# successes −14.4 in HR-RL: docs/baselines.md). The students' fine-tuning is paid with it.
NO_INTRUSION = CrowdNavRewardConfig(intrusion=0.0)

# The rewards a CrowdNav++ training run can be paid with, by name (``pioneer train crowdnav++
# --reward``): the original's, and the same without its intrusion term.
RewardName = Literal["crowdnav", "no-intrusion"]
REWARDS: Mapping[RewardName, CrowdNavRewardConfig] = MappingProxyType(
    {"crowdnav": CrowdNavRewardConfig(), "no-intrusion": NO_INTRUSION}
)

_COLLISION, _SUCCESS = int(Event.COLLISION), int(Event.SUCCESS)  # plain ints: no enum lookup
# The rows of the terms the kernel fills, in the order of ``crowdnav_reward_terms``'s dict.
TERMS = ("success", "collision", "discomfort", "progress", "intrusion", "spin", "reverse")


@functools.lru_cache(maxsize=16)
def _constants(rc: CrowdNavRewardConfig, dt: float) -> tuple[F64, F64, F64]:
    """Per config and Δt (computed once, not every step): the kernel's scalar parameters, the
    prediction times k·Δt_pred ``(K,)`` and the intrusion penalties −20/2^(k+1) · Δt/T
    ``(K,)``, with the per-step factor Δt/T."""
    per_step = dt / rc.reference_dt if rc.reference_dt else 1.0  # T → Δt for per-step terms
    k = np.arange(1, rc.n_pred + 1)
    ks: F64 = (k * rc.pred_dt).astype(np.float64)
    pen: F64 = (rc.intrusion / 2.0 ** (k + 1) * per_step).astype(np.float64)
    params: F64 = np.array(
        [
            rc.success, rc.collision, rc.discomfort_distance, rc.discomfort_scale, rc.potential,
            rc.spin, rc.reverse, dt, per_step,
        ]
    )  # fmt: skip
    for a in (params, ks, pen):
        a.setflags(write=False)
    return params, ks, pen


@njit(cache=True)
def _terms_kernel(
    out: F64,  # (8, B): the TERMS rows, then the total
    prev_goal: F64,  # (B, 2)
    prev_robot: F64,  # (B, 3)
    goal: F64,  # (B, 2)
    robot: F64,  # (B, 3)
    gap: F64,  # (B,)
    event: NDArray[np.int8],  # (B,)
    h_pos: F64,  # (B, N, 2)
    h_vel: F64,  # (B, N, 2)
    h_radius: F64,  # (B, N)
    present: NDArray[np.bool_],  # (B, N)
    command: F64,  # (B, 2)
    ks: F64,  # (K,) prediction times [s]
    pen: F64,  # (K,) intrusion penalties
    params: F64,  # success, collision, d_disc, disc_scale, potential, spin, reverse, dt, per_step
    r_robot: float,
) -> None:  # pragma: no cover - compiled
    """Every term of every copy, with the arithmetic of the formulas in the module docstring
    in the order NumPy evaluated them before this kernel (no fastmath: the same values bit
    for bit; the tests compare against that NumPy reference)."""
    success, collision, d_disc = params[0], params[1], params[2]
    scale, potential = params[3], params[4]
    spin_w, reverse, dt, per_step = params[5], params[6], params[7], params[8]
    n_b, n_h = h_pos.shape[0], h_pos.shape[1]
    for b in range(n_b):
        x0 = prev_goal[b, 0] - prev_robot[b, 0]
        y0 = prev_goal[b, 1] - prev_robot[b, 1]
        x1 = goal[b, 0] - robot[b, 0]
        y1 = goal[b, 1] - robot[b, 1]
        d0 = np.sqrt(x0 * x0 + y0 * y0)
        d1 = np.sqrt(x1 * x1 + y1 * y1)
        c = gap[b]
        close = c < d_disc
        collided = event[b] == _COLLISION
        reached = event[b] == _SUCCESS
        ongoing = not (collided or reached)
        base = (c - d_disc) * scale * dt if close else potential * (d0 - d1)
        first = collision if collided else (success if reached else base)
        intr = 0.0
        if ongoing and n_h > 0 and ks.shape[0] > 0:  # the least of pen_k (hit) or 0 (missed)
            intr = np.inf
            for i in range(n_h):
                reach = r_robot + h_radius[b, i]
                for k in range(ks.shape[0]):
                    dx = (h_pos[b, i, 0] + h_vel[b, i, 0] * ks[k]) - robot[b, 0]
                    dy = (h_pos[b, i, 1] + h_vel[b, i, 1] * ks[k]) - robot[b, 1]
                    hit = present[b, i] and np.sqrt(dx * dx + dy * dy) < reach
                    intr = min(intr, pen[k] if hit else 0.0)
        w = command[b, 1] * dt
        spin = spin_w * (w * w) / per_step
        v = command[b, 0]
        rev = reverse * per_step * np.abs(v) if v < 0.0 else 0.0
        out[0, b] = success if reached else 0.0
        out[1, b] = collision if collided else 0.0
        out[2, b] = base if ongoing and close else 0.0
        out[3, b] = base if ongoing and not close else 0.0
        out[4, b] = intr
        out[5, b] = spin
        out[6, b] = rev
        out[7, b] = first + intr + spin + rev


def _terms(
    world: World, prev: State, new: State, event: NDArray[np.int8], rc: CrowdNavRewardConfig
) -> F64:
    """The ``(8, B)`` table of :func:`_terms_kernel`: the :data:`TERMS` rows, then the total."""
    sim = world.sim
    params, ks, pen = _constants(rc, sim.dt)
    out = np.empty((len(TERMS) + 1, new.batch_size))
    _terms_kernel(
        out, prev.goal, prev.robot, new.goal, new.robot, new.gap, event, new.h_pos, new.h_vel,
        new.h_radius, new.humans_present, new.command, ks, pen, params, float(sim.robot.radius),
    )  # fmt: skip
    return out


def crowdnav_reward_terms(
    world: World,
    prev: State,
    new: State,
    event: NDArray[np.int8],
    config: CrowdNavRewardConfig,
) -> tuple[dict[str, F64], F64]:
    """Per-term rewards ``{name: (B,)}`` and their total ``(B,)`` of the step ``prev → new``
    whose event codes ``(B,)`` the world gave (:func:`pioneer.sim.events.classify`): the
    reward prices an ending, it does not decide it."""
    out = _terms(world, prev, new, event, config)
    return dict(zip(TERMS, out, strict=False)), out[-1]


def crowdnav_reward(
    world: World,
    prev: State,
    new: State,
    event: NDArray[np.int8],
    config: CrowdNavRewardConfig,
) -> F64:
    """Total reward ``(B,)`` of the step ``prev → new`` with the world's event codes (without
    the per-term breakdown: the trainer's hot path)."""
    return _terms(world, prev, new, event, config)[-1]


@dataclasses.dataclass(frozen=True)
class CrowdNavReward:
    """The CrowdNav++ reward as an environment's step reward: called with the step and its
    event codes (the world classifies the step; the reward only prices it), it returns the
    total ``(B,)`` and the per-term rewards ``{name: (B,)}``."""

    config: CrowdNavRewardConfig = CrowdNavRewardConfig()

    def __call__(
        self, world: World, prev: State, new: State, event: NDArray[np.int8]
    ) -> tuple[F64, dict[str, F64]]:
        terms, total = crowdnav_reward_terms(world, prev, new, event, self.config)
        return total, terms
