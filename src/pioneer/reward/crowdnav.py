"""The CrowdNav++ reward (Liu et al., ICRA 2023; its public code's unicycle terms): the reward
the CrowdNav++ baseline is trained on, and the Gymnasium environments' own reward.

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
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from pioneer.bounds import Positive
from pioneer.config import Config
from pioneer.sim.events import Event
from pioneer.sim.world import State, World

__all__ = ["CrowdNavReward", "CrowdNavRewardConfig", "crowdnav_reward", "crowdnav_reward_terms"]

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


class _Parts(NamedTuple):
    event: NDArray[np.int8]
    ongoing: NDArray[np.bool_]  # neither collided nor arrived in this step
    close: NDArray[np.bool_]  # gap below the discomfort distance
    base: F64  # discomfort or potential term
    first: F64  # outcome reward, else ``base``
    intrusion: F64
    spin: F64
    reverse: F64

    @property
    def total(self) -> F64:
        return self.first + self.intrusion + self.spin + self.reverse


_COLLISION, _SUCCESS = int(Event.COLLISION), int(Event.SUCCESS)  # plain ints: no enum lookup


def _norm2(d: F64) -> F64:
    """‖d‖ over the last axis of length 2: the same sum of squares as ``np.linalg.norm``
    (bit for bit), without its per-call overhead."""
    x, y = d[..., 0], d[..., 1]
    out: F64 = np.sqrt(x * x + y * y)
    return out


@functools.lru_cache(maxsize=16)
def _constants(rc: CrowdNavRewardConfig, dt: float) -> tuple[float, F64, F64]:
    """Per config and Δt: the per-step factor Δt/T, the prediction times k·Δt_pred ``(K,)`` and
    the intrusion penalties −20/2^(k+1) · Δt/T ``(K,)`` (computed once, not every step)."""
    per_step = dt / rc.reference_dt if rc.reference_dt else 1.0  # T → Δt for per-step terms
    k = np.arange(1, rc.n_pred + 1)
    ks: F64 = (k * rc.pred_dt).astype(np.float64)
    pen: F64 = (rc.intrusion / 2.0 ** (k + 1) * per_step).astype(np.float64)
    ks.setflags(write=False)
    pen.setflags(write=False)
    return per_step, ks, pen


def _parts(
    world: World, prev: State, new: State, event: NDArray[np.int8], rc: CrowdNavRewardConfig
) -> _Parts:
    sim = world.sim
    dt = sim.dt
    per_step, ks, pen = _constants(rc, dt)
    collided, reached = event == _COLLISION, event == _SUCCESS
    d0 = _norm2(prev.goal - prev.robot[:, :2])
    d1 = _norm2(new.goal - new.robot[:, :2])
    c = new.gap
    close = c < rc.discomfort_distance
    ongoing = ~(collided | reached)
    base = np.where(
        close, (c - rc.discomfort_distance) * rc.discomfort_scale * dt, rc.potential * (d0 - d1)
    )
    first = np.where(collided, rc.collision, np.where(reached, rc.success, base))
    intr = np.zeros(new.batch_size)
    if new.n_humans:
        pred = new.h_pos[:, :, None, :] + new.h_vel[:, :, None, :] * ks[None, None, :, None]
        dist = _norm2(pred - new.robot[:, None, None, :2])  # (B, N, K)
        hit = (dist < sim.robot.radius + new.h_radius[:, :, None]) & new.humans_present[..., None]
        intr = np.where(ongoing, np.where(hit, pen[None, None, :], 0.0).min(axis=(1, 2)), 0.0)
    v, w = new.command[:, 0], new.command[:, 1]
    spin = rc.spin * (w * dt) ** 2 / per_step
    rev = np.where(v < 0.0, rc.reverse * per_step * np.abs(v), 0.0)
    return _Parts(event, ongoing, close, base, first, intr, spin, rev)


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
    rc = config
    p = _parts(world, prev, new, event, rc)
    terms = {
        "success": np.where(p.event == _SUCCESS, rc.success, 0.0),
        "collision": np.where(p.event == _COLLISION, rc.collision, 0.0),
        "discomfort": np.where(p.ongoing & p.close, p.base, 0.0),
        "progress": np.where(p.ongoing & ~p.close, p.base, 0.0),
        "intrusion": p.intrusion,
        "spin": p.spin,
        "reverse": p.reverse,
    }
    return terms, p.total


def crowdnav_reward(
    world: World,
    prev: State,
    new: State,
    event: NDArray[np.int8],
    config: CrowdNavRewardConfig,
) -> F64:
    """Total reward ``(B,)`` of the step ``prev → new`` with the world's event codes (without
    the per-term breakdown: the trainer's hot path)."""
    return _parts(world, prev, new, event, config).total


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
