"""Rehearsal: the fine-tuning's pull towards its starting student on states of layouts the
stage does not practise (policy distillation of the previous stage on its own states).

A fine-tuning stage improves what it practises and gives back what it does not: a stage over
new families erodes families an earlier stage mastered (docs/general-student.md). Rehearsal
keeps them without spending the stage's env steps on them. Before training, the starting
student μ_0 drives ``rehearse_states`` steps over the rehearsed layouts with the fine-tuning's
own exploration noise σ_0 (:class:`~pioneer.learn.layout_env.LayoutEnvs`, the same episode
seeds' range, its own draws); the inputs x_j it met and its commands μ_0(x_j) are kept. Every
minibatch of the actor's PPO update then adds

    β_R · mean over a uniform draw of j of ½ ‖(μ(x_j) − μ_0(x_j)) / (s_u σ_0)‖²

(β_R = ``rehearse_coef``, constant; the same Gaussian KL as the pull towards the DAgger
student, :func:`pioneer.nn.ppo.gaussian_kl`), as many rows as the minibatch. It is the
distillation half of Progress & Compress (Schwarz et al. 2018, arXiv 1805.06370) and of
policy distillation (Rusu et al. 2016, arXiv 1511.06295) with the previous stage as teacher.

The states are drawn again, identically, when a run resumes (its own generators, seeded by the
run's seed), so a checkpoint need not carry them.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch

from pioneer.learn.finetune_config import FinetuneConfig
from pioneer.learn.layout_env import LayoutEnvs
from pioneer.learn.models import Student
from pioneer.nn.ppo import gaussian_kl
from pioneer.progress import progress_bar

__all__ = ["Rehearsal"]

_STREAM = 0x5EA2  # the rehearsal's own draws, apart from the training's


class Rehearsal:
    """The starting student's inputs and commands on the rehearsed layouts (module
    docstring); :meth:`loss` the pull on a draw of them."""

    def __init__(self, inputs: torch.Tensor, commands: torch.Tensor) -> None:
        if inputs.shape[0] != commands.shape[0] or inputs.shape[0] == 0:
            raise ValueError(f"inputs and commands: as many rows, ≥ 1; got {inputs.shape[0]} "
                             f"and {commands.shape[0]}")  # fmt: skip
        self.inputs, self.commands = inputs, commands

    @classmethod
    def collect(
        cls,
        start: Student,
        names: Sequence[Sequence[str]],
        cfg: FinetuneConfig,
        max_humans: int,
        progress: bool = False,
    ) -> Rehearsal:
        """``cfg.rehearse_states`` states (rounded up to whole steps of every copy) of
        ``start`` driving ``names`` (drawn like the training's pools, uniformly) with the
        exploration noise σ_0 = ``cfg.init_std``; every group redraws its layout every
        ``layout_period`` × ``rollout`` steps, as in training."""
        rng = np.random.default_rng(np.random.SeedSequence([cfg.seed, _STREAM]))
        gen = torch.Generator().manual_seed(cfg.seed + _STREAM)
        envs = LayoutEnvs(
            names,
            cfg.groups,
            cfg.group_size,
            start.config.inputs,
            cfg.reward,
            rng,
            cfg.seed + _STREAM,  # its episodes' seeds apart from the training's
            max_humans,
        )
        steps = -(-cfg.rehearse_states // cfg.envs)
        period = cfg.layout_period * cfg.rollout
        std = start.act_std * cfg.init_std
        xs = []
        with torch.no_grad():
            bar = progress_bar(total=steps, desc="rehearsal states", unit="step", enabled=progress)
            for t in range(steps):
                if t and t % period == 0:
                    for g in range(cfg.groups):
                        envs.redraw(g)
                x = torch.from_numpy(envs.student_inputs())
                mean = start.deterministic_action(x, "mode")
                action = mean + std * torch.randn(mean.shape, generator=gen)
                envs.step(action.numpy().astype(np.float64))
                xs.append(x)
                bar.update(1)
            bar.close()
            inputs = torch.cat(xs)
            commands = start.deterministic_action(inputs, "mode")
        return cls(inputs, commands)

    def __len__(self) -> int:
        return int(self.inputs.shape[0])

    def loss(
        self, actor: Student, rows: int, scale: torch.Tensor, gen: torch.Generator
    ) -> torch.Tensor:
        """The pull on ``rows`` states drawn uniformly (with replacement, by ``gen``): the
        mean of ½ ‖(μ(x_j) − μ_0(x_j)) / scale‖²."""
        j = torch.randint(len(self), (rows,), generator=gen)
        mean = actor.deterministic_action(self.inputs[j], "mode")
        return gaussian_kl(mean, self.commands[j], scale).mean()
