"""The parts of PPO (Schulman et al. 2017) every trainer of the project shares: generalised
advantage estimation, the clipped surrogate, the resume rule of a training folder and the
learning curve's CSV. Two trainers use them: CrowdNav++'s
(:mod:`pioneer.baselines.crowdnav.ppo`, a recurrent network on the batched simulator) and the
students' fine-tuning (:mod:`pioneer.learn.finetune`, the DAgger student over a layout
distribution)."""

from __future__ import annotations

import csv
import io
import math
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import torch
from numpy.typing import NDArray

from pioneer.errors import ConfigError, expect
from pioneer.interrupt import deferred
from pioneer.progress import progress_bar

__all__ = [
    "PPOTrainer",
    "check_resume",
    "clipped_surrogate",
    "compute_gae",
    "curve_columns",
    "curve_csv",
    "gaussian_kl",
    "lagrangian_advantage",
    "update_loop",
    "window_row",
]

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


def gaussian_kl(mean: torch.Tensor, target: torch.Tensor, scale: torch.Tensor) -> torch.Tensor:
    """½ ‖(mean − target) / scale‖² per row ``(N,)``: the KL divergence between two Gaussians
    of the same diagonal standard deviation ``scale`` (the fine-tuning's pull towards its
    starting policy and its teacher guidance)."""
    return 0.5 * (((mean - target) / scale) ** 2).sum(-1)


def lagrangian_advantage(adv: F64, cost_adv: F64, lagrange: float) -> F64:
    """PPO-Lagrangian's advantage (Ray et al. 2019, "Benchmarking Safe Exploration in Deep
    RL"): (A_r − λ A_c) / (1 + λ), the cost's advantage weighed by the multiplier λ ≥ 0 and
    the sum rescaled so the policy's step does not grow with λ."""
    return (adv - lagrange * cost_adv) / (1.0 + lagrange)


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


def curve_columns(columns: Sequence[str], rows: Sequence[Sequence[float]]) -> dict[str, F64]:
    """A learning curve's rows as one array per column (what
    :func:`pioneer.viz.plots.plot_learning_curve` plots)."""
    arr = np.asarray(rows, dtype=np.float64).reshape(-1, len(columns))
    return {c: arr[:, i] for i, c in enumerate(columns)}


def window_row(
    returns: Sequence[float], events: Sequence[int], codes: Sequence[int]
) -> list[float]:
    """A learning curve's running statistics over the last finished episodes: their mean
    return, then the share of each event code in ``codes`` (NaN before the first episode)."""
    ev = np.asarray(events)
    mean = float(np.mean(returns)) if len(returns) else math.nan
    return [mean, *(float(np.mean(ev == c)) if ev.size else math.nan for c in codes)]


class Progress(Protocol):
    """What a trainer's checkpoint keeps of its progress besides the networks, optimizers and
    environments: counters, the learning curve, the window of the last episodes and both
    generators (:func:`progress_state`, :func:`restore_progress`)."""

    update: int
    env_steps: int
    episodes: int
    wall: float
    curve: list[list[float]]
    win_return: list[float]
    win_event: list[int]
    gen: torch.Generator
    rng: np.random.Generator


def progress_state(p: Progress, n_columns: int) -> tuple[dict[str, torch.Tensor], dict[str, Any]]:
    """``(tensors, meta)`` of ``p``'s progress for :func:`pioneer.nn.checkpoint.
    write_training_state` (``n_columns``: the learning curve's width)."""
    tensors = {
        "curve": torch.tensor(p.curve, dtype=torch.float64).reshape(-1, n_columns),
        "window/return": torch.tensor(p.win_return, dtype=torch.float64),
        "window/event": torch.tensor(p.win_event, dtype=torch.int64),
        "rng/torch": p.gen.get_state(),
    }
    counters = {"update": p.update, "env_steps": p.env_steps}
    meta = {
        "counters": counters | {"episodes": p.episodes, "wall_time_s": p.wall},
        "rng_numpy": p.rng.bit_generator.state,
    }
    return tensors, meta


def restore_progress(p: Progress, tensors: dict[str, torch.Tensor], meta: dict[str, str]) -> None:
    """Set ``p``'s progress to what :func:`progress_state` stored."""
    import json

    p.curve = tensors["curve"].tolist()
    p.win_return = tensors["window/return"].tolist()
    p.win_event = [int(x) for x in tensors["window/event"].tolist()]
    p.gen.set_state(tensors["rng/torch"])
    p.rng.bit_generator.state = json.loads(meta["rng_numpy"])
    c = json.loads(meta["counters"])
    p.update, p.env_steps = int(c["update"]), int(c["env_steps"])
    p.episodes, p.wall = int(c["episodes"]), float(c["wall_time_s"])


class PPOTrainer(Protocol):
    """What :func:`update_loop` drives: counters, one rollout, one update on it, and the end
    of an update (counted, its learning-curve row returned)."""

    update: int
    env_steps: int
    wall: float

    def rollout(self) -> Any:
        """Collect one rollout (no gradients)."""
        ...

    def learn(self, batch: Any) -> dict[str, float]:
        """One update on ``batch``; its mean losses."""
        ...

    def end_update(self) -> list[float]:
        """Count the update; its learning-curve row."""
        ...


def update_loop(
    tr: PPOTrainer,
    updates: int,
    steps_per_update: int,
    columns: Sequence[str],
    desc: str,
    progress: bool,
    checkpoint_every: int,
    checkpoint: Callable[[], None],
    on_update: Callable[[dict[str, float]], None] | None,
) -> None:
    """Updates until ``updates``, each whole (a signal stops the run between two updates,
    :func:`pioneer.interrupt.deferred`), with a progress bar (steps/s, the curve's mean return
    ``columns[3]`` and success rate ``columns[4]``) and ``checkpoint()`` every
    ``checkpoint_every`` updates before the last."""
    bar = progress_bar(
        total=updates * steps_per_update,
        initial=tr.env_steps,
        unit="step",
        desc=desc,
        enabled=progress,
        mininterval=2.0,
    )
    t_start, s_start = time.perf_counter(), tr.env_steps
    try:
        while tr.update < updates:
            with deferred():
                t0 = time.perf_counter()
                stats = tr.learn(tr.rollout())
                tr.wall += time.perf_counter() - t0
                row = tr.end_update()
                rate = (tr.env_steps - s_start) / max(time.perf_counter() - t_start, 1e-9)
                bar.update(steps_per_update)
                bar.set_postfix(
                    {"steps/s": f"{rate:.0f}", "return": f"{row[3]:.2f}", "SR": f"{row[4]:.2f}"},
                    refresh=False,
                )
                if on_update is not None:
                    on_update({**dict(zip(columns, row, strict=True)), **stats})
                if tr.update % checkpoint_every == 0 and tr.update < updates:
                    checkpoint()
    finally:
        bar.close()
