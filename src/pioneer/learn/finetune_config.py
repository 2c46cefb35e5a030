"""The settings of the students' fine-tuning (the method and its formulas:
:mod:`pioneer.learn.finetune`)."""

from __future__ import annotations

import dataclasses
from typing import Annotated

from annotated_types import Interval, MinLen

from pioneer.bounds import Count, NonNegative, NonNegativeInt, Positive, UnitInterval
from pioneer.config import Config
from pioneer.learn.layout_env import ReplayMode
from pioneer.reward.crowdnav import NO_INTRUSION, CrowdNavRewardConfig

__all__ = ["FINETUNE_REWARD", "FinetuneConfig"]

FINETUNE_REWARD = NO_INTRUSION  # the CrowdNav++ reward without its intrusion term


@dataclasses.dataclass(frozen=True)
class FinetuneConfig(Config):
    """Settings of a fine-tuning run (module docstring)."""

    total_steps: Count = 6_000_000  # env steps (all copies together)
    groups: Count = 8  # layouts stepped at once
    group_size: Count = 8  # copies of each layout
    rollout: Count = 64  # steps per copy per update
    layout_period: Count = 4  # [updates] between two draws of every group's layout
    lr: Positive = 3e-5  # the actor's Adam learning rate (with σ)
    critic_lr: Positive = 1e-3  # the critic's
    gamma: UnitInterval = 0.99  # discount per 0.1 s step
    gae_lambda: UnitInterval = 0.95  # GAE λ
    clip: Positive = 0.2  # PPO ratio clip
    epochs: Count = 4  # passes over each rollout
    minibatches: Count = 4  # per pass
    max_grad_norm: Positive = 0.5  # gradient clipping (global L2 norm, per network)
    init_std: Positive = 0.2  # σ_0: exploration noise in standardised action units
    kl_coef: NonNegative = 1.0  # β_0 of the pull towards the DAgger student
    kl_fade: NonNegativeInt = 500_000  # [env steps] over which β falls to 0
    critic_warmup: NonNegativeInt = 10  # [updates] the critic alone learns first
    # share of the layout draws made in proportion to each layout's running failure rate
    # (prioritised layouts; 0: uniform)
    replay: UnitInterval = 0.0
    # "mix": the replayed share weighs every layout by its failure rate, one not yet seen
    # counting as failing; "plr": the replayed share picks among the layouts already seen,
    # the rest among those not yet seen (prioritised level replay); "mastery": the replayed
    # share practises a few hard layouts, each until it is mastered (pioneer.learn.curriculum)
    replay_mode: ReplayMode = "mix"
    # draw each pattern's layouts by situation (people boarding, leaving, a shallow lobby):
    # its situations equally often, then a layout of one uniformly (pioneer.learn.situations);
    # the curriculum then chooses among situations. False: a pattern's layouts uniformly
    stratify: bool = False
    mastery_layouts: Count = 9  # "mastery": layouts practised at once
    # "mastery": the share of a layout's last ``mastery_window`` episodes that must succeed
    mastery: UnitInterval = 0.9
    mastery_window: Count = 50  # [episodes] "mastery": the recent episodes judged
    # [episodes] "mastery": a layout not mastered in this many leaves the set (dropped)
    mastery_limit: Count = 4000
    critic_hidden: Annotated[tuple[Count, ...], MinLen(1)] = (128, 128)  # its widths
    # the share of training episodes allowed to end in a collision: below 1, PPO-Lagrangian
    # (a cost critic, advantages (A_r − λ A_c) / (1 + λ), λ raised while the running
    # collision rate exceeds it); 1: the plain reward, unconstrained
    collision_limit: UnitInterval = 1.0
    lagrange_lr: Positive = 0.5  # λ's step per update per unit of excess collision rate
    # teacher guidance: β_T of the imitation of the privileged teacher's label in the copies it
    # labels (0: off); one copy in each of the first ``teacher_groups`` groups is labelled
    # every step; ``teacher_alpha`` α of the per-state weight exp(−α d²), d the distance
    # between the DAgger student's command and the label in standardised units (0: weight 1)
    teacher_coef: NonNegative = 0.0
    teacher_groups: Count = 4
    teacher_alpha: NonNegative = 0.0
    # risk-sensitive advantages: below 1, the critic learns ``quantiles`` quantiles of the
    # return and the policy's advantages bootstrap from their lower-tail mean CVaR_α (the
    # mean of the worst α share of returns); 1: the expected return
    risk_alpha: Annotated[float, Interval(gt=0.0, le=1.0)] = 1.0
    quantiles: Annotated[int, Interval(ge=2)] = 32  # N of the critic's quantiles (α < 1)
    reward: CrowdNavRewardConfig = FINETUNE_REWARD
    # [env steps] the time constant of an exponential moving average of the actor's weights,
    # updated after every update (Polyak averaging; stochastic weight averaging in RL, Nikishin
    # et al. 2018): student.safetensors is then the average, student-last.safetensors the last
    # iterate; 0: off
    average_horizon: NonNegativeInt = 0
    # rehearsal of layouts the stage does not practise (``--rehearse``;
    # pioneer.learn.rehearsal): β_R of the pull towards the starting student on its own states
    # there (constant), and how many of those states are kept
    rehearse_coef: NonNegative = 1.0
    rehearse_states: Count = 65_536
    seed: NonNegativeInt = 0  # seeds the critic, the noise, the minibatches and the episodes
    checkpoint_every: Count = 20  # [updates] between checkpoints
    window: Count = 200  # finished episodes in the curve's running statistics

    @property
    def envs(self) -> int:
        """Copies stepped together: groups × group_size."""
        return self.groups * self.group_size

    @property
    def steps_per_update(self) -> int:
        """Env steps per update."""
        return self.envs * self.rollout

    @property
    def updates(self) -> int:
        """Updates for ``total_steps`` (rounded up)."""
        return -(-self.total_steps // self.steps_per_update)
