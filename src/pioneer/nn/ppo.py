"""The parts of PPO (Schulman et al. 2017) every trainer of the project shares: generalised
advantage estimation, the clipped surrogate, the resume rule of a training folder and the
learning curve's CSV. Two trainers use them: CrowdNav++'s
(:mod:`pioneer.baselines.crowdnav.ppo`, a recurrent network on the batched simulator) and the
students' fine-tuning (:mod:`pioneer.learn.finetune`, the DAgger student over a layout
distribution)."""

from __future__ import annotations

import csv
import io
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch
from numpy.typing import NDArray

from pioneer.errors import ConfigError, expect

__all__ = ["check_resume", "clipped_surrogate", "compute_gae", "curve_csv"]

F64 = NDArray[np.float64]


def compute_gae(
    rewards: F64, values: F64, dones: F64, last_value: F64, gamma: float, lam: float
) -> tuple[F64, F64]:
    """Generalised advantage estimates and returns, both ``(T, B)``.

    ``rewards``, ``values`` (V(s_t)), ``dones`` (1: the episode ended with step t) are
    ``(T, B)``; ``last_value`` is V of the state after the last step ``(B,)``.
    δ_t = r_t + γ V_{t+1} (1 − d_t) − V_t,  A_t = δ_t + γ λ (1 − d_t) A_{t+1};  R_t = A_t + V_t.
    An episode cut at the rollout's end (not ended) is bootstrapped with ``last_value``.
    """
    t_len = rewards.shape[0]
    adv = np.zeros_like(rewards, dtype=np.float64)
    last = np.zeros(rewards.shape[1:], dtype=np.float64)
    for t in range(t_len - 1, -1, -1):
        nxt = last_value if t == t_len - 1 else values[t + 1]
        keep = 1.0 - dones[t]
        delta = rewards[t] + gamma * nxt * keep - values[t]
        last = delta + gamma * lam * keep * last
        adv[t] = last
    return adv, adv + values


def clipped_surrogate(
    logp: torch.Tensor, old_logp: torch.Tensor, adv: torch.Tensor, clip: float
) -> torch.Tensor:
    """PPO's policy loss −E[min(ρ A, clip(ρ, 1 − ε, 1 + ε) A)], ρ = π/π_old (scalar)."""
    ratio = torch.exp(logp - old_logp)
    return -torch.min(ratio * adv, ratio.clamp(1 - clip, 1 + clip) * adv).mean()


def check_resume(resume: bool | None, ckpt: Path, out: Path) -> None:
    """``--resume`` needs a checkpoint; a fresh start (``resume=False``) refuses one."""
    if resume is True and not ckpt.is_file():
        raise ConfigError(
            expect("--resume", f"a checkpoint at {ckpt}", "none", "drop --resume to start afresh")
        )
    if resume is False and ckpt.is_file():
        raise ConfigError(
            expect("--out", "a folder without a checkpoint", str(out), "resume or use a new --out")
        )


def curve_csv(columns: Sequence[str], rows: Sequence[Sequence[float]], ints: int = 3) -> str:
    """A learning curve as CSV text: the first ``ints`` columns as integers (update, steps,
    episodes), the others with 6 significant digits."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(columns)
    for r in rows:
        w.writerow([*(int(x) for x in r[:ints]), *(f"{x:.6g}" for x in r[ints:])])
    return buf.getvalue()
